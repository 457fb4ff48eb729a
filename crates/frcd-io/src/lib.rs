#![doc = include_str!("../README.md")]
#![forbid(unsafe_code)]
//! ## API overview
//!
//! Files in and out of frcd:
//!
//! - **meshes** from STL (ASCII and binary, through `stl_io`) and Wavefront OBJ (through `tobj`),
//!   welded by position and validated by [`frcd_geom::TriMesh`]; see [`load_mesh`],
//!   [`load_obj_objects`], and the writers [`write_stl_binary`] and [`write_obj`];
//! - **scenes**: a JSON file naming bodies, their meshes, static flags, excluded pairs and a
//!   trajectory of poses, optionally extended by a CSV trajectory from a dynamics simulation
//!   (`frame,body,x,y,z,qx,qy,qz,qw`); see [`Scene::load`] and [`SceneFile`];
//! - **reports** of interference checks as JSON and CSV; see [`Report`]; clearance thresholds
//!   (scene `"clearance"`, `"clearances"`: [`Clearances`]) and clearance records
//!   ([`ClearanceRecord`], [`summarize_clearances`], [`clearance_csv`]).
//!
//! Every error is an [`Error`] that names the file and, where one exists, the line or the
//! binary record at fault.
//!
//! ```no_run
//! let scene = frcd_io::Scene::load("testdata/bogie/scene.json")?;
//! for (i, frame) in scene.frames().iter().enumerate().take(3) {
//!     println!("frame {i}: {} bodies moved", frame.moved.len());
//! }
//! # Ok::<(), frcd_io::Error>(())
//! ```
#![warn(missing_docs)]

mod clearance;
mod clearance_report;
mod error;
mod fs;
mod mesh;
mod report;
mod scene;
mod trajectory;
mod write;

pub use clearance::{ClearanceSpec, Clearances, check_clearance};
pub use clearance_report::{
    ClearanceRecord, ClearanceSummary, clearance_csv, summarize_clearances,
};
pub use error::{Error, Location};
pub use fs::{
    Limits, MAX_FRAMES, MAX_JSON_BYTES, MAX_MESH_BYTES, MAX_SCENE_BYTES, MAX_TRAJECTORY_BYTES,
    check_output_path, read_limited, read_text_limited, same_file, write_atomic,
};
pub use mesh::{
    LoadOptions, MeshFormat, ObjObject, load_mesh, load_mesh_with, load_obj_objects, parse_obj,
    parse_obj_objects, parse_stl,
};
pub use report::{FrameReport, Interference, PairSummary, Report};
pub use scene::{
    Body, Frame, FrameIter, FramePoses, Frames, PoseSpec, Scene, SceneBody, SceneFile,
    SceneOptions, UNIT_QUATERNION_TOLERANCE,
};
pub use trajectory::{TRAJECTORY_HEADER, Trajectory, TrajectoryRow};
pub use write::{write_obj, write_stl_binary};

/// Shorthand for results of this crate.
pub type Result<T, E = Error> = std::result::Result<T, E>;
