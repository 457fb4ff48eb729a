//! Frame-to-frame state owned by the caller.

use crate::report::Via;
use crate::{Contact, Containment};
use frcd_geom::Pose;
use frcd_obb::{BodyId, Clearance, ClearanceCache, PairCache, World};
use std::collections::HashMap;

#[derive(Clone, Debug)]
pub(crate) struct Outcome {
    pub(crate) pairs: Vec<(u32, u32)>,
    pub(crate) contained: Option<Containment>,
    pub(crate) segments: Vec<Option<Contact>>,
    pub(crate) via: Via,
    pub(crate) clearance: Option<Clearance<()>>,
}

impl Outcome {
    pub(crate) fn collide(&self) -> bool {
        !self.pairs.is_empty() || self.contained.is_some()
    }
}

#[derive(Debug)]
pub(crate) struct PairState {
    pub(crate) poses: (Pose, Pose),
    pub(crate) result: Option<Outcome>,
    pub(crate) cache: PairCache,
    /// Temporal state of the clearance evaluation.
    pub(crate) clearance: ClearanceCache,
    /// What this pair's job took last frame (µs): the narrow phase starts the longest first.
    pub(crate) last_time_us: f64,
}

impl Default for PairState {
    fn default() -> Self {
        Self {
            poses: (Pose::IDENTITY, Pose::IDENTITY),
            result: None,
            cache: PairCache::new(),
            clearance: ClearanceCache::new(),
            last_time_us: 0.0,
        }
    }
}

/// Frame-to-frame state owned by the caller: the broad phase (an [`frcd_obb::World`] holding
/// the checker's bodies: its grown boxes and kept candidate pairs), per-pair coherence caches and last
/// answers, GPU scratch buffers. One per checker and thread of control: a state used with one
/// [`crate::Checker`] is refused by another ([`crate::HybridError::ForeignState`]) until
/// [`FrameState::reset`].
#[derive(Debug, Default)]
pub struct FrameState {
    /// Serial of the checker this state belongs to (0: none yet).
    pub(crate) owner: u64,
    /// The broad phase; body `i` of the checker is `ids[i]`.
    pub(crate) world: Option<World>,
    pub(crate) ids: Vec<BodyId>,
    pub(crate) pairs: HashMap<(u32, u32), PairState>,
    /// Scratch for the batch pose update.
    pub(crate) updates: Vec<(BodyId, Pose)>,
    #[cfg(feature = "gpgpu")]
    pub(crate) gpu_query: frcd_gpgpu::QueryScratch,
    #[cfg(feature = "gpgpu")]
    pub(crate) gpu_boxes: frcd_gpgpu::BoxScratch,
    /// GPU pair answers a pipelined run read before the frame (`crate::pipeline`).
    #[cfg(feature = "gpgpu")]
    pub(crate) gpu_answers: Option<crate::pipeline::GpuAnswers>,
    #[cfg(feature = "image")]
    pub(crate) image: frcd_image::ImageScratch,
}

impl FrameState {
    /// Forgets every cached answer and the broad phase's order (after a jump in the
    /// trajectory), and the checker it belonged to.
    pub fn reset(&mut self) {
        self.owner = 0;
        self.world = None;
        self.ids.clear();
        self.pairs.clear();
    }
}
