//! Many bodies: generational handles, a broad phase that keeps its candidate pairs over grown
//! boxes from step to step (a dynamic box tree for the bodies that leave them; sweep-and-prune,
//! or a grid where the boxes crowd a volume, when many do), and a cached, deterministic,
//! parallel narrow phase whose results are borrowed from the [`World`].

mod boxes4;
mod boxtree;
mod broad;
mod clearance;
mod handle;

pub use broad::overlapping_boxes;
pub use clearance::{
    Apart, Clearance, ClearanceCache, ClearanceWork, SpinProfile, pair_clearance,
    pair_clearance_apart, pair_clearance_cached, pair_clearance_spin,
};
pub use handle::BodyId;

use crate::query::{Collision, Containment, Counters, Mode, PairCache, Request, collide_cached};
use crate::tree::ObbTree;
use broad::BroadPhase;
pub use broad::BroadStats;
use frcd_geom::{Aabb, DVec3, Pose};
use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Why a [`World`] call was refused.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum WorldError {
    /// The handle names a body that was removed (or never existed in this world).
    #[error("{id} is not in the world (removed, or its slot was reused)")]
    UnknownBody {
        /// The handle given.
        id: BodyId,
    },
    /// The handle was made by another [`World`].
    #[error("{id} belongs to another world")]
    ForeignBody {
        /// The handle given.
        id: BodyId,
    },
    /// A pose with a non-finite value or a rotation that is not a unit quaternion.
    #[error("invalid pose for {id}: {pose:?} (not finite, or not a unit rotation)")]
    InvalidPose {
        /// The body (for [`World::add_body`], the handle it would have had).
        id: BodyId,
        /// The pose given.
        pose: Pose,
    },
    /// A body paired with itself.
    #[error("{id} paired with itself")]
    SelfPair {
        /// The body.
        id: BodyId,
    },
    /// A clearance threshold that is negative or NaN.
    #[error("clearance threshold {value} is not a number >= 0")]
    InvalidClearance {
        /// The value given.
        value: f64,
    },
    /// More than `u32::MAX` body slots.
    #[error("the world holds the maximum number of bodies ({max})")]
    TooManyBodies {
        /// The limit.
        max: usize,
    },
}

/// The largest [`WorldOptions::box_slack_percent`] that takes effect.
pub const MAX_BOX_SLACK_PERCENT: u32 = 100;

/// Options of a [`World`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct WorldOptions {
    /// The pair query run on each candidate pair (default: all pairs, surface mode, exact).
    pub request: Request,
    /// Keep a [`PairCache`] per body pair (temporal coherence).
    pub coherence: bool,
    /// The broad phase keeps each body's box grown by this many percent of its largest side on
    /// every side, and its candidate pairs from step to step: a body that moves within its
    /// grown box costs the broad phase one exact box test per candidate pair and nothing else
    /// (default 10). Larger: fewer re-insertions, more candidates to test; 0: tight boxes, every
    /// move re-inserts the body. The answers do not depend on it. At most
    /// [`MAX_BOX_SLACK_PERCENT`]: larger values act as that (the kept candidates grow with the
    /// grown boxes' overlaps, so a huge slack would hold about every pair of bodies).
    pub box_slack_percent: u32,
}

impl Default for WorldOptions {
    fn default() -> Self {
        Self {
            request: Request {
                mode: Mode::AllPairs,
                ..Request::default()
            },
            coherence: true,
            box_slack_percent: 10,
        }
    }
}

/// Two bodies that interfere, borrowed from the [`World`] that found them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BodyContact<'w> {
    /// The body with the lower slot index.
    pub a: BodyId,
    /// The body with the higher slot index.
    pub b: BodyId,
    /// Touching triangle pairs `(tri of a, tri of b)`, sorted (empty in first-contact mode).
    pub pairs: &'w [(u32, u32)],
    /// A touching pair, when there is one.
    pub witness: Option<(u32, u32)>,
    /// Solid mode: containment when no surface pair touches.
    pub contained: Option<Containment>,
}

/// What the last [`World::step`] found and how much work it took; borrows the world, so nothing
/// is copied but the small per-contact headers.
#[derive(Clone, Debug, PartialEq)]
pub struct StepReport<'w> {
    /// Interfering body pairs, sorted by slot index `(a, b)`; identical for any thread count.
    pub contacts: Vec<BodyContact<'w>>,
    /// With a clearance threshold ([`World::set_clearance`], [`World::set_pair_clearance`]):
    /// every pair within its threshold, interfering pairs included (distance 0), sorted like
    /// `contacts`.
    pub clearances: &'w [Clearance],
    /// Body pairs the narrow phase looked at: world boxes overlap, not both static, not excluded.
    pub candidates: usize,
    /// Candidate pairs answered from the previous step because neither pose changed.
    pub reused: usize,
    /// Work of the narrow-phase queries run this step.
    pub counters: Counters,
    /// Work of the clearance evaluations run this step (pairs reused from the last step not
    /// counted).
    pub clearance_work: ClearanceWork,
}

