#![doc = include_str!("../README.md")]
#![forbid(unsafe_code)]
//! # frcd-hybrid
//!
//! The thesis's hybrid scheduler for many-body interference checking, stage by stage:
//!
//! 1. **Rough colliding set (RCS)**: body pairs whose world boxes overlap, minus static-static and
//!    excluded pairs. CPU sweep and prune (insertion sort on last frame's order), or the
//!    all-pairs GPU box pass of `frcd-gpgpu` (feature `gpgpu`) from
//!    [`CostModel::gpu_broad_min_bodies`] bodies on. Both equal the f64 box test.
//! 2. **Accurate colliding set (ACS)**, [`Mode::Fast`] only: the image-space pass of
//!    `frcd-image` (feature `image`) on each RCS pair of closed meshes gives the triangles that
//!    cross interfering pixels; a pair without interfering pixel is dropped.
//! 3. **Exact triangle tests**: [`Mode::Exact`]: every RCS pair gets the exact OBB-tree query,
//!    on the CPU (rayon over pairs, with a per-pair temporal-coherence cache) or on the GPU
//!    (`frcd-gpgpu`'s whole traversal, exact re-decision of uncertain pairs) when
//!    [`CostModel::prefer_gpu_narrow`] says so for the pair's triangle count. [`Mode::Fast`]: the
//!    exact test on the ACS triangles only (CPU, rayon).
//!
//! Pairs whose two poses are bit-for-bit last frame's are answered from last frame.
//!
//! ## The two modes
//!
//! - [`Mode::Exact`] never loses a pair: the answer (interfering body pairs, every touching
//!   triangle pair, solid-mode containment) equals [`frcd_obb::oracle::answer`] for every
//!   non-excluded, not-both-static pair. The image stage is **not run** in this mode: ray parity
//!   sampled at pixel centres can prove interference but never its absence (it misses
//!   interference thinner than a pixel, and touching with zero volume), and every touching
//!   triangle pair has to be listed anyway, so it could only add work.
//! - [`Mode::Fast`] is the thesis's pipeline. Everything it reports is true (the ACS triangle
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

pub mod calibrate;
mod cost;

pub use cost::{CostModel, CostModelError};
pub use frcd_obb::Containment;
pub use frcd_tritri::Contact;

use frcd_geom::{Aabb, Pose, TriMesh, Triangle};
use frcd_obb::{BuildOptions, ObbTree, PairCache, RelativeFrame, Request, collide, collide_cached};
use rayon::prelude::*;
use std::collections::{HashMap, HashSet};
use std::sync::Arc;
use std::time::Instant;

/// What the answer promises.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, Hash, Default, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// Equal to the exact oracle: never loses a pair (see the crate docs).
    #[default]
    Exact,
    /// The thesis's RCS/ACS pipeline: one-sided error bounded by the image resolution.
    Fast,
}

impl Mode {
    /// `exact` or `fast`.
    pub fn name(self) -> &'static str {
        match self {
            Mode::Exact => "exact",
            Mode::Fast => "fast",
        }
    }
}

/// Which backends the scheduler may use.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, Hash, Default, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "lowercase")]
pub enum Backend {
    /// Choose per stage and per pair with the cost model.
    #[default]
    Hybrid,
    /// CPU only: sweep and prune, OBB trees, exact triangle tests.
    Cpu,
    /// GPU box pass and GPU exact pair queries for every pair (feature `gpgpu`).
    Gpgpu,
    /// Image-space ACS for every pair of closed meshes ([`Mode::Fast`] only; feature `image`).
    Image,
}

impl Backend {
    /// `hybrid`, `cpu`, `gpgpu` or `image`.
    pub fn name(self) -> &'static str {
        match self {
            Backend::Hybrid => "hybrid",
            Backend::Cpu => "cpu",
            Backend::Gpgpu => "gpgpu",
            Backend::Image => "image",
        }
    }
}

/// What to do when a GPU is wanted.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub enum GpuPolicy {
    /// Use one when the scene needs it and one is found; otherwise the CPU (noted in
    /// [`Checker::notes`]).
    #[default]
    Auto,
    /// Never create a GPU device.
    Off,
    /// Fail with [`HybridError::Gpu`] when a wanted GPU device cannot be created.
    Require,
}

