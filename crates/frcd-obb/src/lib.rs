#![doc = include_str!("../README.md")]
// The crate's unsafe code: the calls into the AVX2 and AVX-512 builds (traversal, front walk,
// the build's passes), entered only after the CPU was checked for their features (`isa.rs`),
// the AVX2 intrinsics of the traversal's eight-lane test (`wide::avx`), which only those
// builds run, and the `cpuid` that reads the CPU's vendor (`isa::amd`).
#![deny(unsafe_code)]
//! ## API overview
//!
//! - [`ObbTree::build`]: Gottschalk's OBBTree over a [`frcd_geom::TriMesh`] (fit rule
//!   selectable, mean-of-centroids split, configurable leaf size, flat depth-first nodes);
//! - [`collide`]: first contact or every touching triangle pair of two posed trees, tested in
//!   A's frame with a conservative 15-axis SAT (rounding can only keep a box pair), a hybrid
//!   top volume (sphere, AABB, root OBB), optional intersection segments and solid-mode
//!   containment;
//! - [`collide_cached`] with a caller-owned [`PairCache`]: witness pair, its neighbourhood
//!   (first contact, coherent motion), then a traversal front
//!   whose separated pairs keep their margins against a bound on the motion (no test while the
//!   margin holds), with a work budget that falls back to a fresh traversal; same answers as
//!   [`collide`];
//! - [`World`]: many bodies sharing `Arc<ObbTree>`s, a broad phase that keeps its candidate
//!   pairs over grown boxes and re-inserts only the bodies that leave them (a dynamic box tree;
//!   sweep-and-prune or a grid when many move far; [`overlapping_boxes`] on plain boxes) and a
//!   deterministic
//!   (rayon-parallel with the default `parallel` feature) narrow phase;
//! - [`oracle`]: the brute-force exact oracle every backend is compared with.
//!
//! With [`frcd_tritri::Method::Exact`] (the default) the pairs reported are exactly the
//! oracle's: the box tests are conservative and both map B's triangles into A's frame with the
//! same f64 operations ([`RelativeFrame`]).
#![warn(missing_docs)]

mod build;
mod checked;
pub mod distance;
mod isa;
mod nodes;
pub mod oracle;
mod query;
mod radix;
mod sat;
#[cfg(feature = "serde")]
mod saved;
mod solid;
#[cfg(test)]
mod test_rng;
mod tree;
mod wide;
mod world;

pub use checked::{PairSide, QueryError, try_collide, try_collide_cached};
pub use frcd_geom::fit::FitMethod;
pub use frcd_tritri::{Contact, Method};
pub use isa::{set_wide_traversal_isa, wide_traversal_isa};
pub use query::{
    Collision, Containment, Counters, Mode, PairCache, PairFront, RelativeFrame, Request,
    TopVolume, collide, collide_cached, containment,
};
#[cfg(feature = "serde")]
pub use saved::{LoadError, SavedTree};
pub use tree::{BuildOptions, Node, ObbTree, SplitMethod};
pub use world::{
    Apart, BodyContact, BodyId, BroadStats, Clearance, ClearanceCache, ClearanceWork,
    MAX_BOX_SLACK_PERCENT, SpinProfile, StepReport, StepTiming, World, WorldError, WorldOptions,
    overlapping_boxes, pair_clearance, pair_clearance_apart, pair_clearance_cached,
    pair_clearance_spin,
};