#[derive(Debug)]
pub(crate) struct Body {
    pub(crate) tree: Arc<ObbTree>,
    pub(crate) is_static: bool,
    /// Bumped on teleport: pair caches made before it are dropped.
    epoch: u32,
    /// Pairs never tested, by partner (few per body).
    excluded: Vec<BodyId>,
    /// Per-pair clearance thresholds, by partner.
    thresholds: Vec<(BodyId, f64)>,
}

/// A body slot: small (16 bytes), so that the broad phase's pass over the pairs reads the
/// handles and the pair filter's flags from a compact array; the body itself is boxed.
#[derive(Debug)]
struct Slot {
    generation: u32,
    /// The body is static (a copy of `Body::is_static`).
    is_static: bool,
    /// The body may have excluded partners (set by [`World::exclude_pair`], cleared when the
    /// slot is reused): pairs of slots without it skip the exclusion lists.
    may_exclude: bool,
    body: Option<Box<Body>>,
}

/// What a pose update writes, by slot, in one dense array (one cache line per body): `set_poses`
/// on many bodies streams these, the local boxes and the broad phase's world boxes instead of
/// each body's boxed record (about 5 MB a call at 16,384 bodies went through the records).
/// The world box itself is the broad phase's (`BroadPhase::tight_box`).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
struct Placement {
    pose: Pose,
    /// Bumped on every pose change: a pair whose two versions are unchanged is not re-queried.
    version: u64,
}

#[derive(Debug)]
struct PairState {
    versions: (u64, u64),
    epochs: (u32, u32),
    /// The threshold of the last answer (`None`: no clearance asked).
    threshold: Option<f64>,
    answered: bool,
    /// The collision answer (`None` when the raw boxes did not overlap: no interference).
    result: Option<Collision>,
    clearance: Option<Clearance<()>>,
    cache: PairCache,
    /// Temporal state of the clearance evaluation.
    clearance_cache: ClearanceCache,
    /// Work of the last clearance evaluation.
    clearance_work: ClearanceWork,
    /// Time the last evaluation took, in nanoseconds (`u64::MAX` before the first): the
    /// estimate by which the next step orders the pairs, largest first.
    cost_ns: u64,
}

impl PairState {
    fn new() -> Self {
        Self {
            versions: (u64::MAX, u64::MAX),
            epochs: (0, 0),
            threshold: None,
            answered: false,
            result: None,
            clearance: None,
            cache: PairCache::new(),
            clearance_cache: ClearanceCache::new(),
            clearance_work: ClearanceWork::default(),
            cost_ns: u64::MAX,
        }
    }
}

#[derive(Debug)]
struct PairEntry {
    a: BodyId,
    b: BodyId,
    /// The raw world boxes overlap: the collision query runs.
    overlap: bool,
    threshold: Option<f64>,
    /// Answered from the previous step (set by [`World::step`] before the narrow phase).
    reused: bool,
    /// Boxed: the merge of each step moves the entries, and the state is most of their size.
    state: Box<PairState>,
}

/// Where the time of the last [`World::step`] went (wall-clock time on the calling thread, and
/// the narrow phase's work summed over the pairs it evaluated): for tuning and for judging how
/// well a thread pool is used. [`World::last_step_timing`].
///
/// The narrow phase's parallel efficiency is `pair_time / (threads · narrow)`; what it loses
/// is idle time (a thread waiting for the last pairs of another) and scheduling overhead.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StepTiming {
    /// The broad phase and the merge of last step's pair states (sequential).
    pub broad: Duration,
    /// The narrow phase: wall time from dispatching the pairs to the last answer.
    pub narrow: Duration,
    /// Collecting the answers and the statistics (sequential).
    pub collect: Duration,
    /// Sum over the pairs evaluated of the time each took (on whichever thread ran it).
    pub pair_time: Duration,
    /// The longest single pair evaluation.
    pub max_pair: Duration,
    /// Threads of the pool the narrow phase ran on (1 without the `parallel` feature).
    pub threads: usize,
}

#[derive(Debug, Default)]
struct StepStats {
    candidates: usize,
    reused: usize,
    counters: Counters,
    clearance_work: ClearanceWork,
}

