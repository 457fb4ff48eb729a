//! GPU devices and uploads: created when the cost model wants them; software adapters (wgpu
//! `DeviceType::Cpu`, e.g. lavapipe) are costed as software and not used by the hybrid backend
//! unless the cost model was calibrated on that adapter. GPU failures during a frame fall back
//! to the CPU ([`crate::GpuPolicy::Require`] makes them errors).

#[cfg(feature = "gpgpu")]
use crate::exact::{Job, Plan};
use crate::{Accuracy, Backend, Checker, FrameResult, GpuFailure, GpuPolicy, HybridError};
#[cfg(feature = "gpgpu")]
use crate::{FrameState, report::Via};
#[allow(unused_imports)]
use frcd_geom::Pose;

/// A caller's wgpu device and queue for the GPU stages of a checker
/// ([`Checker::with_device`]): an engine's own device, so that the checker's work shares its
/// queue and memory instead of opening a second device (features `gpgpu`, `image`).
#[cfg(any(feature = "gpgpu", feature = "image"))]
#[derive(Clone, Debug)]
pub struct GpuDevice {
    /// The device the checker's buffers, textures and pipelines are created on.
    pub device: wgpu::Device,
    /// The queue its submissions go to.
    pub queue: wgpu::Queue,
}

/// The device [`Checker::init_gpu`] is given: the caller's, or none (then headless devices of
/// the checker's own).
#[cfg(any(feature = "gpgpu", feature = "image"))]
pub(crate) type CallerDevice = GpuDevice;
/// Without GPU features no device can be given.
#[cfg(not(any(feature = "gpgpu", feature = "image")))]
pub(crate) type CallerDevice = std::convert::Infallible;

#[cfg(feature = "gpgpu")]
#[derive(Debug)]
pub(crate) struct Gpgpu {
    pub(crate) ctx: frcd_gpgpu::GpuContext,
    pub(crate) meshes: Vec<frcd_gpgpu::GpuMesh>,
}

#[cfg(feature = "image")]
#[derive(Debug)]
pub(crate) struct Image {
    pub(crate) det: frcd_image::ImageDetector,
    /// Per mesh: `None` for a mesh that is not a closed oriented manifold.
    pub(crate) meshes: Vec<Option<frcd_image::ImageMesh>>,
}

impl Checker {
    /// A GPU stage failed during a frame: an error under [`GpuPolicy::Require`], otherwise a
    /// note in the frame's report (the caller then runs the stage on the CPU).
    #[cfg_attr(not(any(feature = "gpgpu", feature = "image")), allow(dead_code))]
    pub(crate) fn gpu_failed(
        &self,
        stage: &'static str,
        source: GpuFailure,
        result: &mut FrameResult,
    ) -> Result<(), HybridError> {
        if self.options.gpu == GpuPolicy::Require {
            return Err(HybridError::Gpu { stage, source });
        }
        log::warn!("GPU {stage} failed, CPU used: {source}");
        result
            .notes
            .push(format!("GPU {stage} failed, CPU used instead: {source}"));
        Ok(())
    }

    /// True when a software adapter should not be used: the hybrid backend, a GPU not
    /// required ([`GpuPolicy::Auto`]), and a cost model not calibrated on this adapter.
    #[allow(dead_code)]
    fn skip_software(&self, software: bool, adapter: &str) -> bool {
        software
            && self.options.backend == Backend::Hybrid
            && self.options.gpu == GpuPolicy::Auto
            && self.options.cost.adapter != adapter
    }

