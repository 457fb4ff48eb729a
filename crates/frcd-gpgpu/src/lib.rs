#![doc = include_str!("../README.md")]
#![forbid(unsafe_code)]
//! ## API overview
//!
//! The thesis's GPGPU detector on wgpu: each body's OBB tree and triangles are packed into
//! `rgba32float` textures in the body's local frame and uploaded **once**; a query uploads only the
//! relative pose, runs the **whole** pair traversal on the GPU in **one submission** and reads the
//! answer back **once**.
//!
//! - [`GpuContext`]: the caller's `wgpu::Device` + `Queue` ([`GpuContext::from_device`]) or a
//!   headless one ([`GpuContext::headless`]); requirements are checked against the device's limits
//!   ([`requirements`]); no adapter is [`GpuError::NoAdapter`].
//! - [`GpuMesh`]: an uploaded tree ([`GpuContext::upload`]); trees larger than one texture row or
//!   one texture are split across rows and array layers.
//! - [`GpuContext::collide`]: level-synchronous breadth-first traversal of the pair tree, one
//!   indirect dispatch per level (the CPU knows the depths, so every level is recorded up front):
//!   a conservative OBB separating-axis test in f32 whose error bound lets rounding only keep
//!   pairs; child pairs compacted with atomics; triangle pairs tested in WGSL with the
//!   Guigue-Devillers orientation form and a forward error bound that marks a pair *uncertain*
//!   instead of deciding it. The CPU re-decides uncertain pairs with the exact test
//!   ([`frcd_tritri::Method::Exact`]), so the answer equals the exact oracle's
//!   ([`frcd_obb::oracle::pairs`]) pair for pair. Surface mode: touching triangle pairs.
//! - Output and frontier buffers have capacities; an overflow is detected on the GPU (the
//!   append counter runs past the capacity) and the query is re-run with larger buffers — the
//!   answer is never truncated.
//! - [`GpuContext::overlapping_bodies`]: the box overlap of many bodies' world boxes on the GPU
//!   (the hybrid scheduler's rough colliding set) by sort-based sweep and prune in
//!   O(n log n + pairs): a bitonic sort of the box minima on the axis of largest spread, then
//!   each box scans forward while the next minimum is within its maximum. Equal to the f64
//!   all-pairs answer ([`GpuContext::overlapping_bodies_all_pairs`] is the O(n²) form, one
//!   dispatch, faster for few bodies: [`GpuContext::broad_phase`] takes it up to
//!   [`ALL_PAIRS_MAX_BODIES`] bodies and the sweep above).
//!
//! Numbers: the GPU computes in f32 relative to each body's local origin (triangles relative to
//! grid reference points, whose offset the triangle pass can compute exactly in integers: see
//! [`GpuContext::set_exact_offsets`]); every f32 quantity that
//! could drop a candidate carries a computed error bound that holds under WGSL's float rules
//! (rounding either way, fused multiply-adds, flush-to-zero; derivation in
//! `shaders/traverse.wgsl`), and every pair the GPU reports is re-decided exactly on the CPU.
//! Magnitudes above [`MAX_MAGNITUDE`] are refused ([`GpuError::MagnitudeOutOfRange`]).
//!
//! ```no_run
//! use frcd_gpgpu::{GpuContext, QueryScratch};
//! use frcd_obb::{BuildOptions, ObbTree};
//! use frcd_geom::{shapes, DVec3, Pose};
//! let ctx = GpuContext::headless()?;
//! let tree = ObbTree::build(&shapes::icosphere(1.0, 3), &BuildOptions::default());
//! let mesh = ctx.upload(&tree)?;
//! let mut scratch = QueryScratch::default();
//! let hit = ctx.collide(&mesh, &Pose::IDENTITY, &mesh,
//!                       &Pose::from_translation(DVec3::X), &mut scratch)?;
//! assert!(!hit.pairs.is_empty());
//! assert_eq!(hit.submissions, 1);
//! # Ok::<(), frcd_gpgpu::GpuError>(())
//! ```
#![warn(missing_docs)]

mod boxes;
mod context;
#[cfg(test)]
mod emulate;
mod error;
mod front;
mod mesh;
#[doc(hidden)]
pub mod pack;
mod query;
#[doc(hidden)]
pub mod shaders;
mod sweep;

pub use boxes::{BodyPairs, BoxScratch, SubmittedBoxes};
pub use context::{
    EXACT_OFFSETS_ENV, GpuContext, HOST_FRONT_SOFTWARE, HeadlessOptions, ONE_PASS_ENV,
    ONE_PASS_LOOP_BUDGET, ONE_PASS_SOFTWARE_MAX, Recheck, SHADER_VARIANT_ENV, requirements,
};
pub use error::GpuError;
pub use mesh::{ArenaOptions, GpuMesh, MAX_LEAF_TRIANGLES};
pub use pack::{MAX_MAGNITUDE, TexLayout};
pub use query::{
    BatchTimings, BodyPair, GpuBatch, GpuCollision, PendingBatch, QueryScratch, SubmittedBatch,
};
pub use sweep::ALL_PAIRS_MAX_BODIES;
/// The wgpu this crate is built on (to create a device for [`GpuContext::from_device`]).
pub use wgpu;