/// Options of a [`Checker`]. Plain data with [`Default`] (exact, hybrid, solid, no segments).
#[derive(Clone, Debug, PartialEq)]
pub struct Options {
    /// Exact or fast.
    pub mode: Mode,
    /// Which backends may be used.
    pub backend: Backend,
    /// GPU device creation.
    pub gpu: GpuPolicy,
    /// Solid mode: closed bodies wholly inside one another interfere (default true).
    pub solid: bool,
    /// Also compute the contact (segment, point or polygon) of every touching triangle pair.
    pub segments: bool,
    /// Pixels across the longer lateral side of a pair's box overlap (image stage; default 256).
    pub image_resolution: u32,
    /// Measured costs and the thresholds derived from them.
    pub cost: CostModel,
    /// OBB tree build options (default: frcd-obb's fit rule, at most 4 triangles per leaf,
    /// which measured 1.5-1.8x faster than 1 on the bogie demo, whose long thin tread
    /// triangles pass a few millimetres from the brake blocks).
    pub build: BuildOptions,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            mode: Mode::Exact,
            backend: Backend::Hybrid,
            gpu: GpuPolicy::Auto,
            solid: true,
            segments: false,
            image_resolution: 256,
            cost: CostModel::default(),
            build: BuildOptions {
                max_leaf_triangles: 4,
                ..BuildOptions::default()
            },
        }
    }
}

/// One body of the scene.
#[derive(Clone, Debug)]
pub struct BodySpec {
    /// Name (for reports and errors).
    pub name: String,
    /// Mesh in the body's local frame; bodies sharing an `Arc` share one tree and one upload.
    pub mesh: Arc<TriMesh>,
    /// Static bodies are never tested against each other.
    pub is_static: bool,
}

/// Why a [`Checker`] was refused or a frame failed.
#[derive(Debug, thiserror::Error)]
pub enum HybridError {
    /// An exclusion names a body index out of range.
    #[error("excluded pair ({a}, {b}) names a body out of range (the scene has {count})")]
    BadExclusion {
        /// First index.
        a: usize,
        /// Second index.
        b: usize,
        /// Body count.
        count: usize,
    },
    /// `check` got a pose slice of the wrong length.
    #[error("{got} poses given for {expected} bodies")]
    PoseCount {
        /// Bodies.
        expected: usize,
        /// Poses given.
        got: usize,
    },
    /// A pose is not finite or its rotation is not a unit quaternion.
    #[error("pose of body '{body}' is not finite or not a unit rotation: {pose:?}")]
    InvalidPose {
        /// The body.
        body: String,
        /// The pose.
        pose: Pose,
    },
    /// The requested backend needs a cargo feature this build lacks.
    #[error("backend '{backend}' needs frcd-hybrid's cargo feature '{feature}'")]
    FeatureDisabled {
        /// The backend.
        backend: &'static str,
        /// The missing feature.
        feature: &'static str,
    },
    /// The image backend answers within a resolution bound only.
    #[error("the image backend is resolution-bounded: use mode 'fast' (exact mode never runs it)")]
    ImageNeedsFast,
    /// A GPU was required (by [`GpuPolicy::Require`] or a GPU backend) and failed.
    #[error("GPU ({stage}): {message}")]
    Gpu {
        /// Which GPU backend or stage.
        stage: &'static str,
        /// The cause.
        message: String,
    },
}

/// A pipeline stage.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Stage {
    /// Box tests: the rough colliding set.
    Broad,
    /// Image space: the accurate colliding set.
    Image,
    /// Exact triangle tests.
    Narrow,
}

/// Where a stage ran.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum StageBackend {
    /// Not run (nothing to do, or not needed in this mode).
    Skipped,
    /// On the CPU.
    Cpu,
    /// On the GPU.
    Gpu,
    /// Some pairs on the CPU, some on the GPU.
    Mixed,
}

/// Which backend ran one stage of one frame, on how many items, in how long.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StageReport {
    /// The stage.
    pub stage: Stage,
    /// Where it ran.
    pub backend: StageBackend,
    /// Wall time in microseconds.
    pub time_us: f64,
    /// Items handled: bodies (broad), pairs (image, narrow).
    pub items: usize,
}

/// How a pair's answer was obtained.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Via {
    /// CPU OBB-tree query.
    Cpu,
    /// GPU traversal (exact re-decision on the CPU).
    Gpu,
    /// Exact tests on the image-space colliding set.
    Acs,
    /// Last frame's answer (neither pose changed).
    Reused,
}

/// Two bodies that interfere.
#[derive(Clone, Debug, PartialEq)]
pub struct PairContact {
    /// Lower body index.
    pub a: usize,
    /// Higher body index.
    pub b: usize,
    /// Touching triangle pairs `(tri of a, tri of b)`, sorted.
    pub pairs: Vec<(u32, u32)>,
    /// Solid mode: containment when no surface pair touches.
    pub contained: Option<Containment>,
    /// With [`Options::segments`]: the contact of each pair of `pairs`, in A's local frame.
    pub segments: Vec<Option<Contact>>,
    /// How the answer was obtained.
    pub via: Via,
}

