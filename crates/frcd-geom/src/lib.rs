#![doc = include_str!("../README.md")]
#![warn(missing_docs)]
#![forbid(unsafe_code)]

mod bounds;
pub mod eigen;
pub mod fit;
pub mod hull;
mod mesh;
mod pose;
pub mod predicates;
// Procedural shapes for tests, benches and demos: feature `shapes`, off by default, so an
// engine compiling frcd-geom does not pay for 1,800 lines of railway parts.
#[cfg(feature = "shapes")]
pub mod shapes;
mod topology;
mod triangle;

pub use bounds::{ABSOLUTE_SLACK, Aabb, Obb, Sphere, centre_variance};
/// glam's f32 vector, for [`TriMesh::from_f32`] (an engine on another glam version passes
/// `&[[f32; 3]]`, e.g. through `bytemuck::cast_slice`, without copying).
pub use glam::Vec3;
pub use glam::{DMat3, DQuat, DVec2, DVec3};
pub use mesh::{MeshError, MeshReport, TriMesh};
pub use pose::{Pose, PoseError};
pub use topology::Topology;
pub use triangle::Triangle;
