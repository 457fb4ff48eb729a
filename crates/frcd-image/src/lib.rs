#![doc = include_str!("../README.md")]
#![forbid(unsafe_code)]
//! ## API overview
//!
//! Image-space interference detection of two closed triangle meshes with wgpu: Zou's method (c),
//! i.e. Knott & Pai's CInDeR ray parity with depth and stencil buffers, inside the
//! RECODE / Heidelberger view volume cut to the overlap of the two bodies' boxes.
//!
//! ## How a query works
//!
//! 1. Everything happens in mesh A's local frame. B's pose relative to A is composed in f64; the
//!    overlap of A's box and B's (mapped) box is the *region* (boxes disjoint: no collision, no GPU
//!    work). An orthographic [`View`] looks along the region's shortest axis, with square pixels,
//!    `resolution` of them across the region's longer lateral side.
//! 2. Vertices live in GPU vertex buffers, uploaded once per mesh ([`ImageDetector::upload`]) as
//!    f32 relative to the mesh's box centre; per query one f32 matrix per mesh, composed in f64
//!    relative to the image centre, maps them to clip space.
//! 3. For mesh X ∈ {A, B} and the other mesh Y, the surface layers of X in the region are *peeled*
//!    front to back (depth test Less plus "strictly behind the previous layer" in the fragment
//!    shader, Depth32Float so the comparison is exact). For each layer, Y is drawn with depth test
//!    Less and stencil op Invert: stencil bit 0 becomes the parity of Y's faces in front of the
//!    layer, i.e. whether that surface point of X is inside solid Y. The depth range starts in
//!    front of both meshes' boxes, so faces of Y in front of the region still count: the view
//!    volume is cut to the region only laterally and behind.
//! 4. A compute pass per layer marks the pixel when the point is inside Y and adds the point's
//!    depth, with minus for a face where the ray enters X and plus where it leaves: summed over
//!    all layers of both meshes this is exactly the length of the pixel's ray inside `A ∩ B`
//!    (entries and exits of the intersection are surface points of one solid inside the other).
//!    Peeling stops when a layer is empty.
//! 5. The mask and lengths are read back once; `volume = Σ length × pixel area`. On request the
//!    accurate colliding set (triangles of A and B crossing the interfering pixels, dilated) is
//!    computed on the CPU with exact 2D triangle/pixel tests, because the software driver has no
//!    conservative rasterization.
//!
//! Answers are in **solid mode**: one solid wholly inside the other collides (its surface points
//! are inside the other solid). Meshes must be closed, manifold and consistently oriented
//! ([`ImageError::NotSolid`] otherwise).
//!
//! ## Error model (per query, in [`ErrorBounds`])
//!
//! Let `s` be the pixel size and `δ = 2⁻²⁰ · (depth range + ρ)` the depth bound (`ρ`: the meshes'
//! radii and centre distances from the image centre; it covers depth quantisation and f32
//! rounding of vertices, matrices and interpolation), and `ℓ = s/16 + δ` the lateral bound
//! (sub-pixel edge placement: Vulkan guarantees at least 4 sub-pixel bits).
//!
//! - **No false positive**: solids farther apart than `separation = 2(δ + ℓ)` produce no
//!   interfering pixel (what is rasterized is each solid with its vertices moved by at most
//!   `(ℓ, δ)`).
//! - **Misses** only interference thinner than a pixel across or within depth precision: a pixel
//!   reports exactly when its centre ray meets `A ∩ B` (up to the same perturbation), so an
//!   intersection containing a ball of radius `s/√2 + separation` is always detected. Because the
//!   view looks along the region's thinnest axis, a flat penetration (two bodies pressed
//!   together) is measured in depth, not in pixels.
//! - **Volume**: the midpoint rule over the pixels of the exact per-ray lengths; the error is
//!   concentrated at the rim of the projected intersection, estimated a posteriori in
//!   [`ImageResult::volume_error_estimate`].
//!
//! Tests check these with analytic answers (sphere lens volumes bracketed between the polyhedra's
//! in- and circumspheres, boxes at known overlaps, containment, gaps just above the bound) at
//! several resolutions, and pixel by pixel against [`reference::reference_image`], a CPU f64 ray
//! caster over the same pixel centres: every pixel where the GPU differs must be one the bounds
//! explain. `cargo xtask bench image` sweeps 64..2048 pixels.
//!
//! ## Measured (lavapipe, 2-core machine, `cargo xtask bench image` → `testdata/bench/image.md`)
//!
//! | resolution | boxes: ms / volume error | lens (2 × 20,480 tri): ms | corner: largest missed depth | edge: largest missed depth |
//! |---:|---:|---:|---:|---:|
//! | 64 | 0.9 / 1.96% | 41 | 8.8e-3 | 6.3e-3 |
//! | 256 | 4.9 / 0.48% | 51 | 1.6e-3 | 1.1e-3 |
//! | 1024 | 380 / 0.082% | 797 | 3.9e-4 | 5.5e-4 |
//! | 2048 | 1535 / 0.015% | 3615 | 2.8e-4 | 2.0e-4 |
//!
//! (Bodies of size ~2; the missed depths stay below the pixel size, as the error model says;
//! flat penetrations seen along the thin axis are found down to the depth bound, ~1e-5.)
//! `cargo xtask verify` runs this backend at 128 pixels against the exact oracle in solid mode
//! on every generated and stored scene.
//!
//! ## GPU
//!
//! [`ImageContext::from_device`] takes an engine's device and queue; [`ImageContext::headless`] finds
//! an adapter (a real GPU, or Mesa's software Vulkan driver lavapipe). No adapter is
//! [`ImageError::NoAdapter`]. Required: `DEPTH32FLOAT_STENCIL8`, compute shaders, 3 storage
//! buffers per stage; the resolution is bounded by the device's texture and storage-buffer limits.
//! Development and every measurement so far used lavapipe (no real GPU was available).
//! Backends: Vulkan (lavapipe included); Metal and DX12 should work (depth `textureLoad` and
//! stencil-aspect sampling are core WebGPU) but are untested. wgpu's GL backend cannot
//! translate `textureLoad` of a depth texture to GLSL: [`ImageDetector::new`] then fails with
//! [`ImageError::Gpu`] (stage "pipeline creation"), and the hybrid scheduler falls back.
//!
//! ```no_run
//! use frcd_image::{ImageDetector, ImageOptions, ImageScratch};
//! use frcd_geom::{shapes, Pose, DVec3};
//! let det = ImageDetector::headless()?;
//! let a = det.upload("a", &shapes::icosphere(1.0, 3))?;
//! let b = det.upload("b", &shapes::icosphere(1.0, 3))?;
//! let mut scratch = ImageScratch::default();
//! let r = det.query(&mut scratch, &a, &Pose::IDENTITY, &b,
//!     &Pose::from_translation(DVec3::new(1.5, 0.0, 0.0)), &ImageOptions::default())?;
//! assert!(r.collide);
//! println!("volume ≈ {} ± {}", r.volume, r.volume_error_estimate);
//! # Ok::<(), frcd_image::ImageError>(())
//! ```
#![warn(missing_docs)]

mod acs;
mod context;
mod detector;
mod error;
pub mod reference;
mod view;

pub use context::ImageContext;
pub use detector::{
    CollidingSet, ErrorBounds, ImageDetector, ImageMesh, ImageOptions, ImageResult, ImageScratch,
    PixelImage, check_solid,
};
#[doc(hidden)]
pub use detector::{RASTER_WGSL, RESOLVE_WGSL};
pub use error::{ImageError, Which};
pub use view::{View, ViewAxis};
/// The wgpu this crate is built on (to create a device for [`ImageContext::from_device`]).
pub use wgpu;

/// Every WGSL source of this crate, by file name (for validation and tooling).
#[doc(hidden)]
pub const SHADERS: &[(&str, &str)] =
    &[("raster.wgsl", RASTER_WGSL), ("resolve.wgsl", RESOLVE_WGSL)];

#[cfg(test)]
mod send_sync {
    fn assert<T: Send + Sync>() {}
    #[test]
    fn types_are_send_sync() {
        assert::<crate::ImageDetector>();
        assert::<crate::ImageMesh>();
        assert::<crate::ImageScratch>();
        assert::<crate::ImageContext>();
        assert::<crate::ImageResult>();
    }
}