/// Bodies sharing trees through `Arc<ObbTree>`, addressed by generational [`BodyId`] handles;
/// poses updated one by one or in batches; [`World::step`] answers which bodies interfere.
///
/// - **Handles** carry a slot index, a generation and the world's serial: a handle of a removed
///   body, or of another world, is refused with a typed error, never silently aliased.
/// - **Broad phase**: candidate pairs kept from step to step over grown boxes. Each body's box
///   is kept grown by [`WorldOptions::box_slack_percent`] of its largest side; a step tests the
///   candidates with the bodies' own boxes (so the answer is exact), and only the bodies that
///   left their grown box since the last step (or were added or removed) are re-inserted, in a
///   dynamic box tree, and queried for new candidates. When more than an eighth of the bodies
///   leave at once (incoherent motion, a new margin), every candidate is found afresh by a sweep
///   along the axis the centres spread most, or by a uniform grid where many bodies fill a
///   volume; from the second such step in a row, with the bodies' own boxes (the step's answer
///   only: fewer pairs to find, none to filter), and grown boxes again once the motion calms
///   down. [`World::teleport`] drops only the teleported body's own pair caches (lazily, by an
///   epoch, without scanning the pairs).
/// - **Narrow phase**: static-static and excluded pairs are never queried; pairs whose two poses
///   did not change since their last answer are answered from it. The other pairs run in
///   parallel (default `parallel` feature) on the pool given to [`World::set_thread_pool`], or
///   on the caller's current rayon pool; the result does not depend on the thread count.
/// - **Results** are kept in the world and borrowed by the [`StepReport`]: no triangle pair list
///   is cloned.
///
/// ```
/// use frcd_obb::{BuildOptions, ObbTree, World, WorldOptions};
/// use frcd_geom::{shapes, DVec3, Pose};
/// use std::sync::Arc;
/// let ball = Arc::new(ObbTree::build(&shapes::icosphere(1.0, 2), &BuildOptions::default()));
/// let mut world = World::new(WorldOptions::default());
/// let a = world.add_body(ball.clone(), Pose::IDENTITY, true)?;
/// let b = world.add_body(ball, Pose::from_translation(DVec3::new(5.0, 0.0, 0.0)), false)?;
/// assert!(world.step().contacts.is_empty());
/// world.set_pose(b, Pose::from_translation(DVec3::new(1.5, 0.0, 0.0)))?;
/// let report = world.step();
/// assert_eq!((report.contacts[0].a, report.contacts[0].b), (a, b));
/// assert!(!report.contacts[0].pairs.is_empty());
/// world.remove_body(b)?;
/// assert!(world.set_pose(b, Pose::IDENTITY).is_err()); // a stale handle is refused
/// # Ok::<(), frcd_obb::WorldError>(())
/// ```
#[derive(Debug)]
pub struct World {
    options: WorldOptions,
    serial: u32,
    slots: Vec<Slot>,
    /// By slot (valid where the slot holds a body): its pose and version.
    placements: Vec<Placement>,
    /// By slot (valid where the slot holds a body): its tree's box in the body's frame.
    local_boxes: Vec<Aabb>,
    free: Vec<u32>,
    live: usize,
    broad: BroadPhase,
    /// Candidate pairs of the last step with their states, sorted by `(a.index, b.index)`.
    pairs: Vec<PairEntry>,
    /// An empty list whose allocation the next step reuses for its pairs.
    spare: Vec<PairEntry>,
    /// The broad phase's slot pairs and the step's candidate pairs, kept between calls.
    raw_pairs: Vec<(u32, u32)>,
    candidate_pairs: Vec<(BodyId, BodyId)>,
    /// Indices into `pairs` of the interfering pairs of the last step.
    contacts: Vec<u32>,
    clearances: Vec<Clearance>,
    /// The world's clearance threshold.
    clearance: Option<f64>,
    /// Multiset of the per-pair thresholds (f64 bits of values >= 0, which order like the
    /// values), for the broad phase's margin.
    thresholds: BTreeMap<u64, usize>,
    stats: StepStats,
    timing: StepTiming,
    #[cfg(feature = "parallel")]
    pool: Option<Arc<rayon::ThreadPool>>,
}

/// A conservative world box: the local box (a tree's box in its body's frame) mapped by the
/// pose, grown by a relative margin that covers the rounding of the pair queries' relative
/// frames.
// Always inlined: returned through memory, the box's 24-byte corners were read back as
// 16-byte pieces that waited for the writes to reach the cache (perf: half of `move_body`).
#[inline(always)]
pub(crate) fn world_box(local: &Aabb, pose: &Pose) -> Aabb {
    let b = local.transformed(pose);
    let mag = b.min.abs().max(b.max.abs()).max_element();
    b.inflated(mag * 1e-12 + f64::MIN_POSITIVE)
}

impl World {
    /// An empty world.
    pub fn new(options: WorldOptions) -> Self {
        Self {
            options,
            serial: handle::next_world_serial(),
            slots: Vec::new(),
            placements: Vec::new(),
            local_boxes: Vec::new(),
            free: Vec::new(),
            live: 0,
            broad: BroadPhase::new(
                f64::from(options.box_slack_percent.min(MAX_BOX_SLACK_PERCENT)) / 100.0,
            ),
            pairs: Vec::new(),
            spare: Vec::new(),
            raw_pairs: Vec::new(),
            candidate_pairs: Vec::new(),
            contacts: Vec::new(),
            clearances: Vec::new(),
            clearance: None,
            thresholds: BTreeMap::new(),
            stats: StepStats::default(),
            timing: StepTiming::default(),
            #[cfg(feature = "parallel")]
            pool: None,
        }
    }

    /// The options.
    pub fn options(&self) -> &WorldOptions {
        &self.options
    }

    /// Runs the narrow phase on this pool from now on (`None`: the caller's current rayon pool,
    /// which is the global pool unless the caller is inside `ThreadPool::install`). A pool of
    /// one thread makes the step sequential. The answers do not depend on the pool.
    #[cfg(feature = "parallel")]
    pub fn set_thread_pool(&mut self, pool: Option<Arc<rayon::ThreadPool>>) {
        self.pool = pool;
    }

