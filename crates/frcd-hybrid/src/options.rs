//! Options, modes, backends and body descriptions.

use crate::CostModel;
use frcd_geom::TriMesh;
use frcd_obb::BuildOptions;
use std::sync::Arc;

/// What the answer promises.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, Hash, Default, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "lowercase")]
pub enum Accuracy {
    /// Equal to the exact oracle: never loses a pair (see the crate docs).
    #[default]
    Exact,
    /// The thesis's RCS/ACS pipeline: one-sided error bounded by the image resolution.
    Fast,
}

impl Accuracy {
    /// `exact` or `fast`.
    pub fn name(self) -> &'static str {
        match self {
            Accuracy::Exact => "exact",
            Accuracy::Fast => "fast",
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
    /// GPU exact pair queries for every pair, and the box pass on the GPU from
    /// [`Options::gpgpu_box_pass_min_bodies`] bodies on (on the CPU below: the frame's
    /// [`StageReport`](crate::StageReport)s say which ran; feature `gpgpu`).
    Gpgpu,
    /// Image-space ACS for every pair of closed meshes ([`Accuracy::Fast`] only; feature `image`).
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
    /// [`crate::Checker::notes`]).
    #[default]
    Auto,
    /// Never create a GPU device.
    Off,
    /// Fail with [`HybridError::Gpu`](crate::HybridError::Gpu) when a wanted GPU device cannot be created.
    Require,
}

/// Options of a [`Checker`](crate::Checker). Plain data with [`Default`] (exact, hybrid, solid, no segments).
#[derive(Clone, Debug, PartialEq)]
pub struct Options {
    /// Exact or fast.
    pub mode: Accuracy,
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
    /// OBB trees the GPU pair traversal uploads (backend GPGPU, or the hybrid's GPU narrow
    /// phase), built only when a GPU is used (`None`: the collision trees of
    /// [`Options::build`]). Default: at most 2 triangles per leaf (frcd-obb's default, the
    /// trees every frcd-gpgpu benchmark and real-GPU figure used): on the software driver
    /// (lavapipe, 2 cores) the 64-part checker frame took 0.83-0.86 of its time with the
    /// collision trees' leaves of 4, timed in one process by
    /// `cargo xtask bench gpgpu --boxes-only --bodies 2 --checker-parts 64 --checker-gpu-leaves 1,2,3`
    /// and twice with `2,3` (2026-12-02); a leaf pair of 4 lists up to 16 triangle pairs for
    /// the triangle pass.
    /// The answers are the same either way: the GPU reports triangle pairs by the meshes' own
    /// indices, and the CPU re-decides each exactly.
    pub gpu_build: Option<BuildOptions>,
    /// Box tests per level the CPU may take off the GPU at the top of each GPU pair batch
    /// (frcd-gpgpu's `GpuContext::set_host_front`, feature `gpgpu`): the batch's first
    /// levels, too small to fill a GPU, are descended on the CPU and each saves a dispatch;
    /// the answers are the same. `None`: the context's default (1,024 on a software adapter
    /// such as lavapipe, 0 on a hardware one); `Some(0)`: the GPU starts at the roots.
    pub gpu_host_front: Option<u32>,
    /// How the GPU pair batch traverses (frcd-gpgpu's `GpuContext::set_one_pass`, feature
    /// `gpgpu`): `Some(0)`, one dispatch per level of the pair trees; `Some(n)`, every level
    /// and the triangle tests in one dispatch of `n` workgroups; `None`: the context's default
    /// (one pass on a software adapter such as lavapipe, where each dispatch costs more than a
    /// level's work; the level chain on a hardware one). The answers are the same.
    pub gpu_one_pass: Option<u32>,
    /// Re-decide on the CPU, with the exact test, every triangle pair the GPU pair traversal
    /// reports (default true; frcd-gpgpu's `Recheck::All`, feature `gpgpu`), or only those it
    /// left uncertain (false: `Recheck::Uncertain`). The GPU's *touching* verdicts are
    /// certified by the same error bounds as its *disjoint* ones (checked under every WGSL
    /// rounding mode by frcd-gpgpu's emulation tests), so the answers equal the oracle either
    /// way on a conforming driver; true also guards against one that is not, at the cost of
    /// an exact test per touching pair: 5-7 % of the 64-part checker frame on the software
    /// driver (lavapipe, 2026-12-02), 35 % of a 1.3M-triangle batch on an H200 (2026-11-27).
    pub gpu_recheck_certified: bool,
    /// Backend GPGPU: the body count from which the box pass (the rough colliding set) runs on
    /// the GPU; below it the CPU broad phase ([`frcd_obb::World`]) runs it, and a frame sends
    /// the GPU one submission (its pair batch) instead of two (`0` or `2`: the GPU box pass
    /// always). Default 1,024: on an NVIDIA H200 (2026-11-28) the GPU box pass first beat the
    /// CPU broad phase at 1,024 scattered bodies (0.19 against 0.27 ms) and took 5x its
    /// 0.03 ms at 256; on the software driver (lavapipe, 2 cores) it never wins, and in the
    /// 64-part checker frame it cost 0.54 ms of GPGPU `check`'s 5.0 against the CPU broad
    /// phase's 0.06 (2026-12-03). The answers are the same either way. The hybrid backend
    /// chooses by its cost model instead ([`CostModel::gpu_broad_min_bodies`]).
    pub gpgpu_box_pass_min_bodies: usize,
    /// OBB trees for the clearance distance searches, built only when a clearance threshold is
    /// set (`None`: the collision trees of [`Options::build`]). Default: at most 1 triangle per
    /// leaf: on the bogie demo the brake blocks' distance searches against the wheel treads
    /// (conformal surfaces 1-5 mm apart) took about half the time of leaf size 4.
    pub clearance_build: Option<BuildOptions>,
    /// Clearance threshold of the scene (scene units; `None`: no clearance, the default). Every
    /// tested body pair within it is reported in [`crate::FrameResult::clearances`] each frame,
    /// interfering pairs with distance 0; the broad phase is grown by it, and pairs farther
    /// apart cost no distance query.
    pub clearance: Option<f64>,
    /// Per body pair thresholds `((a, b), threshold)`, overriding `clearance` for that pair.
    pub pair_clearances: Vec<((usize, usize), f64)>,
    /// Look for bodies that are solids of revolution ([`frcd_obb::SpinProfile::detect`]) when a
    /// clearance threshold is set, and prove their pairs far with the meridian bound, which
    /// holds whatever angle such a body has turned to about its axis (default true: a spinning
    /// wheelset's pairs with the side frames need no distance search). The answers are the same
    /// either way.
    pub clearance_spin: bool,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            mode: Accuracy::Exact,
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
            gpu_build: Some(BuildOptions::default()),
            gpu_host_front: None,
            gpu_one_pass: None,
            gpu_recheck_certified: true,
            gpgpu_box_pass_min_bodies: 1024,
            clearance_build: Some(BuildOptions {
                max_leaf_triangles: 1,
                ..BuildOptions::default()
            }),
            clearance: None,
            pair_clearances: Vec::new(),
            clearance_spin: true,
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
