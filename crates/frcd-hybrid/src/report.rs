//! What a frame reports: contacts, clearances, stage backends and times.

use crate::{Contact, Containment};

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
    /// With [`Options::segments`](crate::Options::segments): the contact of each pair of `pairs`, in A's local frame.
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
    /// With [`crate::Options::clearance`] or per-pair thresholds: every pair within its
    /// threshold, sorted by `(a, b)`; interfering pairs with distance 0.
    pub clearances: Vec<PairClearance>,
    /// Work of this frame's clearance evaluations (pairs reused from the last frame not
    /// counted): pairs, pairs proved far by the motion bound, distance queries, exact decisions.
    pub clearance_work: frcd_obb::ClearanceWork,
    /// What happened this frame that the caller should know: GPU failures and the CPU fallback
    /// that answered instead.
    pub notes: Vec<String>,
}

/// A body pair within its clearance threshold, bodies named by index.
pub type PairClearance = frcd_obb::Clearance<usize>;

impl FrameResult {
    pub(crate) fn empty() -> Self {
        let skipped = |stage| StageReport {
            stage,
            backend: StageBackend::Skipped,
            time_us: 0.0,
            items: 0,
        };
        Self {
            contacts: Vec::new(),
            stages: [
                skipped(Stage::Broad),
                skipped(Stage::Image),
                skipped(Stage::Narrow),
            ],
            rcs: 0,
            reused: 0,
            image_dropped: 0,
            acs_triangles: 0,
            pair_times_us: Vec::new(),
            clearances: Vec::new(),
            clearance_work: frcd_obb::ClearanceWork::default(),
            notes: Vec::new(),
        }
    }

    /// Total time of the stages in microseconds.
    pub fn time_us(&self) -> f64 {
        self.stages.iter().map(|s| s.time_us).sum()
    }
}
