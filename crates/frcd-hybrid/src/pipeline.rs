//! Pipelined checking: the GPU traverses frame k+1 while the CPU finishes frame k.
//!
//! [`Checker::check_pipelined`] takes frame k+1's poses and returns frame k's answer (one frame
//! of latency). Per call: frame k+1's rough colliding set is computed (the broad phase, on the
//! backend [`Checker::check`] would use; a GPU box pass is submitted and read) and its GPU body
//! pairs are **submitted** (one batch, one submission); then frame k's batch, submitted one
//! call earlier, is read back and its touching pairs re-decided exactly on the CPU, and frame k
//! runs through [`Checker::check`] with its rough colliding set and GPU answers already in hand
//! (CPU pairs, solid mode, segments, clearance) while the GPU works on frame k+1
//! ([`Pipeline::set_decide_first`] re-decides frame k before frame k+1's batch is submitted
//! instead, while the GPU runs frame k+1's box pass). The broad phase runs once per frame.
//! The answers equal [`Checker::check`]'s frame for frame: the same stages run on the same
//! poses; the broad phase and the GPU pairs are only computed earlier.

use crate::{Checker, FrameResult, FrameState, HybridError};
use frcd_geom::Pose;
#[cfg(feature = "gpgpu")]
use std::collections::{HashMap, HashSet};

/// Work done for a frame before it runs: its rough colliding set and its GPU pair answers,
/// used by [`Checker::check`] (`Checker::rcs_ahead`, `Checker::gpu_pair_queries`) when its
/// poses are these.
#[cfg(feature = "gpgpu")]
#[derive(Debug)]
pub(crate) struct GpuAnswers {
    pub(crate) poses: Vec<Pose>,
    pub(crate) pairs: HashMap<(u32, u32), Vec<(u32, u32)>>,
    /// The frame's rough colliding set (taken by the broad phase stage).
    pub(crate) rcs: Option<RcsAhead>,
}

/// A frame's rough colliding set computed ahead of the frame.
#[cfg(feature = "gpgpu")]
pub(crate) struct RcsAhead {
    candidates: Vec<crate::rcs::Candidate>,
    backend: crate::StageBackend,
    time_us: f64,
    /// Notes the broad phase left (a GPU box pass that fell back to the CPU).
    notes: Vec<String>,
}

#[cfg(feature = "gpgpu")]
impl std::fmt::Debug for RcsAhead {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RcsAhead")
            .field("candidates", &self.candidates.len())
            .field("backend", &self.backend)
            .finish()
    }
}

/// A submitted frame's poses and overlapping body pairs.
#[cfg(feature = "gpgpu")]
type PrevFrame = (Vec<Pose>, HashSet<(u32, u32)>);

/// A frame ahead of its turn, begun ([`Checker::begin_ahead`]): its poses, its rough colliding
/// set begun (a GPU box pass possibly in flight), the notes so far and the time spent.
#[cfg(feature = "gpgpu")]
struct AheadStart {
    poses: Vec<Pose>,
    rcs: crate::rcs::RcsStart,
    notes: FrameResult,
    time: std::time::Duration,
}

/// A frame computed ahead: its rough colliding set and its GPU batch, submitted and not yet
/// read (none when no pair goes to the GPU or the submission failed).
#[cfg(feature = "gpgpu")]
#[derive(Debug)]
struct InFlight {
    poses: Vec<Pose>,
    rcs: RcsAhead,
    batch: Option<(Vec<(u32, u32)>, frcd_gpgpu::SubmittedBatch)>,
}

