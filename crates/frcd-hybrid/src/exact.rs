//! Stage 3: exact triangle tests on the CPU (and completion of GPU answers), and the clearance
//! of pairs within their threshold.

use crate::report::Via;
use crate::state::{Outcome, PairState};
use crate::{Checker, Contact};
use frcd_geom::{Pose, Triangle};
use frcd_obb::{ObbTree, PairCache, RelativeFrame, Request, collide_cached};
use std::time::Instant;

impl Checker {
    fn request(&self, mode: frcd_obb::Mode) -> Request {
        Request {
            mode,
            segments: self.options.segments,
            solid: self.options.solid,
            ..Request::default()
        }
    }

    /// Completes one job (CPU work; GPU results were stored in the plan).
    pub(crate) fn finish_job(&self, job: &mut Job, poses: &[Pose]) {
        let t = Instant::now();
        self.finish_job_inner(job, poses);
        job.time_us = t.elapsed().as_secs_f64() * 1e6;
        job.state.last_time_us = job.time_us;
    }

    fn finish_job_inner(&self, job: &mut Job, poses: &[Pose]) {
        let (ia, ib) = (job.key.0 as usize, job.key.1 as usize);
        let (pa, pb) = (&poses[ia], &poses[ib]);
        let (ta, tb) = (
            &self.trees[self.bodies[ia].mesh],
            &self.trees[self.bodies[ib].mesh],
        );
        let plan = std::mem::replace(&mut job.plan, Plan::Cpu);
        let (ma, mb) = (self.bodies[ia].mesh, self.bodies[ib].mesh);
        let spins = [
            self.clearance_spins[ma].as_deref(),
            self.clearance_spins[mb].as_deref(),
        ];
        // A pair with a clearance threshold: its clearance first. When that proves the surfaces
        // apart (a certified lower bound above 0 on their exact distance, for the same f64
        // inputs as the exact collision test), no triangle pair touches and only solid-mode
        // containment is left of the collision query: the answer is the same, without its
        // traversal of surfaces that are a few millimetres apart. Tried only for a pair that
        // was answered last frame without interfering: one that interfered most likely still
        // does, and one seen for the first time may touch (the search would be wasted).
        let mut early_work = frcd_obb::ClearanceWork::default();
        let was_apart = job.state.result.as_ref().is_some_and(|o| !o.collide());
        if let (Plan::Cpu, Some(t), true) = (&plan, job.threshold, was_apart) {
            let (apart, w) = frcd_obb::pair_clearance_apart(
                &self.clearance_trees[ma],
                pa,
                &self.clearance_trees[mb],
                pb,
                t,
                self.options.solid,
                spins,
                &mut job.state.clearance,
            );
            early_work = w;
            if let Some(apart) = apart {
                // The clearance trees hold the collision trees' meshes: the same containment.
                let contained = apart.contained;
                let mut outcome = Outcome {
                    pairs: Vec::new(),
                    contained,
                    segments: Vec::new(),
                    via: Via::Cpu,
                    clearance: apart.clearance,
                };
                job.clearance_work = early_work;
                if contained.is_some() {
                    // Interfering after all (one inside the other): its clearance is 0.
                    let (c, w) = frcd_obb::pair_clearance_spin(
                        &self.clearance_trees[ma],
                        pa,
                        &self.clearance_trees[mb],
                        pb,
                        t,
                        None,
                        true,
                        spins,
                        &mut job.state.clearance,
                    );
                    outcome.clearance = c;
                    early_work.pairs = 0;
                    job.clearance_work = early_work;
                    job.clearance_work += w;
                }
                job.plan = Plan::Cpu;
                job.state.poses = (*pa, *pb);
                job.state.result = Some(outcome);
                return;
            }
        }
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
                clearance: None,
            },
            Plan::ClearanceOnly => Outcome {
                pairs: Vec::new(),
                contained: None,
                segments: Vec::new(),
                via: Via::Cpu,
                clearance: None,
            },
            Plan::Cpu => self.cpu_query(ta, pa, tb, pb, &mut job.state.cache),
            Plan::GpuDone(pairs) => {
                // The GPU proved no surface pair touches: only containment is left to find.
                let contained = if pairs.is_empty() && self.options.solid {
                    frcd_obb::containment(ta, pa, tb, pb)
                } else {
                    None
                };
                let segments = self.segments_of(&pairs, ta, pa, tb, pb);
                Outcome {
                    pairs,
                    contained,
                    segments,
                    via: Via::Gpu,
                    clearance: None,
                }
            }
            Plan::Acs(sa, sb) => {
                let tri_a: Vec<Triangle> = sa.iter().map(|&i| ta.triangle(i)).collect();
                let tri_b: Vec<Triangle> = sb.iter().map(|&i| tb.triangle(i)).collect();
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
                        clearance: None,
                    }
                }
            }
        };
        let mut outcome = outcome;
        if let Some(t) = job.threshold {
            (outcome.clearance, job.clearance_work) = frcd_obb::pair_clearance_spin(
                &self.clearance_trees[ma],
                pa,
                &self.clearance_trees[mb],
                pb,
                t,
                outcome.pairs.first().copied(),
                outcome.collide(),
                spins,
                &mut job.state.clearance,
            );
            job.clearance_work += early_work;
        }
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
            clearance: None,
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
                frcd_tritri::intersection_segment(&ta.triangle(x), &frame.triangle(&tb.triangle(y)))
            })
            .collect()
    }
}

#[derive(Debug, PartialEq)]
#[cfg_attr(not(all(feature = "gpgpu", feature = "image")), allow(dead_code))]
pub(crate) enum Plan {
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
    /// The boxes do not overlap: no interference, only the clearance to find.
    ClearanceOnly,
}

pub(crate) struct Job {
    pub(crate) key: (u32, u32),
    /// The raw boxes overlap (the collision query runs).
    pub(crate) overlap: bool,
    /// The pair's clearance threshold.
    pub(crate) threshold: Option<f64>,
    pub(crate) state: PairState,
    pub(crate) plan: Plan,
    pub(crate) time_us: f64,
    /// Work of this frame's clearance evaluation.
    pub(crate) clearance_work: frcd_obb::ClearanceWork,
}
