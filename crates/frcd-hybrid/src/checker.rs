//! The checker: bodies, trees, options, GPU devices; [`Checker::check`] runs the stages
//! (`rcs`, `acs`, `exact`) on a caller-owned [`FrameState`].

use crate::exact::{Job, Plan};
#[cfg(feature = "gpgpu")]
use crate::gpu::Gpgpu;
#[cfg(feature = "image")]
use crate::gpu::Image;
use crate::report::{PairClearance, PairContact, Stage, StageBackend, StageReport, Via};
use crate::{Accuracy, Backend, BodySpec, FrameResult, FrameState, HybridError, Options};
use frcd_geom::{Pose, TriMesh};
use frcd_obb::{ObbTree, SpinProfile, World, WorldOptions};
use rayon::prelude::*;
use std::collections::{HashMap, HashSet};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::time::Instant;

static NEXT_SERIAL: AtomicU64 = AtomicU64::new(1);

#[derive(Debug)]
pub(crate) struct BodyInfo {
    pub(crate) name: String,
    pub(crate) mesh: usize,
    pub(crate) is_static: bool,
}

/// The scheduler: trees built once per distinct mesh, GPU uploads made once; [`Checker::check`]
/// answers one frame. The broad phase and the body handles are an [`frcd_obb::World`]'s (kept
/// in the [`FrameState`]); body `i` is the `i`-th [`BodySpec`].
#[derive(Debug)]
pub struct Checker {
    /// Identifies the checker to its frame states.
    pub(crate) serial: u64,
    pub(crate) pool: Option<Arc<rayon::ThreadPool>>,
    pub(crate) bodies: Vec<BodyInfo>,
    pub(crate) meshes: Vec<Arc<TriMesh>>,
    pub(crate) trees: Vec<Arc<ObbTree>>,
    /// Per mesh, the tree of the clearance searches (`trees` unless
    /// [`Options::clearance_build`] asks for others).
    pub(crate) clearance_trees: Vec<Arc<ObbTree>>,
    /// Per mesh, its meridian profile when it is a solid of revolution and
    /// [`Options::clearance_spin`] asks for them.
    pub(crate) clearance_spins: Vec<Option<Arc<SpinProfile>>>,
    pub(crate) excluded: HashSet<(u32, u32)>,
    pub(crate) options: Options,
    pub(crate) notes: Vec<String>,
    #[cfg(feature = "gpgpu")]
    pub(crate) gpgpu: Option<Gpgpu>,
    #[cfg(feature = "image")]
    pub(crate) image: Option<Image>,
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
        Self::build(bodies, exclude, options, None)
    }

    /// [`Checker::new`] whose GPU stages run on the caller's device and queue (an engine's
    /// own) instead of a headless device of the checker's own: frcd-gpgpu's
    /// `GpuContext::from_device` and frcd-image's `ImageContext::from_device` on clones of
    /// `device`'s handles. The same rules choose whether a GPU stage runs at all (the backend,
    /// the cost model, [`Options::gpu`]); a device that lacks what a wanted stage needs is
    /// refused as a headless one would be (an error under [`crate::GpuPolicy::Require`] or a
    /// GPGPU / image backend, otherwise a note and the CPU).
    ///
    /// ```no_run
    /// # fn engine_device() -> (wgpu::Device, wgpu::Queue) { unimplemented!() }
    /// use frcd_hybrid::{Backend, Checker, GpuDevice, Options};
    /// let (device, queue) = engine_device();
    /// let options = Options { backend: Backend::Gpgpu, ..Options::default() };
    /// let checker = Checker::with_device(vec![], &[], options, GpuDevice { device, queue })?;
    /// # Ok::<(), frcd_hybrid::HybridError>(())
    /// ```
    #[cfg(any(feature = "gpgpu", feature = "image"))]
    pub fn with_device(
        bodies: Vec<BodySpec>,
        exclude: &[(usize, usize)],
        options: Options,
        device: crate::GpuDevice,
    ) -> Result<Self, HybridError> {
        Self::build(bodies, exclude, options, Some(device))
    }

    fn build(
        bodies: Vec<BodySpec>,
        exclude: &[(usize, usize)],
        options: Options,
        device: Option<crate::gpu::CallerDevice>,
    ) -> Result<Self, HybridError> {
        let count = bodies.len();
        let mut excluded = HashSet::new();
        for &(a, b) in exclude {
            if a >= count || b >= count {
                return Err(HybridError::BadExclusion { a, b, count });
            }
            excluded.insert((a.min(b) as u32, a.max(b) as u32));
        }
        if let Some(value) = options.clearance.filter(|t| t.is_nan() || *t < 0.0) {
            return Err(HybridError::BadClearance {
                a: usize::MAX,
                b: usize::MAX,
                value,
                count,
            });
        }
        for &((a, b), value) in &options.pair_clearances {
            if a >= count || b >= count || a == b || value.is_nan() || value < 0.0 {
                return Err(HybridError::BadClearance { a, b, value, count });
            }
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
            Backend::Image if options.mode == Accuracy::Exact => {
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
        let wants_clearance = options.clearance.is_some() || !options.pair_clearances.is_empty();
        let clearance_trees: Vec<Arc<ObbTree>> = match options.clearance_build {
            Some(cb) if wants_clearance && cb != build => meshes
                .par_iter()
                .map(|m| Arc::new(ObbTree::build(m, &cb)))
                .collect(),
            _ => trees.clone(),
        };
        let clearance_spins: Vec<Option<Arc<SpinProfile>>> =
            if wants_clearance && options.clearance_spin {
                clearance_trees
                    .par_iter()
                    .map(|t| SpinProfile::detect(t).map(Arc::new))
                    .collect()
            } else {
                vec![None; clearance_trees.len()]
            };
        #[allow(unused_mut)]
        let mut checker = Checker {
            serial: NEXT_SERIAL.fetch_add(1, Ordering::Relaxed),
            pool: None,
            bodies: infos,
            meshes,
            trees,
            clearance_trees,
            clearance_spins,
            excluded,
            options,
            notes: Vec::new(),
            #[cfg(feature = "gpgpu")]
            gpgpu: None,
            #[cfg(feature = "image")]
            image: None,
        };
        checker.init_gpu(device)?;
        Ok(checker)
    }

    /// Largest triangle count of a testable body pair (for the GPU narrow-phase decision).
    pub(crate) fn max_pair_triangles(&self) -> usize {
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

    pub(crate) fn testable(&self, i: u32, j: u32) -> bool {
        let (a, b) = (&self.bodies[i as usize], &self.bodies[j as usize]);
        let both_static = a.is_static && b.is_static;
        !both_static && !self.excluded.contains(&(i.min(j), i.max(j)))
    }

    /// Runs the CPU narrow phase on this pool (`None`: the caller's current rayon pool, the
    /// global one unless the caller is inside `ThreadPool::install`). Answers do not depend on
    /// the pool.
    pub fn set_thread_pool(&mut self, pool: Option<Arc<rayon::ThreadPool>>) {
        self.pool = pool;
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

    /// Answers one frame: `poses[i]` is body `i`'s world pose. `state` is this checker's
    /// frame-to-frame state (a state of another checker is refused).
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
        if state.owner != 0 && state.owner != self.serial {
            return Err(HybridError::ForeignState);
        }
        if state.world.is_none() {
            self.bind(state, poses)?;
        }
        let mut result = FrameResult::empty();
        // Stage 1: rough colliding set (body pairs, with whether their raw boxes overlap and
        // their clearance threshold).
        // (A pipelined run computed it ahead: `crate::pipeline`.)
        let t0 = Instant::now();
        let (rcs, broad_backend, ahead_us) = match self.rcs_ahead(poses, state, &mut result) {
            Some(ahead) => ahead,
            None => {
                let (rcs, backend) = self.rough_colliding_set(poses, state, &mut result)?;
                (rcs, backend, 0.0)
            }
        };
        result.stages[0] = StageReport {
            stage: Stage::Broad,
            backend: broad_backend,
            time_us: ahead_us + t0.elapsed().as_secs_f64() * 1e6,
            items: n,
        };
        result.rcs = rcs.iter().filter(|c| c.overlap).count();
        // Take the states of the RCS pairs; pairs that left the RCS are forgotten.
        let mut old = std::mem::take(&mut state.pairs);
        let mut work: Vec<Job> = rcs
            .iter()
            .map(|c| {
                let k = c.key;
                let st = old.remove(&k).unwrap_or_default();
                let cur = (poses[k.0 as usize], poses[k.1 as usize]);
                let reuse = st.result.is_some() && st.poses == cur;
                Job {
                    key: k,
                    overlap: c.overlap,
                    threshold: c.threshold,
                    state: st,
                    plan: match (reuse, c.overlap) {
                        (true, _) => Plan::Reuse,
                        (false, true) => Plan::Cpu,
                        (false, false) => Plan::ClearanceOnly,
                    },
                    time_us: 0.0,
                    clearance_work: frcd_obb::ClearanceWork::default(),
                }
            })
            .collect();
        drop(old);
        // Stage 2: accurate colliding set (fast mode).
        #[cfg(feature = "image")]
        if self.options.mode == Accuracy::Fast {
            self.accurate_colliding_set(&mut work, poses, state, &mut result)?;
        }
        // Stage 3: exact triangle tests.
        let t2 = Instant::now();
        let gpu_pairs = self.gpu_pair_queries(&mut work, poses, state, &mut result)?;
        let cpu_pairs = work
            .iter()
            .filter(|j| !matches!(j.plan, Plan::Reuse | Plan::Dropped | Plan::ClearanceOnly))
            .count()
            - gpu_pairs;
        let run = |work: &mut Vec<Job>| self.run_jobs(work, poses);
        match &self.pool {
            Some(pool) => pool.install(|| run(&mut work)),
            None => run(&mut work),
        }
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
            } else if job.overlap {
                result
                    .pair_times_us
                    .push((job.key.0 as usize, job.key.1 as usize, job.time_us));
            }
            let (a, b) = (job.key.0 as usize, job.key.1 as usize);
            if out.collide() {
                result.contacts.push(PairContact {
                    a,
                    b,
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
            result.clearance_work += job.clearance_work;
            if let Some(c) = out.clearance {
                let c: PairClearance = c.with_ids(a, b);
                result.clearances.push(c);
            }
            state.pairs.insert(job.key, job.state);
        }
        Ok(result)
    }

    /// Runs the frame's jobs on the current pool, longest first by last frame's time, each
    /// thread taking the next job when it is done (a few heavy pairs, such as the bogie's
    /// wheel / brake-block distance searches, then land on different threads). The answers do
    /// not depend on the order.
    fn run_jobs(&self, work: &mut [Job], poses: &[Pose]) {
        let threads = rayon::current_num_threads();
        if threads <= 1 || work.len() <= 1 {
            work.iter_mut().for_each(|job| self.finish_job(job, poses));
            return;
        }
        let mut order: Vec<&mut Job> = work.iter_mut().collect();
        order.sort_by(|x, y| y.state.last_time_us.total_cmp(&x.state.last_time_us));
        let order: Vec<std::sync::Mutex<&mut Job>> =
            order.into_iter().map(std::sync::Mutex::new).collect();
        let next = AtomicUsize::new(0);
        let take = || {
            loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                let Some(job) = order.get(i) else { break };
                let mut job = job.lock().unwrap_or_else(|e| e.into_inner());
                self.finish_job(&mut job, poses);
            }
        };
        rayon::scope(|s| {
            for _ in 1..threads.min(order.len()) {
                s.spawn(|_| take());
            }
            take();
        });
    }

    /// Binds a fresh state to this checker: a World holding every body, its exclusions and
    /// clearance thresholds.
    pub(crate) fn bind(&self, state: &mut FrameState, poses: &[Pose]) -> Result<(), HybridError> {
        let mut world = World::new(WorldOptions::default());
        let ids = self
            .bodies
            .iter()
            .zip(poses)
            .map(|(b, p)| world.add_body(self.trees[b.mesh].clone(), *p, b.is_static))
            .collect::<Result<Vec<_>, _>>()?;
        for &(a, b) in &self.excluded {
            world.exclude_pair(ids[a as usize], ids[b as usize])?;
        }
        world.set_clearance(self.options.clearance)?;
        for &((a, b), t) in &self.options.pair_clearances {
            world.set_pair_clearance(ids[a], ids[b], Some(t))?;
        }
        state.pairs.clear();
        state.world = Some(world);
        state.ids = ids;
        state.owner = self.serial;
        Ok(())
    }
}