    pub(crate) fn init_gpu(&mut self, device: Option<CallerDevice>) -> Result<(), HybridError> {
        #[cfg(not(any(feature = "gpgpu", feature = "image")))]
        let _ = device;
        let o = self.options.clone();
        if o.gpu == GpuPolicy::Off {
            if matches!(o.backend, Backend::Gpgpu | Backend::Image) {
                return Err(HybridError::Gpu {
                    stage: "init",
                    source: GpuFailure::Unavailable(format!(
                        "backend '{}' needs a GPU but GPU use is off",
                        o.backend.name()
                    )),
                });
            }
            return Ok(());
        }
        let n = self.bodies.len();
        let want_gpgpu = match o.backend {
            Backend::Gpgpu => true,
            Backend::Hybrid => {
                o.cost.gpu_broad_min_bodies().is_some_and(|m| n >= m)
                    || (o.mode == Accuracy::Exact
                        && o.cost
                            .gpu_narrow_min_triangles()
                            .is_some_and(|t| self.max_pair_triangles() >= t))
            }
            _ => false,
        };
        let want_image = o.mode == Accuracy::Fast
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
            match self.make_gpgpu(device.as_ref()) {
                Ok(g) => {
                    let name = g.ctx.adapter_info().name.clone();
                    if self.skip_software(g.ctx.is_software(), &name) {
                        self.notes.push(format!(
                            "gpgpu: '{name}' is a software adapter, costed as software: CPU used \
                             (a cost model calibrated on this adapter changes that)"
                        ));
                    } else {
                        self.gpgpu = Some(g);
                    }
                }
                Err(source) if hard => {
                    return Err(HybridError::Gpu {
                        stage: "gpgpu",
                        source,
                    });
                }
                Err(e) => self.notes.push(format!("gpgpu unavailable, CPU used: {e}")),
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
            match self.make_image(device.as_ref()) {
                Ok(g) => {
                    let ctx = g.det.context();
                    let name = ctx.adapter_info().map_or(String::new(), |i| i.name.clone());
                    if self.skip_software(ctx.is_software(), &name) {
                        self.notes.push(format!(
                            "image: '{name}' is a software adapter, costed as software: exact \
                             CPU path used (a cost model calibrated on this adapter changes that)"
                        ));
                    } else {
                        self.image = Some(g);
                    }
                }
                Err(source) if hard => {
                    return Err(HybridError::Gpu {
                        stage: "image",
                        source,
                    });
                }
                Err(e) => self
                    .notes
                    .push(format!("image space unavailable, exact CPU path used: {e}")),
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
    fn make_gpgpu(&self, device: Option<&GpuDevice>) -> Result<Gpgpu, GpuFailure> {
        use rayon::prelude::*;
        let mut ctx = match device {
            Some(d) => frcd_gpgpu::GpuContext::from_device(d.device.clone(), d.queue.clone())?,
            None => frcd_gpgpu::GpuContext::headless()?,
        };
        if let Some(tests) = self.options.gpu_host_front {
            ctx.set_host_front(tests);
        }
        if let Some(workgroups) = self.options.gpu_one_pass {
            ctx.set_one_pass(workgroups);
        }
        if !self.options.gpu_recheck_certified {
            ctx.set_recheck(frcd_gpgpu::Recheck::Uncertain);
        }
        let meshes = match self.options.gpu_build {
            // Trees of their own for the GPU, dropped once packed (the upload keeps the mesh).
            Some(gb) if gb != self.options.build => self
                .meshes
                .par_iter()
                .map(|m| frcd_obb::ObbTree::build(m, &gb))
                .collect::<Vec<_>>()
                .iter()
                .map(|t| ctx.upload(t))
                .collect::<Result<Vec<_>, _>>()?,
            _ => self
                .trees
                .iter()
                .map(|t| ctx.upload(t))
                .collect::<Result<Vec<_>, _>>()?,
        };
        Ok(Gpgpu { ctx, meshes })
    }

    #[cfg(feature = "image")]
    fn make_image(&mut self, device: Option<&GpuDevice>) -> Result<Image, GpuFailure> {
        let det = match device {
            Some(d) => frcd_image::ImageDetector::new(frcd_image::ImageContext::from_device(
                d.device.clone(),
                d.queue.clone(),
            )?)?,
            None => frcd_image::ImageDetector::headless()?,
        };
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
                Err(e) => return Err(e.into()),
            }
        }
        Ok(Image { det, meshes })
    }

    /// True when body pair `key`, computed fresh in exact mode, goes to the GPU pair traversal
    /// (a GPU in use and the backend or the cost model choosing it for its triangle count).
    #[cfg(feature = "gpgpu")]
    pub(crate) fn wants_gpu_narrow(&self, key: (u32, u32)) -> bool {
        let o = &self.options;
        if self.gpgpu.is_none() || o.mode != Accuracy::Exact {
            return false;
        }
        let (ma, mb) = (
            self.bodies[key.0 as usize].mesh,
            self.bodies[key.1 as usize].mesh,
        );
        let tris = self.meshes[ma].triangle_count() + self.meshes[mb].triangle_count();
        o.backend == Backend::Gpgpu || o.cost.prefer_gpu_narrow(tris)
    }

    /// Exact mode: the GPU pair traversal for the pairs the cost model gives it, all in **one**
    /// batch (one submission, one readback: [`frcd_gpgpu::GpuContext::collide_batch`]). Pairs a
    /// pipelined run already answered for these poses ([`crate::Pipeline`]) are taken from its
    /// answers. Returns how many pairs the GPU answered; on a GPU error the pairs stay on the
    /// CPU.
    #[cfg(feature = "gpgpu")]
    pub(crate) fn gpu_pair_queries(
        &self,
        work: &mut [Job],
        poses: &[Pose],
        state: &mut FrameState,
        result: &mut FrameResult,
    ) -> Result<usize, HybridError> {
        let mut answered = state.gpu_answers.take().filter(|a| a.poses == poses);
        let Some(g) = self
            .gpgpu
            .as_ref()
            .filter(|_| self.options.mode == Accuracy::Exact)
        else {
            return Ok(0);
        };
        let _ = Via::Gpu;
        let mut gpu_pairs = 0;
        let mut batch_jobs = Vec::new();
        for (i, job) in work.iter_mut().enumerate() {
            if job.plan != Plan::Cpu || !self.wants_gpu_narrow(job.key) {
                continue;
            }
            match answered.as_mut().and_then(|a| a.pairs.remove(&job.key)) {
                Some(pairs) => {
                    job.plan = Plan::GpuDone(pairs);
                    gpu_pairs += 1;
                }
                None => batch_jobs.push(i),
            }
        }
        if batch_jobs.is_empty() {
            return Ok(gpu_pairs);
        }
        let items: Vec<frcd_gpgpu::BodyPair<'_>> = batch_jobs
            .iter()
            .map(|&i| {
                let (ia, ib) = (work[i].key.0 as usize, work[i].key.1 as usize);
                let (ma, mb) = (self.bodies[ia].mesh, self.bodies[ib].mesh);
                (&g.meshes[ma], &poses[ia], &g.meshes[mb], &poses[ib])
            })
            .collect();
        match g.ctx.collide_batch(&items, &mut state.gpu_query) {
            Ok(batch) => {
                for (&i, r) in batch_jobs.iter().zip(batch.results) {
                    work[i].plan = Plan::GpuDone(r.pairs);
                    gpu_pairs += 1;
                }
            }
            Err(e) => self.gpu_failed("pair query", e.into(), result)?,
        }
        Ok(gpu_pairs)
    }

    /// Command-buffer submissions made on the checker's GPGPU device so far (0 without one):
    /// one per frame that sends pairs to the GPU, plus one per buffer overflow re-run.
    pub fn gpu_submissions(&self) -> u64 {
        #[cfg(feature = "gpgpu")]
        if let Some(g) = &self.gpgpu {
            return g.ctx.submissions();
        }
        0
    }

    /// Without the `gpgpu` feature no pair runs on the GPU.
    #[cfg(not(feature = "gpgpu"))]
    pub(crate) fn gpu_pair_queries(
        &self,
        _work: &mut [crate::exact::Job],
        _poses: &[Pose],
        _state: &mut crate::FrameState,
        _result: &mut FrameResult,
    ) -> Result<usize, HybridError> {
        Ok(0)
    }
}