    /// Number of bodies.
    pub fn len(&self) -> usize {
        self.live
    }

    /// True when there are no bodies.
    pub fn is_empty(&self) -> bool {
        self.live == 0
    }

    /// The handles of every body, by slot index.
    pub fn bodies(&self) -> impl Iterator<Item = BodyId> + '_ {
        self.slots.iter().enumerate().filter_map(|(i, s)| {
            s.body
                .as_ref()
                .map(|_| BodyId::new(i as u32, s.generation, self.serial))
        })
    }

    /// True when `id` names a body of this world.
    pub fn contains(&self, id: BodyId) -> bool {
        self.get(id).is_ok()
    }

    pub(crate) fn get(&self, id: BodyId) -> Result<&Body, WorldError> {
        if id.world() != self.serial {
            return Err(WorldError::ForeignBody { id });
        }
        match self.slots.get(id.index() as usize) {
            Some(Slot {
                generation,
                body: Some(b),
                ..
            }) if *generation == id.generation() => Ok(b),
            _ => Err(WorldError::UnknownBody { id }),
        }
    }

    fn get_mut(&mut self, id: BodyId) -> Result<&mut Body, WorldError> {
        self.get(id)?;
        Ok(self.slots[id.index() as usize]
            .body
            .as_deref_mut()
            .expect("checked above"))
    }

    fn handle(&self, i: u32) -> BodyId {
        BodyId::new(i, self.slots[i as usize].generation, self.serial)
    }

    /// Adds a body; static bodies are never tested against each other. An invalid pose
    /// (non-finite, or a rotation that is not a unit quaternion) is refused. Slots of removed
    /// bodies are reused with a new generation.
    pub fn add_body(
        &mut self,
        tree: Arc<ObbTree>,
        pose: Pose,
        is_static: bool,
    ) -> Result<BodyId, WorldError> {
        let (index, generation) = match self.free.last() {
            Some(&i) => (i, self.slots[i as usize].generation),
            None => {
                if self.slots.len() >= u32::MAX as usize {
                    return Err(WorldError::TooManyBodies {
                        max: u32::MAX as usize,
                    });
                }
                (self.slots.len() as u32, 0)
            }
        };
        let id = BodyId::new(index, generation, self.serial);
        if !pose.is_valid() {
            return Err(WorldError::InvalidPose { id, pose });
        }
        let local = tree.aabb();
        let aabb = world_box(&local, &pose);
        let body = Body {
            tree,
            is_static,
            epoch: 0,
            excluded: Vec::new(),
            thresholds: Vec::new(),
        };
        let placement = Placement { pose, version: 0 };
        let slot = Slot {
            generation,
            is_static,
            may_exclude: false,
            body: Some(Box::new(body)),
        };
        if self.free.pop().is_some() {
            self.slots[index as usize] = slot;
            self.placements[index as usize] = placement;
            self.local_boxes[index as usize] = local;
        } else {
            self.slots.push(slot);
            self.placements.push(placement);
            self.local_boxes.push(local);
        }
        self.live += 1;
        self.broad.set(index, aabb);
        Ok(id)
    }

    /// Removes a body and returns its tree. Its handle (and every copy of it) is refused from
    /// now on; its pairs and exclusions are forgotten.
    pub fn remove_body(&mut self, id: BodyId) -> Result<Arc<ObbTree>, WorldError> {
        self.get(id)?;
        let slot = &mut self.slots[id.index() as usize];
        let body = slot.body.take().expect("checked above");
        // A slot whose generation would wrap is retired rather than reused.
        if slot.generation < u32::MAX {
            slot.generation += 1;
            self.free.push(id.index());
        }
        self.live -= 1;
        for other in &body.excluded {
            if let Ok(o) = self.get_mut(*other) {
                o.excluded.retain(|x| *x != id);
            }
        }
        for &(other, t) in &body.thresholds {
            if let Ok(o) = self.get_mut(other) {
                o.thresholds.retain(|x| x.0 != id);
            }
            self.forget_threshold(t);
        }
        self.broad.remove(id.index());
        Ok(body.tree)
    }

    /// Moves a body (coherent motion: the broad phase re-sorts incrementally).
    pub fn set_pose(&mut self, id: BodyId, pose: Pose) -> Result<(), WorldError> {
        self.get(id)?;
        if !pose.is_valid() {
            return Err(WorldError::InvalidPose { id, pose });
        }
        self.move_body(id, pose);
        Ok(())
    }

    /// Moves a checked body to `pose` (nothing changes if it is there already).
    #[inline(always)]
    fn move_body(&mut self, id: BodyId, pose: Pose) {
        let i = id.index() as usize;
        if self.placements[i].pose != pose {
            // The box passed on as a value, not read back from memory: written piecewise, a
            // 16-byte read spanning two of those writes waits for them to reach the cache
            // (a quarter of this function's time, perf).
            let aabb = world_box(&self.local_boxes[i], &pose);
            self.place_body(id, pose, aabb);
        }
    }

    /// [`World::move_body`] with the body's world box for `pose` already computed.
    #[inline(always)]
    fn place_body(&mut self, id: BodyId, pose: Pose, aabb: Aabb) {
        let p = &mut self.placements[id.index() as usize];
        if p.pose != pose {
            p.pose = pose;
            p.version += 1;
            self.broad.set(id.index(), aabb);
        }
    }

    /// Moves many bodies at once. Every handle and pose is checked first: on an error nothing
    /// has moved.
    pub fn set_poses(&mut self, updates: &[(BodyId, Pose)]) -> Result<(), WorldError> {
        for &(id, pose) in updates {
            self.get(id)?;
            if !pose.is_valid() {
                return Err(WorldError::InvalidPose { id, pose });
            }
        }
        #[cfg(target_arch = "x86_64")]
        if crate::isa::has_avx2() {
            // SAFETY: the CPU has AVX2 (checked just above).
            #[allow(unsafe_code)]
            unsafe {
                self.move_bodies_avx2(updates)
            };
            return Ok(());
        }
        self.move_bodies::<[f64; 4]>(updates);
        Ok(())
    }

    /// Moves the bodies of `updates` (all checked), in order: four world boxes are computed at
    /// once ([`boxes4::world_boxes4`], the same bits as one at a time), then the four moves
    /// are made one after the other (so a body named twice ends at its last pose, as with
    /// one update at a time).
    #[inline(always)]
    fn move_bodies<V: boxes4::Lanes>(&mut self, updates: &[(BodyId, Pose)]) {
        let mut chunks = updates.chunks_exact(4);
        for chunk in &mut chunks {
            let mut local = [Aabb::EMPTY; 4];
            let mut poses = [Pose::IDENTITY; 4];
            let mut boxed = true;
            for (k, &(id, pose)) in chunk.iter().enumerate() {
                local[k] = self.local_boxes[id.index() as usize];
                poses[k] = pose;
                boxed &= !local[k].is_empty();
            }
            if boxed {
                let boxes = boxes4::world_boxes4::<V>(&local, &poses);
                for (&(id, pose), aabb) in chunk.iter().zip(boxes) {
                    self.place_body(id, pose, aabb);
                }
            } else {
                // An empty local box maps to itself: one body at a time.
                for &(id, pose) in chunk {
                    self.move_body(id, pose);
                }
            }
        }
        for &(id, pose) in chunks.remainder() {
            self.move_body(id, pose);
        }
    }

    /// [`World::move_bodies`] built with AVX2 (the same IEEE operations: no FMA, so the same
    /// boxes bit for bit; the four lanes of [`boxes4::world_boxes4`] take one register).
    ///
    /// # Safety
    ///
    /// The CPU must have AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[allow(unsafe_code)]
    unsafe fn move_bodies_avx2(&mut self, updates: &[(BodyId, Pose)]) {
        self.move_bodies::<boxes4::avx::F64x4>(updates);
    }

    /// Moves a body far (incoherent motion): like [`World::set_pose`], and the coherence caches
    /// of its pairs are dropped when next used (lazily, by an epoch, without scanning the pairs).
    pub fn teleport(&mut self, id: BodyId, pose: Pose) -> Result<(), WorldError> {
        self.set_pose(id, pose)?;
        let body = self.get_mut(id)?;
        body.epoch = body.epoch.wrapping_add(1);
        Ok(())
    }

    /// What the broad phase did since the world was made: rebuilds, re-inserted bodies, tree
    /// builds (work counts for tests and benchmarks; they never change an answer).
    pub fn broad_stats(&self) -> BroadStats {
        self.broad.stats
    }

    /// The pose of a body.
    pub fn pose(&self, id: BodyId) -> Option<Pose> {
        self.get(id).ok()?;
        Some(self.placements[id.index() as usize].pose)
    }

    /// The tree of a body.
    pub fn tree(&self, id: BodyId) -> Option<&Arc<ObbTree>> {
        self.get(id).ok().map(|b| &b.tree)
    }

    /// Never test this pair (parts joined by design).
    pub fn exclude_pair(&mut self, a: BodyId, b: BodyId) -> Result<(), WorldError> {
        self.get(a)?;
        self.get(b)?;
        if a == b {
            return Err(WorldError::SelfPair { id: a });
        }
        if self.is_excluded(a, b) {
            return Ok(());
        }
        self.get_mut(a)?.excluded.push(b);
        self.get_mut(b)?.excluded.push(a);
        self.slots[a.index() as usize].may_exclude = true;
        self.slots[b.index() as usize].may_exclude = true;
        Ok(())
    }

    /// Clearance threshold of every tested pair without its own (`None`: no clearance, the
    /// default). Pairs within it are reported in [`StepReport::clearances`] each step.
    pub fn set_clearance(&mut self, threshold: Option<f64>) -> Result<(), WorldError> {
        if let Some(value) = threshold.filter(|t| t.is_nan() || *t < 0.0) {
            return Err(WorldError::InvalidClearance { value });
        }
        self.clearance = threshold.map(|t| t + 0.0);
        Ok(())
    }

    /// The world's clearance threshold.
    pub fn clearance(&self) -> Option<f64> {
        self.clearance
    }

    /// Clearance threshold of one pair, overriding the world's (`None`: back to the world's).
    pub fn set_pair_clearance(
        &mut self,
        a: BodyId,
        b: BodyId,
        threshold: Option<f64>,
    ) -> Result<(), WorldError> {
        self.get(a)?;
        self.get(b)?;
        if a == b {
            return Err(WorldError::SelfPair { id: a });
        }
        if let Some(value) = threshold.filter(|t| t.is_nan() || *t < 0.0) {
            return Err(WorldError::InvalidClearance { value });
        }
        if let Some(&(_, old)) = self.get(a)?.thresholds.iter().find(|x| x.0 == b) {
            self.forget_threshold(old);
            self.get_mut(a)?.thresholds.retain(|x| x.0 != b);
            self.get_mut(b)?.thresholds.retain(|x| x.0 != a);
        }
        if let Some(t) = threshold.map(|t| t + 0.0) {
            *self.thresholds.entry(t.to_bits()).or_insert(0) += 1;
            self.get_mut(a)?.thresholds.push((b, t));
            self.get_mut(b)?.thresholds.push((a, t));
        }
        Ok(())
    }

    fn forget_threshold(&mut self, t: f64) {
        let k = t.to_bits();
        if let Some(c) = self.thresholds.get_mut(&k) {
            *c -= 1;
            if *c == 0 {
                self.thresholds.remove(&k);
            }
        }
    }

    /// The clearance threshold of a pair: its own, else the world's.
    pub fn pair_clearance_threshold(&self, a: BodyId, b: BodyId) -> Option<f64> {
        let (ba, bb) = (self.get(a).ok()?, self.get(b).ok()?);
        let (list, other) = if ba.thresholds.len() <= bb.thresholds.len() {
            (&ba.thresholds, b)
        } else {
            (&bb.thresholds, a)
        };
        list.iter()
            .find(|x| x.0 == other)
            .map(|x| x.1)
            .or(self.clearance)
    }

    /// The largest clearance threshold of any pair (the broad phase's margin).
    pub fn max_clearance(&self) -> Option<f64> {
        let own = self
            .thresholds
            .keys()
            .next_back()
            .map(|&k| f64::from_bits(k));
        match (own, self.clearance) {
            (Some(x), Some(y)) => Some(x.max(y)),
            (x, y) => x.or(y),
        }
    }

    fn is_excluded(&self, a: BodyId, b: BodyId) -> bool {
        let (Ok(ba), Ok(bb)) = (self.get(a), self.get(b)) else {
            return false;
        };
        // Search the shorter list.
        if ba.excluded.len() <= bb.excluded.len() {
            ba.excluded.contains(&b)
        } else {
            bb.excluded.contains(&a)
        }
    }

    /// True when the pair is ever tested: two live bodies, not both static, not excluded.
    pub fn is_pair_tested(&self, a: BodyId, b: BodyId) -> bool {
        match (self.get(a), self.get(b)) {
            (Ok(ba), Ok(bb)) => {
                a != b && !(ba.is_static && bb.is_static) && !self.is_excluded(a, b)
            }
            _ => false,
        }
    }

    /// Runs the broad phase alone (for schedulers that run their own narrow phase, like
    /// `frcd-hybrid`): the tested body pairs whose world boxes, each grown by `margin / 2`,
    /// overlap — every pair closer than `margin` among them. Sorted by slot index, `a < b`.
    pub fn overlapping_pairs(&mut self, margin: f64) -> Vec<(BodyId, BodyId)> {
        let mut out = Vec::new();
        self.overlapping_pairs_into(margin, &mut out);
        out
    }

    /// [`World::overlapping_pairs`] written into `out` (cleared first), so that a caller that
    /// runs it every frame keeps one allocation.
    ///
    /// ```
    /// use frcd_geom::{DVec3, Pose, shapes};
    /// use frcd_obb::{BuildOptions, ObbTree, World, WorldOptions};
    /// use std::sync::Arc;
    ///
    /// let cube = Arc::new(ObbTree::build(&shapes::cuboid(DVec3::ONE), &BuildOptions::default()));
    /// let mut w = World::new(WorldOptions::default());
    /// let a = w.add_body(cube.clone(), Pose::IDENTITY, false)?;
    /// let b = w.add_body(cube, Pose::from_translation(DVec3::X), false)?;
    /// let mut pairs = Vec::new();
    /// for frame in 0..3 {
    ///     w.set_pose(b, Pose::from_translation(DVec3::X * (1.0 + frame as f64)))?;
    ///     w.overlapping_pairs_into(0.0, &mut pairs);
    ///     assert_eq!(pairs, if frame < 2 { vec![(a, b)] } else { vec![] });
    /// }
    /// # Ok::<(), frcd_obb::WorldError>(())
    /// ```
    pub fn overlapping_pairs_into(&mut self, margin: f64, out: &mut Vec<(BodyId, BodyId)>) {
        out.clear();
        // The broad phase's slot pairs, in a list kept from call to call.
        let mut raw = std::mem::take(&mut self.raw_pairs);
        raw.clear();
        self.broad.pairs(margin.max(0.0), &mut raw);
        out.reserve(raw.len());
        for (k, &(i, j)) in raw.iter().enumerate() {
            // The second slot of each pair is a random read: ask for it a few pairs ahead.
            if let Some(&(_, ahead)) = raw.get(k + broad::PREFETCH_AHEAD) {
                broad::prefetch(&self.slots[ahead as usize]);
            }
            let (a, b) = (self.handle(i), self.handle(j));
            if self.pair_filter(a, b) {
                out.push((a, b));
            }
        }
        self.raw_pairs = raw;
    }

    fn pair_filter(&self, a: BodyId, b: BodyId) -> bool {
        let (sa, sb) = (
            &self.slots[a.index() as usize],
            &self.slots[b.index() as usize],
        );
        !(sa.is_static && sb.is_static)
            && (!sa.may_exclude && !sb.may_exclude || !self.is_excluded(a, b))
    }

    /// Advances one step: broad phase, then the narrow phase on the candidate pairs whose poses
    /// changed since their last answer. The report borrows the world.
    ///
    /// The narrow phase hands the pairs to the pool's threads one at a time, the costliest
    /// first (by the time each took last step; new pairs first of all), so that no thread is
    /// left with a long pair while the others idle at the end of the step. The answers do not
    /// depend on that order or on the thread count.
    pub fn step(&mut self) -> StepReport<'_> {
        let t_start = Instant::now();
        let margin = self.max_clearance().unwrap_or(0.0);
        let mut cands = std::mem::take(&mut self.candidate_pairs);
        self.overlapping_pairs_into(margin, &mut cands);
        // Merge last step's states (sorted like `cands`) into this step's work list (both
        // allocations are kept from step to step).
        let mut old_pairs = std::mem::take(&mut self.pairs);
        let mut old = old_pairs.drain(..).peekable();
        let mut work: Vec<PairEntry> = std::mem::take(&mut self.spare);
        work.clear();
        work.reserve(cands.len());
        for &(a, b) in &cands {
            let (ia, ib) = (a.index(), b.index());
            let (box_a, box_b) = (self.broad.tight_box(ia), self.broad.tight_box(ib));
            let overlap = box_a.intersects(box_b);
            let threshold = if margin > 0.0 || self.clearance.is_some() {
                self.pair_clearance_threshold(a, b)
            } else {
                None
            };
            // Boxes farther apart than the pair's threshold: nothing to ask.
            if !overlap && threshold.is_none_or(|t| box_gap(box_a, box_b) > t) {
                continue;
            }
            let key = (a.index(), b.index());
            let mut state = None;
            while let Some(e) = old.peek() {
                let k = (e.a.index(), e.b.index());
                if k < key {
                    old.next();
                } else {
                    if k == key && e.a == a && e.b == b {
                        state = old.next().map(|e| e.state);
                    }
                    break;
                }
            }
            let state = state.unwrap_or_else(|| Box::new(PairState::new()));
            // Neither pose changed since the last answer (same threshold): reuse it.
            let reused = state.answered
                && state.versions
                    == (
                        self.placements[ia as usize].version,
                        self.placements[ib as usize].version,
                    )
                && state.threshold == threshold;
            work.push(PairEntry {
                a,
                b,
                overlap,
                threshold,
                reused,
                state,
            });
        }
        drop(old);
        self.spare = old_pairs;
        self.candidate_pairs = cands;
        let slots = &self.slots;
        let placements = &self.placements;
        let options = self.options;
        let run = |e: &mut PairEntry| {
            let t = Instant::now();
            let (ia, ib) = (e.a.index() as usize, e.b.index() as usize);
            let ba = slots[ia].body.as_deref().expect("live");
            let bb = slots[ib].body.as_deref().expect("live");
            let (pa, pb) = (&placements[ia], &placements[ib]);
            let st = &mut e.state;
            let versions = (pa.version, pb.version);
            let epochs = (ba.epoch, bb.epoch);
            if !options.coherence || st.epochs != epochs {
                st.cache.clear();
            }
            st.result = e.overlap.then(|| {
                collide_cached(
                    &ba.tree,
                    &pa.pose,
                    &bb.tree,
                    &pb.pose,
                    &options.request,
                    &mut st.cache,
                )
            });
            (st.clearance, st.clearance_work) = match e.threshold {
                Some(t) => {
                    let (witness, interfering) = st
                        .result
                        .as_ref()
                        .map_or((None, false), |c| (c.witness, c.collide));
                    pair_clearance_cached(
                        &ba.tree,
                        &pa.pose,
                        &bb.tree,
                        &pb.pose,
                        t,
                        witness,
                        interfering,
                        &mut st.clearance_cache,
                    )
                }
                None => (None, ClearanceWork::default()),
            };
            st.versions = versions;
            st.epochs = epochs;
            st.threshold = e.threshold;
            st.answered = true;
            st.cost_ns = (t.elapsed().as_nanos() as u64).min(u64::MAX - 1);
        };
        // The pairs to evaluate, costliest first.
        let mut jobs: Vec<(u64, &mut PairEntry)> = work
            .iter_mut()
            .filter(|e| !e.reused)
            .map(|e| (e.state.cost_ns, e))
            .collect();
        jobs.sort_unstable_by_key(|x| std::cmp::Reverse(x.0));
        let t_narrow = Instant::now();
        #[cfg(feature = "parallel")]
        let threads = {
            use rayon::iter::{ParallelBridge, ParallelIterator};
            // `par_bridge` gives each thread the next pair of the list as it becomes free
            // (greedy list scheduling in cost order); one lock per pair, microseconds of
            // work each.
            let each = |jobs: Vec<(u64, &mut PairEntry)>| {
                if rayon::current_num_threads() > 1 {
                    jobs.into_iter().par_bridge().for_each(|(_, e)| run(e));
                } else {
                    jobs.into_iter().for_each(|(_, e)| run(e));
                }
                rayon::current_num_threads()
            };
            match &self.pool {
                Some(pool) => pool.install(|| each(jobs)),
                None => each(jobs),
            }
        };
        #[cfg(not(feature = "parallel"))]
        let threads = {
            jobs.into_iter().for_each(|(_, e)| run(e));
            1
        };
        let t_collect = Instant::now();
        let mut stats = StepStats {
            candidates: work.len(),
            ..StepStats::default()
        };
        let (mut pair_time, mut max_pair) = (0u64, 0u64);
        self.contacts.clear();
        self.clearances.clear();
        for (i, e) in work.iter().enumerate() {
            if e.reused {
                stats.reused += 1;
            } else {
                stats.clearance_work += e.state.clearance_work;
                pair_time += e.state.cost_ns;
                max_pair = max_pair.max(e.state.cost_ns);
            }
            if let Some(c) = &e.state.result {
                if !e.reused {
                    stats.counters += c.counters;
                }
                if c.collide {
                    self.contacts.push(i as u32);
                }
            }
            if let Some(c) = e.state.clearance {
                self.clearances.push(c.with_ids(e.a, e.b));
            }
        }
        self.pairs = work;
        self.stats = stats;
        let t_end = Instant::now();
        self.timing = StepTiming {
            broad: t_narrow - t_start,
            narrow: t_collect - t_narrow,
            collect: t_end - t_collect,
            pair_time: Duration::from_nanos(pair_time),
            max_pair: Duration::from_nanos(max_pair),
            threads,
        };
        self.last_step()
    }

    /// Where the time of the last [`World::step`] went ([`StepTiming`]; all zero before the
    /// first step).
    ///
    /// ```
    /// use frcd_obb::{BuildOptions, ObbTree, World, WorldOptions};
    /// use frcd_geom::{shapes, DVec3, Pose};
    /// use std::sync::Arc;
    /// let ball = Arc::new(ObbTree::build(&shapes::icosphere(1.0, 2), &BuildOptions::default()));
    /// let mut world = World::new(WorldOptions::default());
    /// world.add_body(ball.clone(), Pose::IDENTITY, false)?;
    /// world.add_body(ball, Pose::from_translation(DVec3::new(1.5, 0.0, 0.0)), false)?;
    /// world.step();
    /// let t = world.last_step_timing();
    /// assert!(t.threads >= 1 && t.max_pair <= t.pair_time);
    /// # Ok::<(), frcd_obb::WorldError>(())
    /// ```
    pub fn last_step_timing(&self) -> StepTiming {
        self.timing
    }

    /// The report of the last [`World::step`] again (empty before the first).
    pub fn last_step(&self) -> StepReport<'_> {
        let contacts = self
            .contacts
            .iter()
            .map(|&i| {
                let e = &self.pairs[i as usize];
                let c = e
                    .state
                    .result
                    .as_ref()
                    .expect("interfering pairs ran the query");
                BodyContact {
                    a: e.a,
                    b: e.b,
                    pairs: &c.pairs,
                    witness: c.witness,
                    contained: c.contained,
                }
            })
            .collect();
        StepReport {
            contacts,
            clearances: &self.clearances,
            candidates: self.stats.candidates,
            reused: self.stats.reused,
            counters: self.stats.counters,
            clearance_work: self.stats.clearance_work,
        }
    }

    /// World box of a body (conservative).
    pub fn body_aabb(&self, id: BodyId) -> Option<Aabb> {
        self.get(id).ok()?;
        Some(*self.broad.tight_box(id.index()))
    }

    /// Centre of a body's world box (convenience for scene generators).
    pub fn body_center(&self, id: BodyId) -> Option<DVec3> {
        self.body_aabb(id).map(|b| b.center())
    }
}

/// Euclidean distance between two boxes (0 when they overlap): a lower bound of the distance of
/// anything inside them.
fn box_gap(a: &Aabb, b: &Aabb) -> f64 {
    let d = (a.min - b.max).max(b.min - a.max).max(DVec3::ZERO);
    d.length()
}