/// Caller-owned state of pipelined checking ([`Checker::check_pipelined`]): the frame state
/// (its broad phase runs one frame ahead of the answers), the frame held back (its poses) and
/// its GPU batch in flight. One per checker; a pipeline used with one checker is refused by
/// another ([`HybridError::ForeignState`]) until [`Pipeline::reset`].
///
/// ```no_run
/// use frcd_hybrid::{BodySpec, Checker, Options, Pipeline};
/// # fn poses(_: usize) -> Vec<frcd_geom::Pose> { vec![] }
/// # let bodies: Vec<BodySpec> = vec![];
/// let checker = Checker::new(bodies, &[], Options::default())?;
/// let mut pipe = Pipeline::new();
/// for k in 0..100 {
///     // Frame k goes in; frame k-1's answer comes out (none for the first frame).
///     if let Some(frame) = checker.check_pipelined(&poses(k), &mut pipe)? {
///         println!("{} contacts", frame.contacts.len());
///     }
/// }
/// let last = checker.flush_pipelined(&mut pipe)?; // frame 99
/// # Ok::<(), frcd_hybrid::HybridError>(())
/// ```
#[derive(Debug, Default)]
pub struct Pipeline {
    state: FrameState,
    /// Owner of the pipeline (a checker's serial; 0: none yet).
    owner: u64,
    /// Re-decide frame k before submitting frame k+1's batch ([`Pipeline::set_decide_first`]).
    decide_first: bool,
    /// The frame held back: its poses (checked at the next call).
    held: Option<Vec<Pose>>,
    #[cfg(feature = "gpgpu")]
    in_flight: Option<InFlight>,
    /// Scratch buffers of the batch not in flight.
    #[cfg(feature = "gpgpu")]
    spare: Option<frcd_gpgpu::QueryScratch>,
    /// The previously submitted frame's poses and candidate pairs (whose answers the frame
    /// state will hold, so a pair with unchanged poses is reused, not recomputed).
    #[cfg(feature = "gpgpu")]
    prev: Option<PrevFrame>,
}

impl Pipeline {
    /// An empty pipeline.
    pub fn new() -> Self {
        Self::default()
    }

    /// True while a frame is held back (its answer comes with the next call or
    /// [`Checker::flush_pipelined`]).
    pub fn is_holding(&self) -> bool {
        self.held.is_some()
    }

    /// The order of a call's work: `true` re-decides frame k's GPU pairs before frame k+1's
    /// batch is submitted (while the GPU runs frame k+1's box pass, when that pass runs on the
    /// GPU: [`crate::Options::gpgpu_box_pass_min_bodies`]; its latency is then spent on the
    /// re-decision); `false` (the default) submits that batch first, so that the re-decision
    /// overlaps its traversal. The answers are the same either way. On the 2-core
    /// software-driver host (lavapipe, 2026-12-02, the box pass then on the GPU) `true` took
    /// 1.01-1.09 of the default's time on the 64-part checker frame (three runs of 21 in one
    /// process, `cargo xtask bench gpgpu --checker-pipeline-orders`), so the default stays.
    pub fn set_decide_first(&mut self, decide_first: bool) {
        self.decide_first = decide_first;
    }

    /// The order set by [`Pipeline::set_decide_first`].
    pub fn decide_first(&self) -> bool {
        self.decide_first
    }

    /// The frame state (coherence caches, broad phase) of the frames answered so far.
    pub fn state(&self) -> &FrameState {
        &self.state
    }

    /// Drops the held frame and its GPU work, forgets every cached answer and the checker the
    /// pipeline belonged to (the order of [`Pipeline::set_decide_first`] is kept).
    pub fn reset(&mut self) {
        *self = Self {
            decide_first: self.decide_first,
            ..Self::default()
        };
    }
}

impl Checker {
    /// Pipelined [`Checker::check`]: takes frame k+1's poses, returns frame k's answer (`None`
    /// on the first call). Frame k+1's GPU pair batch is submitted before frame k is finished,
    /// so the GPU traverses frame k+1 while the CPU re-decides frame k's GPU pairs exactly and
    /// runs its CPU pairs. Answers equal [`Checker::check`]'s, frame for frame; call
    /// [`Checker::flush_pipelined`] for the last frame. Without a GPU in use it is
    /// [`Checker::check`] with one frame of latency.
    ///
    /// Bad poses are refused before anything is held (the held frame stays held). An error
    /// while finishing frame k is returned for frame k; frame k+1 stays held.
    pub fn check_pipelined(
        &self,
        poses: &[Pose],
        pipe: &mut Pipeline,
    ) -> Result<Option<FrameResult>, HybridError> {
        self.check_poses(poses)?;
        if pipe.owner != 0 && pipe.owner != self.serial {
            return Err(HybridError::ForeignState);
        }
        pipe.owner = self.serial;
        #[cfg(feature = "gpgpu")]
        let start = self.begin_ahead(poses, pipe)?;
        let held = pipe.held.replace(poses.to_vec());
        #[cfg(feature = "gpgpu")]
        {
            let current = pipe.in_flight.take();
            // Frame k's batch is read and re-decided after frame k+1's batch is submitted (the
            // re-decision overlaps its traversal), or while the GPU runs frame k+1's box pass
            // (`Pipeline::set_decide_first`).
            // A failure to finish frame k+1 ahead leaves frame k held (it is not answered
            // yet), as a refusal before anything is held would; its batch is read next call.
            if pipe.decide_first {
                self.read_in_flight(current, pipe)?;
                match self.finish_ahead(start, pipe) {
                    Ok(next) => pipe.in_flight = next,
                    Err(e) => {
                        pipe.held = held;
                        return Err(e);
                    }
                }
            } else {
                match self.finish_ahead(start, pipe) {
                    Ok(next) => pipe.in_flight = next,
                    Err(e) => {
                        pipe.held = held;
                        pipe.in_flight = current;
                        return Err(e);
                    }
                }
                self.read_in_flight(current, pipe)?;
            }
        }
        let Some(held) = held else {
            return Ok(None);
        };
        self.check(&held, &mut pipe.state).map(Some)
    }