/// The answer for one frame.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameResult {
    /// Interfering body pairs, sorted by `(a, b)`.
    pub contacts: Vec<PairContact>,
    /// Broad, image, narrow, in that order.
    pub stages: [StageReport; 3],
    /// Size of the rough colliding set (body pairs).
    pub rcs: usize,
    /// Pairs answered from last frame.
    pub reused: usize,
    /// Pairs the image stage dropped (no interfering pixel).
    pub image_dropped: usize,
    /// Triangles in the accurate colliding sets of this frame (both bodies, all pairs).
    pub acs_triangles: usize,
    /// Narrow-phase time of each RCS pair answered this frame (`a`, `b`, µs; CPU work of the
    /// pair, after any GPU query), for profiling which pairs dominate.
    pub pair_times_us: Vec<(usize, usize, f64)>,
}

impl FrameResult {
    /// Total time of the stages in microseconds.
    pub fn time_us(&self) -> f64 {
        self.stages.iter().map(|s| s.time_us).sum()
    }
}

#[derive(Clone, Debug)]
struct Outcome {
    pairs: Vec<(u32, u32)>,
    contained: Option<Containment>,
    segments: Vec<Option<Contact>>,
    via: Via,
}

impl Outcome {
    fn collide(&self) -> bool {
        !self.pairs.is_empty() || self.contained.is_some()
    }
}

#[derive(Debug)]
struct PairState {
    poses: (Pose, Pose),
    result: Option<Outcome>,
    cache: PairCache,
}

impl Default for PairState {
    fn default() -> Self {
        Self {
            poses: (Pose::IDENTITY, Pose::IDENTITY),
            result: None,
            cache: PairCache::new(),
        }
    }
}

/// Frame-to-frame state owned by the caller: the broad phase's order, per-pair coherence caches
/// and last answers, GPU scratch buffers. One per scene and thread of control.
#[derive(Debug, Default)]
pub struct FrameState {
    order: Vec<u32>,
    pairs: HashMap<(u32, u32), PairState>,
    #[cfg(feature = "gpgpu")]
    gpu_query: frcd_gpgpu::QueryScratch,
    #[cfg(feature = "gpgpu")]
    gpu_boxes: frcd_gpgpu::BoxScratch,
    #[cfg(feature = "image")]
    image: frcd_image::ImageScratch,
}

impl FrameState {
    /// Forgets every cached answer and order (after a jump in the trajectory).
    pub fn reset(&mut self) {
        self.order.clear();
        self.pairs.clear();
    }
}

#[derive(Debug)]
struct BodyInfo {
    name: String,
    mesh: usize,
    is_static: bool,
}

#[cfg(feature = "gpgpu")]
#[derive(Debug)]
struct Gpgpu {
    ctx: frcd_gpgpu::GpuContext,
    meshes: Vec<frcd_gpgpu::GpuMesh>,
}

#[cfg(feature = "image")]
#[derive(Debug)]
struct Image {
    det: frcd_image::ImageDetector,
    /// Per mesh: `None` for a mesh that is not a closed oriented manifold.
    meshes: Vec<Option<frcd_image::GpuMesh>>,
}

/// The scheduler: trees built once per distinct mesh, GPU uploads made once; [`Checker::check`]
/// answers one frame.
#[derive(Debug)]
pub struct Checker {
    bodies: Vec<BodyInfo>,
    meshes: Vec<Arc<TriMesh>>,
    trees: Vec<Arc<ObbTree>>,
    excluded: HashSet<(u32, u32)>,
    options: Options,
    notes: Vec<String>,
    #[cfg(feature = "gpgpu")]
    gpgpu: Option<Gpgpu>,
    #[cfg(feature = "image")]
    image: Option<Image>,
}

/// A conservative world box (as `frcd_obb::World`'s): the local box mapped by the pose, grown by
/// a relative margin that covers the rounding of the pair queries' relative frames.
fn world_box(tree: &ObbTree, pose: &Pose) -> Aabb {
    let b = tree.aabb().transformed(pose);
    let mag = b.min.abs().max(b.max.abs()).max_element();
    b.inflated(mag * 1e-12 + f64::MIN_POSITIVE)
}

