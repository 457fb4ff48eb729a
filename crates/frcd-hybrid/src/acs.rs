//! Stage 2 (fast mode): the accurate colliding set from image space.

use crate::exact::{Job, Plan};
use crate::report::{Stage, StageBackend, StageReport};
use crate::{Backend, Checker, FrameResult, FrameState, HybridError};
use frcd_geom::Pose;
use std::time::Instant;

impl Checker {
    /// Runs the image-space pass on the pairs the cost model gives it; a pair without an
    /// interfering pixel is dropped, the others get their colliding triangle sets. On a GPU
    /// error the remaining pairs take the exact CPU path (noted in the frame's report).
    pub(crate) fn accurate_colliding_set(
        &self,
        work: &mut [Job],
        poses: &[Pose],
        state: &mut FrameState,
        result: &mut FrameResult,
    ) -> Result<(), HybridError> {
        let Some(img) = &self.image else {
            return Ok(());
        };
        let o = &self.options;
        let t1 = Instant::now();
        let mut ran = 0;
        for job in work.iter_mut().filter(|j| j.plan == Plan::Cpu) {
            let (ia, ib) = (job.key.0 as usize, job.key.1 as usize);
            let (ma, mb) = (self.bodies[ia].mesh, self.bodies[ib].mesh);
            let (Some(ga), Some(gb)) = (&img.meshes[ma], &img.meshes[mb]) else {
                continue;
            };
            if o.backend == Backend::Hybrid {
                let tris = self.meshes[ma].triangle_count() + self.meshes[mb].triangle_count();
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
            let r = match img
                .det
                .query(&mut state.image, ga, &poses[ia], gb, &poses[ib], &opts)
            {
                Ok(r) => r,
                Err(e) => {
                    self.gpu_failed("image", e.into(), result)?;
                    break;
                }
            };
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
        Ok(())
    }
}