    /// The answer of the frame [`Checker::check_pipelined`] holds back (`None` when none is).
    pub fn flush_pipelined(&self, pipe: &mut Pipeline) -> Result<Option<FrameResult>, HybridError> {
        if pipe.owner != 0 && pipe.owner != self.serial {
            return Err(HybridError::ForeignState);
        }
        let Some(held) = pipe.held.take() else {
            return Ok(None);
        };
        #[cfg(feature = "gpgpu")]
        {
            let current = pipe.in_flight.take();
            self.read_in_flight(current, pipe)?;
        }
        self.check(&held, &mut pipe.state).map(Some)
    }

    /// The checks of [`Checker::check`] on poses, made before a frame is held.
    fn check_poses(&self, poses: &[Pose]) -> Result<(), HybridError> {
        if poses.len() != self.bodies.len() {
            return Err(HybridError::PoseCount {
                expected: self.bodies.len(),
                got: poses.len(),
            });
        }
        if let Some(i) = poses.iter().position(|p| !p.is_valid()) {
            return Err(HybridError::InvalidPose {
                body: self.bodies[i].name.clone(),
                pose: poses[i],
            });
        }
        Ok(())
    }

    /// Frame `poses` ahead of its turn, first half: the rough colliding set begun on the
    /// pipeline's frame state (whose broad phase thereby moves one frame ahead of the answers;
    /// a GPU box pass is submitted, not waited for). `None` when no GPU pair stage runs (then
    /// [`Checker::check`] runs the frame's broad phase itself).
    #[cfg(feature = "gpgpu")]
    fn begin_ahead(
        &self,
        poses: &[Pose],
        pipe: &mut Pipeline,
    ) -> Result<Option<AheadStart>, HybridError> {
        if self.gpgpu.is_none() || self.options.mode != crate::Accuracy::Exact {
            return Ok(None);
        }
        if pipe.state.world.is_none() {
            self.bind(&mut pipe.state, poses)?;
        }
        let t0 = std::time::Instant::now();
        let mut notes = FrameResult::empty();
        let rcs = self.rcs_begin(poses, &mut pipe.state, &mut notes)?;
        Ok(Some(AheadStart {
            poses: poses.to_vec(),
            rcs,
            notes,
            time: t0.elapsed(),
        }))
    }