impl Checker {
    /// Builds one OBB tree per distinct mesh and, when the options and the scene call for them
    /// (and the features are compiled in), the GPU devices and uploads. `exclude` lists body
    /// index pairs never tested.
    pub fn new(
        bodies: Vec<BodySpec>,
        exclude: &[(usize, usize)],
        options: Options,
    ) -> Result<Self, HybridError> {
        let count = bodies.len();
        let mut excluded = HashSet::new();
        for &(a, b) in exclude {
            if a >= count || b >= count {
                return Err(HybridError::BadExclusion { a, b, count });
            }
            excluded.insert((a.min(b) as u32, a.max(b) as u32));
        }
        match options.backend {
            Backend::Gpgpu if !cfg!(feature = "gpgpu") => {
                return Err(HybridError::FeatureDisabled {
                    backend: "gpgpu",
                    feature: "gpgpu",
                });
            }
            Backend::Image if !cfg!(feature = "image") => {
                return Err(HybridError::FeatureDisabled {
                    backend: "image",
                    feature: "image",
                });
            }
            Backend::Image if options.mode == Mode::Exact => {
                return Err(HybridError::ImageNeedsFast);
            }
            _ => {}
        }
        let mut meshes: Vec<Arc<TriMesh>> = Vec::new();
        let mut index: HashMap<*const TriMesh, usize> = HashMap::new();
        let mut infos = Vec::with_capacity(count);
        for b in bodies {
            let k = Arc::as_ptr(&b.mesh);
            let mesh = *index.entry(k).or_insert_with(|| {
                meshes.push(b.mesh.clone());
                meshes.len() - 1
            });
            infos.push(BodyInfo {
                name: b.name,
                mesh,
                is_static: b.is_static,
            });
        }
        let build = options.build;
        let trees: Vec<Arc<ObbTree>> = meshes
            .par_iter()
            .map(|m| Arc::new(ObbTree::build(m, &build)))
            .collect();
        #[allow(unused_mut)]
        let mut checker = Checker {
            bodies: infos,
            meshes,
            trees,
            excluded,
            options,
            notes: Vec::new(),
            #[cfg(feature = "gpgpu")]
            gpgpu: None,
            #[cfg(feature = "image")]
            image: None,
        };
        checker.init_gpu()?;
        Ok(checker)
    }

    /// Largest triangle count of a testable body pair (for the GPU narrow-phase decision).
    fn max_pair_triangles(&self) -> usize {
        let mut best = 0;
        let tri = |i: usize| self.meshes[self.bodies[i].mesh].triangle_count();
        for i in 0..self.bodies.len() {
            for j in i + 1..self.bodies.len() {
                if !self.testable(i as u32, j as u32) {
                    continue;
                }
                best = best.max(tri(i) + tri(j));
            }
        }
        best
    }

    fn testable(&self, i: u32, j: u32) -> bool {
        let (a, b) = (&self.bodies[i as usize], &self.bodies[j as usize]);
        let both_static = a.is_static && b.is_static;
        !both_static && !self.excluded.contains(&(i.min(j), i.max(j)))
    }

    fn init_gpu(&mut self) -> Result<(), HybridError> {
        let o = self.options.clone();
        if o.gpu == GpuPolicy::Off {
            if matches!(o.backend, Backend::Gpgpu | Backend::Image) {
                return Err(HybridError::Gpu {
                    stage: "init",
                    message: format!(
                        "backend '{}' needs a GPU but GPU use is off",
                        o.backend.name()
                    ),
                });
            }
            return Ok(());
        }
        let n = self.bodies.len();
        let want_gpgpu = match o.backend {
            Backend::Gpgpu => true,
            Backend::Hybrid => {
                o.cost.gpu_broad_min_bodies().is_some_and(|m| n >= m)
                    || (o.mode == Mode::Exact
                        && o.cost
                            .gpu_narrow_min_triangles()
                            .is_some_and(|t| self.max_pair_triangles() >= t))
            }
            _ => false,
        };
        let want_image = o.mode == Mode::Fast
            && match o.backend {
                Backend::Image => true,
                Backend::Hybrid => o.cost.image_us.is_some(),
                _ => false,
            }
            && self.meshes.iter().any(|m| m.topology().is_closed());
        let hard =
            o.gpu == GpuPolicy::Require || matches!(o.backend, Backend::Gpgpu | Backend::Image);
        let _ = hard; // used only with the GPU features
        if want_gpgpu {
            #[cfg(feature = "gpgpu")]
            match self.make_gpgpu() {
                Ok(g) => self.gpgpu = Some(g),
                Err(message) if hard => {
                    return Err(HybridError::Gpu {
                        stage: "gpgpu",
                        message,
                    });
                }
                Err(message) => self
                    .notes
                    .push(format!("gpgpu unavailable, CPU used: {message}")),
            }
            #[cfg(not(feature = "gpgpu"))]
            if o.gpu == GpuPolicy::Require {
                return Err(HybridError::FeatureDisabled {
                    backend: "hybrid",
                    feature: "gpgpu",
                });
            }
        }
        if want_image {
            #[cfg(feature = "image")]
            match self.make_image() {
                Ok(g) => self.image = Some(g),
                Err(message) if hard => {
                    return Err(HybridError::Gpu {
                        stage: "image",
                        message,
                    });
                }
                Err(message) => self.notes.push(format!(
                    "image space unavailable, exact CPU path used: {message}"
                )),
            }
            #[cfg(not(feature = "image"))]
            if o.gpu == GpuPolicy::Require {
                return Err(HybridError::FeatureDisabled {
                    backend: "hybrid",
                    feature: "image",
                });
            }
        }
        Ok(())
    }

