//! # frcd-geom
//!
//! Geometry primitives shared by every frcd crate, in f64 (glam `DVec3`, `DMat3`, `DQuat`):
//!
//! - [`Triangle`]: a closed triangle (a zero-area one is a segment or a point);
//! - [`Pose`]: a rigid transform, with composition, inverse and the relative pose of two bodies;
//! - [`TriMesh`]: a validated indexed triangle mesh, welded by position, with a [`MeshReport`]
//!   (degenerate and duplicate triangles) and a [`Topology`] report (closed, manifold, oriented);
//! - bounding volumes [`Aabb`], [`Sphere`], [`Obb`] with OBB fitting ([`fit`]: vertex
//!   covariance, area-weighted triangles, convex hull surface);
//! - [`hull`]: an exact-predicate 3D convex hull (Quickhull) with explicit flat results;
//! - [`predicates`]: exact orientation predicates (`orient3d`, `orient2d`, `collinear3`);
//! - [`shapes`]: procedural closed meshes with outward normals for tests, benches and demos
//!   (box, spheres, cylinder, torus, torus knot, spur gear, coil spring, railway wheel,
//!   wheelset and rail), the generic [`shapes::revolve`] and [`shapes::sweep`] builders,
//!   [`shapes::subdivide`] and [`shapes::merge`].
//!
//! ```
//! use frcd_geom::{shapes, Pose, DVec3, DQuat};
//! let ball = shapes::icosphere(1.0, 2);
//! assert!(ball.topology().is_closed_oriented_manifold());
//! let pose = Pose::new(DVec3::new(1e6, 0.0, 0.0), DQuat::IDENTITY);
//! assert_eq!(pose.transform_point(DVec3::ZERO).x, 1e6);
//! ```
#![warn(missing_docs)]

mod bounds;
pub mod fit;
pub mod hull;
mod mesh;
mod pose;
pub mod predicates;
pub mod shapes;
mod topology;
mod triangle;

pub use bounds::{Aabb, Obb, Sphere};
pub use glam::{DMat3, DQuat, DVec2, DVec3};
pub use mesh::{MeshError, MeshReport, TriMesh};
pub use pose::{Pose, PoseError};
pub use topology::Topology;
pub use triangle::Triangle;