    /// Second half: the rough colliding set finished and the frame's GPU pairs (those
    /// [`Checker::check`] will send to the GPU: overlapping, not reused, chosen by the cost
    /// model) submitted as one batch.
    #[cfg(feature = "gpgpu")]
    fn finish_ahead(
        &self,
        start: Option<AheadStart>,
        pipe: &mut Pipeline,
    ) -> Result<Option<InFlight>, HybridError> {
        let (Some(start), Some(g)) = (start, self.gpgpu.as_ref()) else {
            return Ok(None);
        };
        let AheadStart {
            poses,
            rcs,
            mut notes,
            time,
        } = start;
        let t0 = std::time::Instant::now();
        let (candidates, backend) = self.rcs_finish(rcs, &mut pipe.state, &mut notes)?;
        let rcs = RcsAhead {
            candidates,
            backend,
            time_us: (time + t0.elapsed()).as_secs_f64() * 1e6,
            notes: notes.notes,
        };
        let poses = poses.as_slice();
        // Only pairs whose raw boxes overlap run the collision query (the others are in the
        // set for their clearance only).
        let overlapping: Vec<(u32, u32)> = rcs
            .candidates
            .iter()
            .filter(|c| c.overlap)
            .map(|c| c.key)
            .collect();
        // Check reuses a pair's last answer when the pair was a candidate of the previous frame
        // and both poses are unchanged (then its boxes overlapped then too: only overlapping
        // pairs need remembering).
        let reused = |key: (u32, u32)| {
            pipe.prev.as_ref().is_some_and(|(p, keys)| {
                keys.contains(&key)
                    && p[key.0 as usize] == poses[key.0 as usize]
                    && p[key.1 as usize] == poses[key.1 as usize]
            })
        };
        let keys: Vec<(u32, u32)> = overlapping
            .iter()
            .copied()
            .filter(|&k| !reused(k) && self.wants_gpu_narrow(k))
            .collect();
        pipe.prev = Some((poses.to_vec(), overlapping.into_iter().collect()));
        let mut ahead = InFlight {
            poses: poses.to_vec(),
            rcs,
            batch: None,
        };
        if keys.is_empty() {
            return Ok(Some(ahead));
        }
        let items: Vec<frcd_gpgpu::BodyPair<'_>> = keys
            .iter()
            .map(|&(a, b)| {
                let (ia, ib) = (a as usize, b as usize);
                let (ma, mb) = (self.bodies[ia].mesh, self.bodies[ib].mesh);
                (&g.meshes[ma], &poses[ia], &g.meshes[mb], &poses[ib])
            })
            .collect();
        let scratch = pipe.spare.take().unwrap_or_default();
        match g.ctx.submit_batch(&items, scratch) {
            Ok(batch) => ahead.batch = Some((keys, batch)),
            Err(e) => self.gpu_ahead_failed(e)?,
        }
        Ok(Some(ahead))
    }

    /// Reads frame k's batch (waiting on its submission only; the GPU may be busy with frame
    /// k+1) and leaves its answers and rough colliding set for [`Checker::check`].
    #[cfg(feature = "gpgpu")]
    fn read_in_flight(
        &self,
        current: Option<InFlight>,
        pipe: &mut Pipeline,
    ) -> Result<(), HybridError> {
        pipe.state.gpu_answers = None;
        let (Some(f), Some(g)) = (current, self.gpgpu.as_ref()) else {
            return Ok(());
        };
        let mut answers = GpuAnswers {
            poses: f.poses,
            pairs: HashMap::new(),
            rcs: Some(f.rcs),
        };
        if let Some((keys, batch)) = f.batch {
            match g.ctx.resolve_batch(batch) {
                Ok((batch, scratch)) => {
                    pipe.spare = Some(scratch);
                    answers.pairs = keys
                        .into_iter()
                        .zip(batch.results.into_iter().map(|r| r.pairs))
                        .collect();
                }
                Err(e) => self.gpu_ahead_failed(e)?,
            }
        }
        pipe.state.gpu_answers = Some(answers);
        Ok(())
    }

    /// The rough colliding set a pipelined run computed ahead for these poses (its notes
    /// added to `result`), as `(candidates, backend, microseconds)`; `None` otherwise.
    #[cfg(feature = "gpgpu")]
    pub(crate) fn rcs_ahead(
        &self,
        poses: &[Pose],
        state: &mut FrameState,
        result: &mut FrameResult,
    ) -> Option<(Vec<crate::rcs::Candidate>, crate::StageBackend, f64)> {
        let rcs = state
            .gpu_answers
            .as_mut()
            .filter(|a| a.poses == poses)?
            .rcs
            .take()?;
        result.notes.extend(rcs.notes);
        Some((rcs.candidates, rcs.backend, rcs.time_us))
    }

    /// Without the `gpgpu` feature nothing is computed ahead.
    #[cfg(not(feature = "gpgpu"))]
    pub(crate) fn rcs_ahead(
        &self,
        _poses: &[Pose],
        _state: &mut FrameState,
        _result: &mut FrameResult,
    ) -> Option<(Vec<crate::rcs::Candidate>, crate::StageBackend, f64)> {
        None
    }

    /// A GPU failure ahead of the frame: an error under [`crate::GpuPolicy::Require`];
    /// otherwise the frame's own pair stage runs as in [`Checker::check`] (and reports its
    /// fallback there).
    #[cfg(feature = "gpgpu")]
    fn gpu_ahead_failed(&self, e: frcd_gpgpu::GpuError) -> Result<(), HybridError> {
        if self.options.gpu == crate::GpuPolicy::Require {
            return Err(HybridError::Gpu {
                stage: "pair query",
                source: e.into(),
            });
        }
        log::warn!("GPU pair batch ahead of its frame failed: {e}");
        Ok(())
    }
}