    #[cfg(feature = "gpgpu")]
    fn make_gpgpu(&self) -> Result<Gpgpu, String> {
        let ctx = frcd_gpgpu::GpuContext::headless().map_err(|e| e.to_string())?;
        let meshes = self
            .trees
            .iter()
            .map(|t| ctx.upload(t))
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| e.to_string())?;
        Ok(Gpgpu { ctx, meshes })
    }

    #[cfg(feature = "image")]
    fn make_image(&mut self) -> Result<Image, String> {
        let det = frcd_image::ImageDetector::headless().map_err(|e| e.to_string())?;
        let mut meshes = Vec::with_capacity(self.meshes.len());
        for (i, m) in self.meshes.iter().enumerate() {
            let name = self
                .bodies
                .iter()
                .find(|b| b.mesh == i)
                .map_or(String::new(), |b| b.name.clone());
            match det.upload_shared(&name, m.clone()) {
                Ok(g) => meshes.push(Some(g)),
                Err(frcd_image::ImageError::NotSolid { name, .. }) => {
                    self.notes.push(format!(
                        "mesh of '{name}' is not a closed oriented manifold: its pairs take the exact path"
                    ));
                    meshes.push(None);
                }
                Err(e) => return Err(e.to_string()),
            }
        }
        Ok(Image { det, meshes })
    }

    /// Number of bodies.
    pub fn len(&self) -> usize {
        self.bodies.len()
    }

    /// True without bodies.
    pub fn is_empty(&self) -> bool {
        self.bodies.is_empty()
    }

    /// Name of body `i`.
    pub fn body_name(&self, i: usize) -> Option<&str> {
        self.bodies.get(i).map(|b| b.name.as_str())
    }

    /// Mesh of body `i` (local frame).
    pub fn body_mesh(&self, i: usize) -> Option<&Arc<TriMesh>> {
        self.bodies.get(i).map(|b| &self.meshes[b.mesh])
    }

    /// The options.
    pub fn options(&self) -> &Options {
        &self.options
    }

    /// What the constructor decided about GPUs and meshes (fallbacks, open meshes), one line
    /// each.
    pub fn notes(&self) -> &[String] {
        &self.notes
    }

    /// True when a GPU box pass / pair query device is in use.
    pub fn has_gpgpu(&self) -> bool {
        #[cfg(feature = "gpgpu")]
        return self.gpgpu.is_some();
        #[cfg(not(feature = "gpgpu"))]
        false
    }

    /// True when an image-space device is in use.
    pub fn has_image(&self) -> bool {
        #[cfg(feature = "image")]
        return self.image.is_some();
        #[cfg(not(feature = "image"))]
        false
    }

    /// Adapter names of the GPU devices in use (empty when none).
    pub fn adapters(&self) -> Vec<String> {
        #[allow(unused_mut)]
        let mut out = Vec::new();
        #[cfg(feature = "gpgpu")]
        if let Some(g) = &self.gpgpu {
            out.push(format!("gpgpu: {}", g.ctx.adapter_info().name));
        }
        #[cfg(feature = "image")]
        if let Some(g) = &self.image {
            out.push(format!("image: {}", g.det.context().adapter_name()));
        }
        out
    }

    /// Rough colliding set on the CPU: sweep and prune along x, insertion sort on last order.
    fn sweep_and_prune(&self, boxes: &[Aabb], order: &mut Vec<u32>) -> Vec<(u32, u32)> {
        if order.len() != boxes.len() {
            *order = (0..boxes.len() as u32).collect();
        }
        let key = |i: u32| boxes[i as usize].min.x;
        // Insertion sort: near linear under coherent motion.
        for i in 1..order.len() {
            let mut j = i;
            while j > 0 && key(order[j - 1]).total_cmp(&key(order[j])).is_gt() {
                order.swap(j - 1, j);
                j -= 1;
            }
        }
        let mut out = Vec::new();
        for (p, &i) in order.iter().enumerate() {
            let bi = &boxes[i as usize];
            for &j in &order[p + 1..] {
                let bj = &boxes[j as usize];
                if bj.min.x > bi.max.x {
                    break;
                }
                if bi.intersects(bj) && self.testable(i, j) {
                    out.push((i.min(j), i.max(j)));
                }
            }
        }
        out.sort_unstable();
        out
    }

    /// Answers one frame: `poses[i]` is body `i`'s world pose.
    pub fn check(
        &self,
        poses: &[Pose],
        state: &mut FrameState,
    ) -> Result<FrameResult, HybridError> {
        let n = self.bodies.len();
        if poses.len() != n {
            return Err(HybridError::PoseCount {
                expected: n,
                got: poses.len(),
            });
        }
        if let Some(i) = poses.iter().position(|p| !p.is_valid()) {
            return Err(HybridError::InvalidPose {
                body: self.bodies[i].name.clone(),
                pose: poses[i],
            });
        }
        #[allow(unused_variables)]
        let o = &self.options;
        // Stage 1: rough colliding set.
        let t0 = Instant::now();
        let boxes: Vec<Aabb> = (0..n)
            .map(|i| world_box(&self.trees[self.bodies[i].mesh], &poses[i]))
            .collect();
        #[allow(unused_mut)]
        let mut broad_backend = StageBackend::Cpu;
        #[allow(unused_mut)]
        let mut rcs: Option<Vec<(u32, u32)>> = None;
        #[cfg(feature = "gpgpu")]
        if let Some(g) = &self.gpgpu {
            let use_gpu = o.backend == Backend::Gpgpu
                || o.cost.gpu_broad_min_bodies().is_some_and(|m| n >= m);
            if use_gpu && n >= 2 {
                let found = g
                    .ctx
                    .overlapping_bodies(&boxes, &mut state.gpu_boxes)
                    .map_err(|e| HybridError::Gpu {
                        stage: "box pass",
                        message: e.to_string(),
                    })?;
                let mut v: Vec<(u32, u32)> = found
                    .pairs
                    .into_iter()
                    .map(|(i, j)| (i.min(j), i.max(j)))
                    .filter(|&(i, j)| self.testable(i, j))
                    .collect();
                v.sort_unstable();
                rcs = Some(v);
                broad_backend = StageBackend::Gpu;
            }
        }
        let rcs = match rcs {
            Some(v) => v,
            None => self.sweep_and_prune(&boxes, &mut state.order),
        };
        let broad = StageReport {
            stage: Stage::Broad,
            backend: broad_backend,
            time_us: t0.elapsed().as_secs_f64() * 1e6,
            items: n,
        };
        let mut result = FrameResult {
            contacts: Vec::new(),
            stages: [
                broad,
                StageReport {
                    stage: Stage::Image,
                    backend: StageBackend::Skipped,
                    time_us: 0.0,
                    items: 0,
                },
                StageReport {
                    stage: Stage::Narrow,
                    backend: StageBackend::Skipped,
                    time_us: 0.0,
                    items: 0,
                },
            ],
            rcs: rcs.len(),
            reused: 0,
            image_dropped: 0,
            acs_triangles: 0,
            pair_times_us: Vec::new(),
        };
        // Take the states of the RCS pairs; pairs that left the RCS are forgotten.
        let mut old = std::mem::take(&mut state.pairs);
        let mut work: Vec<Job> = rcs
            .iter()
            .map(|&k| {
                let st = old.remove(&k).unwrap_or_default();
                let cur = (poses[k.0 as usize], poses[k.1 as usize]);
                let reuse = st.result.is_some() && st.poses == cur;
                Job {
                    key: k,
                    state: st,
                    plan: if reuse { Plan::Reuse } else { Plan::Cpu },
                    time_us: 0.0,
                }
            })
            .collect();
        drop(old);
        // Stage 2: accurate colliding set (fast mode).
        #[cfg(feature = "image")]
        if o.mode == Mode::Fast {
            if let Some(img) = &self.image {
                let t1 = Instant::now();
                let mut ran = 0;
                for job in work.iter_mut().filter(|j| j.plan == Plan::Cpu) {
                    let (ia, ib) = (job.key.0 as usize, job.key.1 as usize);
                    let (ma, mb) = (self.bodies[ia].mesh, self.bodies[ib].mesh);
                    let (Some(ga), Some(gb)) = (&img.meshes[ma], &img.meshes[mb]) else {
                        continue;
                    };
                    if o.backend == Backend::Hybrid {
                        let tris =
                            self.meshes[ma].triangle_count() + self.meshes[mb].triangle_count();
                        let cpu_ns = o.cost.cpu_narrow_ns_per_triangle * tris as f64;
                        if o.cost.image_us.is_none_or(|us| us * 1e3 >= cpu_ns) {
                            continue;
                        }
                    }
                    let opts = frcd_image::ImageOptions {
                        resolution: o.image_resolution,
                        colliding_set: true,
                        ..frcd_image::ImageOptions::default()
                    };
                    let r = img
                        .det
                        .query(&mut state.image, ga, &poses[ia], gb, &poses[ib], &opts)
                        .map_err(|e| HybridError::Gpu {
                            stage: "image",
                            message: e.to_string(),
                        })?;
                    ran += 1;
                    job.plan = match (r.collide, r.colliding_set) {
                        (true, Some(cs)) => {
                            result.acs_triangles += cs.tris_a.len() + cs.tris_b.len();
                            Plan::Acs(cs.tris_a, cs.tris_b)
                        }
                        (true, None) => Plan::Cpu,
                        (false, _) => {
                            result.image_dropped += 1;
                            Plan::Dropped
                        }
                    };
                }
                if ran > 0 {
                    result.stages[1] = StageReport {
                        stage: Stage::Image,
                        backend: StageBackend::Gpu,
                        time_us: t1.elapsed().as_secs_f64() * 1e6,
                        items: ran,
                    };
                }
            }
        }
        // Stage 3: exact triangle tests.
        let t2 = Instant::now();
        #[allow(unused_mut)]
        let mut gpu_pairs = 0usize;
        #[cfg(feature = "gpgpu")]
        if o.mode == Mode::Exact {
            if let Some(g) = &self.gpgpu {
                for job in work.iter_mut().filter(|j| j.plan == Plan::Cpu) {
                    let (ia, ib) = (job.key.0 as usize, job.key.1 as usize);
                    let (ma, mb) = (self.bodies[ia].mesh, self.bodies[ib].mesh);
                    let tris = self.meshes[ma].triangle_count() + self.meshes[mb].triangle_count();
                    if o.backend != Backend::Gpgpu && !o.cost.prefer_gpu_narrow(tris) {
                        continue;
                    }
                    let hit = g
                        .ctx
                        .collide(
                            &g.meshes[ma],
                            &poses[ia],
                            &g.meshes[mb],
                            &poses[ib],
                            &mut state.gpu_query,
                        )
                        .map_err(|e| HybridError::Gpu {
                            stage: "pair query",
                            message: e.to_string(),
                        })?;
                    job.plan = Plan::GpuDone(hit.pairs);
                    gpu_pairs += 1;
                }
            }
        }
        let cpu_pairs = work
            .iter()
            .filter(|j| !matches!(j.plan, Plan::Reuse | Plan::Dropped))
            .count()
            - gpu_pairs;
        work.par_iter_mut()
            .for_each(|job| self.finish_job(job, poses));
        if gpu_pairs + cpu_pairs > 0 {
            result.stages[2] = StageReport {
                stage: Stage::Narrow,
                backend: match (cpu_pairs > 0, gpu_pairs > 0) {
                    (true, true) => StageBackend::Mixed,
                    (false, true) => StageBackend::Gpu,
                    _ => StageBackend::Cpu,
                },
                time_us: t2.elapsed().as_secs_f64() * 1e6,
                items: cpu_pairs + gpu_pairs,
            };
        }
        for job in work {
            let out = job.state.result.as_ref().expect("every job answered");
            if job.plan == Plan::Reuse {
                result.reused += 1;
            } else {
                result
                    .pair_times_us
                    .push((job.key.0 as usize, job.key.1 as usize, job.time_us));
            }
            if out.collide() {
                result.contacts.push(PairContact {
                    a: job.key.0 as usize,
                    b: job.key.1 as usize,
                    pairs: out.pairs.clone(),
                    contained: out.contained,
                    segments: out.segments.clone(),
                    via: if job.plan == Plan::Reuse {
                        Via::Reused
                    } else {
                        out.via
                    },
                });
            }
            state.pairs.insert(job.key, job.state);
        }
        Ok(result)
    }

    fn request(&self, mode: frcd_obb::Mode) -> Request {
        Request {
            mode,
            segments: self.options.segments,
            solid: self.options.solid,
            ..Request::default()
        }
    }

    /// Completes one job (CPU work; GPU results were stored in the plan).
    fn finish_job(&self, job: &mut Job, poses: &[Pose]) {
        let t = Instant::now();
        self.finish_job_inner(job, poses);
        job.time_us = t.elapsed().as_secs_f64() * 1e6;
    }

    fn finish_job_inner(&self, job: &mut Job, poses: &[Pose]) {
        let (ia, ib) = (job.key.0 as usize, job.key.1 as usize);
        let (pa, pb) = (&poses[ia], &poses[ib]);
        let (ta, tb) = (
            &self.trees[self.bodies[ia].mesh],
            &self.trees[self.bodies[ib].mesh],
        );
        let plan = std::mem::replace(&mut job.plan, Plan::Cpu);
        let outcome = match plan {
            Plan::Reuse => {
                job.plan = Plan::Reuse;
                return;
            }
            Plan::Dropped => Outcome {
                pairs: Vec::new(),
                contained: None,
                segments: Vec::new(),
                via: Via::Acs,
            },
            Plan::Cpu => self.cpu_query(ta, pa, tb, pb, &mut job.state.cache),
            Plan::GpuDone(pairs) => {
                let contained = if pairs.is_empty() && self.options.solid {
                    collide(ta, pa, tb, pb, &self.request(frcd_obb::Mode::FirstContact)).contained
                } else {
                    None
                };
                let segments = self.segments_of(&pairs, ta, pa, tb, pb);
                Outcome {
                    pairs,
                    contained,
                    segments,
                    via: Via::Gpu,
                }
            }
            Plan::Acs(sa, sb) => {
                let tri_a: Vec<Triangle> = sa.iter().map(|&i| ta.triangles()[i as usize]).collect();
                let tri_b: Vec<Triangle> = sb.iter().map(|&i| tb.triangles()[i as usize]).collect();
                let mut pairs: Vec<(u32, u32)> =
                    frcd_obb::oracle::pairs_of_triangles(&tri_a, pa, &tri_b, pb)
                        .into_iter()
                        .map(|(x, y)| (sa[x as usize], sb[y as usize]))
                        .collect();
                pairs.sort_unstable();
                if pairs.is_empty() {
                    // Image space saw interference but the ACS holds no touching pair:
                    // containment or a contact outside the dilated pixels; ask the exact query.
                    let mut o = self.cpu_query(ta, pa, tb, pb, &mut job.state.cache);
                    o.via = Via::Acs;
                    o
                } else {
                    let segments = self.segments_of(&pairs, ta, pa, tb, pb);
                    Outcome {
                        pairs,
                        contained: None,
                        segments,
                        via: Via::Acs,
                    }
                }
            }
        };
        job.plan = Plan::Cpu;
        job.state.poses = (*pa, *pb);
        job.state.result = Some(outcome);
    }

    fn cpu_query(
        &self,
        ta: &ObbTree,
        pa: &Pose,
        tb: &ObbTree,
        pb: &Pose,
        cache: &mut PairCache,
    ) -> Outcome {
        let c = collide_cached(
            ta,
            pa,
            tb,
            pb,
            &self.request(frcd_obb::Mode::AllPairs),
            cache,
        );
        Outcome {
            pairs: c.pairs,
            contained: c.contained,
            segments: c.segments,
            via: Via::Cpu,
        }
    }

    fn segments_of(
        &self,
        pairs: &[(u32, u32)],
        ta: &ObbTree,
        pa: &Pose,
        tb: &ObbTree,
        pb: &Pose,
    ) -> Vec<Option<Contact>> {
        if !self.options.segments {
            return Vec::new();
        }
        let frame = RelativeFrame::new(pa, pb);
        pairs
            .iter()
            .map(|&(x, y)| {
                frcd_tritri::intersection_segment(
                    &ta.triangles()[x as usize],
                    &frame.triangle(&tb.triangles()[y as usize]),
                )
            })
            .collect()
    }
}

#[derive(Debug, PartialEq)]
#[cfg_attr(not(all(feature = "gpgpu", feature = "image")), allow(dead_code))]
enum Plan {
    /// Same poses as last frame: keep the answer.
    Reuse,
    /// CPU OBB-tree query.
    Cpu,
    /// GPU pairs found; containment and segments still to do.
    GpuDone(Vec<(u32, u32)>),
    /// Exact tests on the accurate colliding set.
    Acs(Vec<u32>, Vec<u32>),
    /// Image space found no interference (fast mode).
    Dropped,
}

struct Job {
    key: (u32, u32),
    state: PairState,
    plan: Plan,
    time_us: f64,
}

#[cfg(test)]
mod send_sync {
    fn assert<T: Send + Sync>() {}
    #[test]
    fn types_are_send_sync() {
        assert::<crate::Checker>();
        assert::<crate::FrameState>();
        assert::<crate::FrameResult>();
        assert::<crate::CostModel>();
    }
}
