#![doc = include_str!("../README.md")]
#![forbid(unsafe_code)]
//! ## API overview
//!
//! The thesis's hybrid scheduler for many-body interference checking, stage by stage:
//!
//! 1. **Rough colliding set (RCS)** (`rcs`): body pairs whose world boxes overlap, minus
//!    static-static and excluded pairs: the broad phase of an [`frcd_obb::World`] kept in the
//!    caller's [`FrameState`] (candidate pairs kept over grown boxes from frame to frame), or
//!    the GPU box pass of `frcd-gpgpu` (feature `gpgpu`, a sort-and-sweep) from
//!    [`CostModel::gpu_broad_min_bodies`] bodies on ([`Options::gpgpu_box_pass_min_bodies`]
//!    on [`Backend::Gpgpu`]). Both equal the f64 box test. With a
//!    clearance threshold the boxes are grown by it.
//! 2. **Accurate colliding set (ACS)**, [`Accuracy::Fast`] only: the image-space pass of
//!    `frcd-image` (feature `image`) on each RCS pair of closed meshes gives the triangles that
//!    cross interfering pixels; a pair without interfering pixel is dropped.
//! 3. **Exact triangle tests**: [`Accuracy::Exact`]: every RCS pair gets the exact OBB-tree query,
//!    on the CPU (rayon over pairs, with a per-pair temporal-coherence cache) or on the GPU
//!    (`frcd-gpgpu`'s whole traversal, exact re-decision of uncertain pairs) when
//!    [`CostModel::prefer_gpu_narrow`] says so for the pair's triangle count. [`Accuracy::Fast`]: the
//!    exact test on the ACS triangles only (CPU, rayon).
//!
//! Pairs whose two poses are bit-for-bit last frame's are answered from last frame.
//!
//! Stages live in their own modules: `rcs` (broad phase), `acs` (image space), `exact` (triangle
//! tests and clearance), `gpu` (devices, costing and fallback), `report`, `options`, `state`.
//!
//! ## Clearance
//!
//! [`Options::clearance`] (and [`Options::pair_clearances`] per body pair): every tested pair
//! whose surfaces come within the threshold is reported in [`FrameResult::clearances`] with its
//! distance, closest points and triangle pair ([`frcd_obb::distance`]); interfering pairs
//! report 0. Pairs whose grown boxes stay apart cost no distance query; the others run
//! [`frcd_obb::pair_clearance_spin`] with state kept in the [`FrameState`]: a pair whose
//! last certified distance, less the bodies' motion since (rigorously bounded), stays above the
//! threshold costs no query either; nor does one with a body that is a solid of revolution
//! (a wheelset: [`frcd_obb::SpinProfile`], [`Options::clearance_spin`]) whose meridian images
//! are farther apart than the threshold, whatever angle that body has turned to; and a search
//! is bounded by the decision band (an exact [`frcd_obb::distance::within`] decides inside it).
//! A pair whose boxes overlap and which was checked last frame without interfering gets its
//! clearance first ([`frcd_obb::pair_clearance_apart`]): when that proves the surfaces apart,
//! the collision query's surface traversal is skipped (only solid-mode containment is left,
//! answered there).
//! The answers equal those of a fresh state without these shortcuts. The searches run on
//! trees of their own ([`Options::clearance_build`]) in the narrow phase, the longest pair
//! jobs (by last frame's time) first, each thread taking the next job when it is done;
//! [`FrameResult::clearance_work`] counts them.
//!
//! ## GPU failures and software adapters
//!
//! With [`GpuPolicy::Auto`] any GPU error during a frame falls back to the CPU for that stage
//! and says so in [`FrameResult::notes`]; [`GpuPolicy::Require`] makes it a
//! [`HybridError::Gpu`] that keeps the typed cause ([`GpuFailure`]). A software adapter (wgpu
//! `DeviceType::Cpu`, such as lavapipe) is not used by the hybrid backend unless the cost
//! model was calibrated on that adapter ([`CostModel::adapter`]) or a GPU is required.
//!
//! ## The two modes
//!
//! - [`Accuracy::Exact`] never loses a pair: the answer (interfering body pairs, every touching
//!   triangle pair, solid-mode containment) equals [`frcd_obb::oracle::answer`] for every
//!   non-excluded, not-both-static pair. The image stage is **not run** in this mode: ray parity
//!   sampled at pixel centres can prove interference but never its absence (it misses
//!   interference thinner than a pixel, and touching with zero volume), and every touching
//!   triangle pair has to be listed anyway, so it could only add work.
//! - [`Accuracy::Fast`] is the thesis's pipeline. Everything it reports is true (the ACS triangle
//!   pairs are decided by the exact test; a pair whose ACS yields no touching pair gets the full
//!   exact query). Its error is one-sided and bounded by the image resolution: with `s` the
//!   pixel size of the pair's view (the longer lateral side of the two boxes' overlap divided
//!   by [`Options::image_resolution`]) and the depth/lateral bounds of `frcd-image`
//!   ([`frcd_image::ErrorBounds`]), a body pair is missed only when no pixel-centre ray of the
//!   view meets `A ∩ B` (up to the detector's stated perturbation); an intersection that
//!   contains a ball of radius `s/√2 + separation` is always found. Touching contact of zero
//!   volume is not reported. A reported pair may list fewer triangle pairs than the oracle:
//!   those touching outside the interfering pixels dilated by one pixel.
//!   Pairs with an open mesh (no solid, no ray parity) take the exact path.
//!
//! ## Skipping what a scene does not need
//!
//! No GPU feature, no adapter ([`GpuPolicy::Auto`]) or open meshes: the CPU path. Few bodies:
//! no GPU box pass. An empty RCS: nothing else runs. GPU devices are created only when the cost
//! model says some stage of this scene could use them. Every [`FrameResult`] says which backend
//! each stage used and how long it took ([`StageReport`]).
//!
//! ```
//! use frcd_hybrid::{BodySpec, Checker, FrameState, Options};
//! use frcd_geom::{shapes, DVec3, Pose};
//! use std::sync::Arc;
//! let ball = Arc::new(shapes::icosphere(1.0, 2));
//! let bodies = vec![
//!     BodySpec { name: "a".into(), mesh: ball.clone(), is_static: true },
//!     BodySpec { name: "b".into(), mesh: ball, is_static: false },
//! ];
//! let checker = Checker::new(bodies, &[], Options::default())?;
//! let mut state = FrameState::default();
//! let poses = [Pose::IDENTITY, Pose::from_translation(DVec3::new(1.5, 0.0, 0.0))];
//! let frame = checker.check(&poses, &mut state)?;
//! assert_eq!((frame.contacts[0].a, frame.contacts[0].b), (0, 1));
//! assert!(!frame.contacts[0].pairs.is_empty());
//! # Ok::<(), frcd_hybrid::HybridError>(())
//! ```
#![warn(missing_docs)]

#[cfg(feature = "image")]
mod acs;
pub mod calibrate;
mod checker;
mod cost;
mod error;
mod exact;
mod gpu;
mod options;
mod pipeline;
mod rcs;
mod report;
mod state;

pub use checker::Checker;
pub use cost::{CostModel, CostModelError};
pub use error::{GpuFailure, HybridError};
pub use frcd_obb::Containment;
pub use frcd_tritri::Contact;
#[cfg(any(feature = "gpgpu", feature = "image"))]
pub use gpu::GpuDevice;
pub use options::{Accuracy, Backend, BodySpec, GpuPolicy, Options};
pub use pipeline::Pipeline;
pub use report::{FrameResult, PairClearance, PairContact, Stage, StageBackend, StageReport, Via};
pub use state::FrameState;

#[cfg(test)]
mod send_sync {
    fn assert<T: Send + Sync>() {}
    #[test]
    fn types_are_send_sync() {
        assert::<crate::Checker>();
        assert::<crate::FrameState>();
        assert::<crate::Pipeline>();
        assert::<crate::FrameResult>();
        assert::<crate::CostModel>();
    }
}
