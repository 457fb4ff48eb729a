//! Stage 1: the rough colliding set (body pairs whose world boxes overlap), from the
//! [`frcd_obb::World`] broad phase or the GPU box pass.

use crate::report::StageBackend;
use crate::{Checker, FrameResult, FrameState, HybridError};
use frcd_geom::{Aabb, DVec3};

/// A body pair of the rough colliding set.
pub(crate) struct Candidate {
    /// Body indices, `a < b`.
    pub(crate) key: (u32, u32),
    /// The raw world boxes overlap: the collision query runs (otherwise the pair is only
    /// within its clearance threshold's reach).
    pub(crate) overlap: bool,
    /// The pair's clearance threshold.
    pub(crate) threshold: Option<f64>,
}

/// Euclidean distance between two boxes (0 when they overlap).
fn box_gap(a: &Aabb, b: &Aabb) -> f64 {
    (a.min - b.max).max(b.min - a.max).max(DVec3::ZERO).length()
}

/// A rough colliding set begun ([`Checker::rcs_begin`]): the World moved to the frame's poses
/// and, when the GPU box pass runs, that pass submitted and not yet read.
pub(crate) struct RcsStart {
    margin: f64,
    #[cfg(feature = "gpgpu")]
    pending: Option<frcd_gpgpu::SubmittedBoxes>,
}

impl Checker {
    /// Moves the state's World to `poses` and returns the pairs to look at: boxes overlapping,
    /// or closer than the pair's clearance threshold. Sorted by `(a, b)`.
    pub(crate) fn rough_colliding_set(
        &self,
        poses: &[frcd_geom::Pose],
        state: &mut FrameState,
        result: &mut FrameResult,
    ) -> Result<(Vec<Candidate>, StageBackend), HybridError> {
        let start = self.rcs_begin(poses, state, result)?;
        self.rcs_finish(start, state, result)
    }

    /// The first half of [`Checker::rough_colliding_set`]: moves the World to `poses` and, when
    /// the GPU box pass is chosen, submits it (read by [`Checker::rcs_finish`], so the caller
    /// can work while the GPU runs it). A GPU failure here leaves the pass to the CPU.
    pub(crate) fn rcs_begin(
        &self,
        poses: &[frcd_geom::Pose],
        state: &mut FrameState,
        #[allow(unused_variables)] result: &mut FrameResult,
    ) -> Result<RcsStart, HybridError> {
        let world = state.world.as_mut().expect("bound by check");
        state.updates.clear();
        state
            .updates
            .extend(state.ids.iter().copied().zip(poses.iter().copied()));
        world.set_poses(&state.updates)?;
        let margin = world.max_clearance().unwrap_or(0.0);
        #[allow(unused_mut)]
        let mut start = RcsStart {
            margin,
            #[cfg(feature = "gpgpu")]
            pending: None,
        };
        #[cfg(feature = "gpgpu")]
        if let Some(g) = &self.gpgpu {
            let n = state.ids.len();
            let o = &self.options;
            let use_gpu = if o.backend == crate::Backend::Gpgpu {
                n >= o.gpgpu_box_pass_min_bodies
            } else {
                o.cost.gpu_broad_min_bodies().is_some_and(|m| n >= m)
            };
            if use_gpu && n >= 2 {
                let boxes: Vec<Aabb> = state
                    .ids
                    .iter()
                    .map(|&id| {
                        world
                            .body_aabb(id)
                            .expect("live body")
                            .inflated(margin * 0.5)
                    })
                    .collect();
                let scratch = std::mem::take(&mut state.gpu_boxes);
                match g.ctx.submit_broad_phase(&boxes, scratch) {
                    Ok(p) => start.pending = Some(p),
                    Err(e) => self.gpu_failed("box pass", e.into(), result)?,
                }
            }
        }
        Ok(start)
    }

    /// The second half of [`Checker::rough_colliding_set`]: reads the GPU box pass
    /// [`Checker::rcs_begin`] submitted (or runs the World's broad phase) and filters the pairs.
    pub(crate) fn rcs_finish(
        &self,
        #[allow(unused_mut)] mut start: RcsStart,
        state: &mut FrameState,
        #[allow(unused_variables)] result: &mut FrameResult,
    ) -> Result<(Vec<Candidate>, StageBackend), HybridError> {
        let margin = start.margin;
        #[allow(unused_mut)]
        let mut found: Option<Vec<(u32, u32)>> = None;
        #[allow(unused_mut)]
        let mut backend = StageBackend::Cpu;
        #[cfg(feature = "gpgpu")]
        if let (Some(g), Some(pending)) = (&self.gpgpu, start.pending.take()) {
            match g.ctx.resolve_broad_phase(pending) {
                Ok((f, scratch)) => {
                    state.gpu_boxes = scratch;
                    let mut v: Vec<(u32, u32)> = f
                        .pairs
                        .into_iter()
                        .map(|(i, j)| (i.min(j), i.max(j)))
                        .filter(|&(i, j)| self.testable(i, j))
                        .collect();
                    v.sort_unstable();
                    found = Some(v);
                    backend = StageBackend::Gpu;
                }
                Err(e) => self.gpu_failed("box pass", e.into(), result)?,
            }
        }
        let world = state.world.as_mut().expect("bound by check");
        let found = match found {
            Some(v) => v,
            None => world
                .overlapping_pairs(margin)
                .into_iter()
                .map(|(a, b)| (a.index(), b.index()))
                .collect(),
        };
        let ids = &state.ids;
        let out = found
            .into_iter()
            .filter_map(|(i, j)| {
                let (a, b) = (ids[i as usize], ids[j as usize]);
                let (ba, bb) = (world.body_aabb(a)?, world.body_aabb(b)?);
                let overlap = ba.intersects(&bb);
                let threshold = if margin > 0.0 || world.clearance().is_some() {
                    world.pair_clearance_threshold(a, b)
                } else {
                    None
                };
                if !overlap && threshold.is_none_or(|t| box_gap(&ba, &bb) > t) {
                    return None;
                }
                Some(Candidate {
                    key: (i, j),
                    overlap,
                    threshold,
                })
            })
            .collect();
        Ok((out, backend))
    }
}
