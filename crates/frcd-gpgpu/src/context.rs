use crate::GpuError;
use crate::shaders;
use std::sync::atomic::{AtomicU64, Ordering};

static NEXT_CONTEXT_ID: AtomicU64 = AtomicU64::new(1);

/// Workgroup size of the traversal pass (must match `WG` in the shaders).
pub(crate) const WG: u32 = 64;
/// Boxes per tile of the box pass (workgroup size and staged tile, must match boxes.wgsl).
pub(crate) const BOX_TILE: u32 = 64;

/// The device limits frcd-gpgpu needs (no optional feature is needed:
/// [`wgpu::Features::empty()`]). Everything else (texture size, buffer sizes, workgroups per
/// dimension) is read from the device and used as it is; meshes and buffers that do not fit
/// return a typed error.
///
/// Also needed, checked where an adapter is known ([`GpuContext::headless`],
/// [`GpuContext::from_adapter`]): the downlevel flags `COMPUTE_SHADERS` and `INDIRECT_EXECUTION`.
pub fn requirements() -> wgpu::Limits {
    wgpu::Limits {
        // traverse.wgsl: frontier in/out (triangle list and output in the triangle pass),
        // state, triangle list, pair table, the next two levels' indirect arguments.
        max_storage_buffers_per_shader_stage: 7,
        // The arena (nodes, triangles) and the pairs' poses.
        max_sampled_textures_per_shader_stage: 3,
        // The arena layout, the capacities, the traversal level.
        max_uniform_buffers_per_shader_stage: 3,
        max_bind_groups: 2,
        max_storage_buffer_binding_size: 1 << 16,
        max_compute_invocations_per_workgroup: WG,
        max_compute_workgroup_size_x: WG,
        max_compute_workgroup_size_y: 1,
        // boxes.wgsl stages 64 boxes of 64 bytes.
        max_compute_workgroup_storage_size: BOX_TILE * 64,
        max_compute_workgroup_size_z: 1,
        max_compute_workgroups_per_dimension: 1,
        // The pose texture's rows are 1,280 texels (256 pairs of five; asked as WebGL 2's
        // minimum, 2,048); the arena needs one node (4 texels) per row at least.
        max_texture_dimension_2d: 2048,
        // Two layers at least (wgpu's GL backend, see `pack::MIN_LAYERS`).
        max_texture_array_layers: 2,
        ..wgpu::Limits::downlevel_webgl2_defaults()
    }
}

/// The device features GPU pass timers need.
pub(crate) const PASS_TIMER_FEATURES: wgpu::Features =
    wgpu::Features::TIMESTAMP_QUERY.union(wgpu::Features::TIMESTAMP_QUERY_INSIDE_PASSES);

/// Options of [`GpuContext::headless`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct HeadlessOptions {
    /// Prefer a discrete GPU (default) or an integrated / low-power one.
    pub low_power: bool,
    /// Ask for the fallback (software) adapter only.
    pub force_fallback_adapter: bool,
    /// Restrict the instance to these wgpu backends (e.g. `wgpu::Backends::GL`); `None`: every
    /// backend compiled in, narrowed by `WGPU_BACKEND`.
    pub backends: Option<wgpu::Backends>,
    /// Shape of the mesh arena.
    pub arena: crate::ArenaOptions,
    /// Ask for GPU timestamps and time every pass of a batch ([`crate::BatchTimings`]); where
    /// the adapter offers no timestamps inside passes the context is made without them
    /// ([`GpuContext::has_pass_timers`] says which). Off by default: a profiling aid.
    pub pass_timers: bool,
    /// Which reported triangle pairs the CPU re-decides exactly ([`Recheck`]).
    pub recheck: Recheck,
}

/// Which triangle pairs the GPU reports the CPU re-decides with the exact test.
///
/// The GPU reports a pair as *touching* only when every sign it used exceeds an error bound
/// derived for any conforming WGSL implementation (either rounding direction, fused
/// multiply-adds, flush-to-zero; the derivation is beside `tri_tri` in `shaders/traverse.wgsl`,
/// checked by `emulate.rs` under every rounding mode), and as *uncertain* otherwise. On a real
/// GPU the CPU's exact test of the reported pairs is most of a large batch's time (an H200: 13 of
/// 16 ms at 1.3M triangles per body on one thread), mostly cache misses fetching both triangles.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Recheck {
    /// Every reported pair, touching or uncertain (the default): a driver that breaks WGSL's float
    /// rules, or a bug, cannot add a pair ([`crate::GpuCollision::gpu_refuted`] counts what the
    /// exact test dropped).
    #[default]
    All,
    /// Only the pairs the GPU flagged uncertain; its *touching* pairs are taken as certified by
    /// the bounds (`gpu_refuted` stays 0). Faster where many pairs touch; trusts the driver's
    /// conformance, as its *disjoint* verdicts always do: `emulate.rs` checks under every
    /// rounding mode, with and without FMA and flush-to-zero, that no disjoint pair is declared
    /// touching (`no_disjoint_triangle_pair_is_declared_touching_under_any_rounding`).
    Uncertain,
}

/// Environment variable that overrides the default of [`GpuContext::set_exact_offsets`] for
/// new contexts: `1` on, `0` off (for measurements through programs that do not call it).
pub const EXACT_OFFSETS_ENV: &str = "FRCD_GPGPU_EXACT_OFFSETS";

/// Environment variable that overrides the default of [`GpuContext::set_one_pass`] for new
/// contexts: the workgroups (`0`: the level chain), for measurements through programs that do
/// not call it.
pub const ONE_PASS_ENV: &str = "FRCD_GPGPU_ONE_PASS";

/// Environment variable that sets `traverse.wgsl`'s override constant `VARIANT` (a u32, 0 when
/// unset) in the pipelines of new contexts: a measurement hook. A contrast build of the shader
/// branches on it, `if VARIANT == 1u { the change } else { the code it replaces }`, and
/// `cargo xtask bench gpgpu --checker-shader-variants 1` builds one checker per variant and
/// times them run by run in one process (on a shared host separate processes differ by more
/// than most changes measure). Shipped shaders never read it.
pub const SHADER_VARIANT_ENV: &str = "FRCD_GPGPU_SHADER_VARIANT";

/// [`SHADER_VARIANT_ENV`]'s value: 0 when unset; a value that is not a u32 is 0 with a warning.
fn shader_variant() -> u32 {
    let Ok(v) = std::env::var(SHADER_VARIANT_ENV) else {
        return 0;
    };
    v.trim().parse().unwrap_or_else(|_| {
        log::warn!("{SHADER_VARIANT_ENV}={v:?} is not a u32; shader variant 0 used");
        0
    })
}

/// Loop iterations one invocation of the one-pass traversal may run before its workgroup stops
/// and the batch re-runs as the level chain. llvmpipe silently ends a shader invocation's
/// loops once they have run 65,535 iterations in all (Mesa's `LP_MAX_TGSI_LOOP_ITERATIONS`):
/// a workgroup whose share of a large batch needs more would lose pairs there. The shader
/// counts a bound on its iterations (the copy of its first level, each level's loop over its
/// entries, the loops of its leaf pairs' triangle tests) before it runs them and stops short
/// of this. [`GpuContext::set_one_pass_loop_budget`] never sets more.
pub const ONE_PASS_LOOP_BUDGET: u32 = 49_152;

/// Most workgroups [`GpuContext::set_one_pass`]'s default gives a software adapter.
pub const ONE_PASS_SOFTWARE_MAX: u32 = 64;

/// The one-pass traversal's default for a new context, unless [`ONE_PASS_ENV`] says: on a
/// software adapter one workgroup per thread the driver runs shaders on (lavapipe's
/// `LP_NUM_THREADS`, by default the host's cores; at most [`ONE_PASS_SOFTWARE_MAX`]), since
/// such a driver runs each workgroup on one thread; on a hardware adapter the level chain (0).
/// Measured on a 2-core host with lavapipe (2026-12-02): with 2 workgroups the checker's 64-part
/// frame took 0.81-0.94 of the level chain's, with 4 about 1.07 of 2's; 64 and 256 workgroups
/// made one batch 2.3× and 7× slower than 2.
fn one_pass_default(info: &wgpu::AdapterInfo) -> u32 {
    let var = |name: &str| std::env::var(name).ok().and_then(|v| v.parse::<u32>().ok());
    if let Some(n) = var(ONE_PASS_ENV) {
        return n;
    }
    if info.device_type != wgpu::DeviceType::Cpu {
        return 0;
    }
    // LP_NUM_THREADS=0: lavapipe runs shaders on its queue thread alone.
    let threads = var("LP_NUM_THREADS")
        .map(|n| n.max(1))
        .or_else(|| {
            std::thread::available_parallelism()
                .ok()
                .map(|n| n.get() as u32)
        })
        .unwrap_or(1);
    threads.clamp(1, ONE_PASS_SOFTWARE_MAX)
}

/// [`GpuContext::set_host_front`]'s default on software adapters: box tests per level the CPU
/// takes off the GPU at the top of a batch's pair trees. 1,024 since 2026-12-03: with the
/// one-pass traversal and the 64-part checker frame's box pass on the CPU, lavapipe (2 cores)
/// took 0.957-0.967 of 2,048's time in GPGPU `check` over three runs of 31-51 alternated in
/// one process (`check_pipelined` 0.944-1.005; 512 about the same, 4,096 1.02-1.06;
/// `cargo xtask bench gpgpu --boxes-only --bodies 2 --checker-parts 64 --checker-host-front 512,1024`).
pub const HOST_FRONT_SOFTWARE: u32 = 1024;

/// The exact path's default for a new context: on for hardware adapters (on an H200 it cut the
/// uncertain pairs 70-200× at no measurable cost to the triangle pass), off for software ones
/// (on lavapipe its integer work made the triangle pass about twice as long, more than the CPU
/// re-decision it saves there; see docs/performance/gpu.md), unless [`EXACT_OFFSETS_ENV`] says.
fn exact_offsets_default(info: &wgpu::AdapterInfo) -> bool {
    match std::env::var(EXACT_OFFSETS_ENV).as_deref() {
        Ok("1") => true,
        Ok("0") => false,
        _ => info.device_type != wgpu::DeviceType::Cpu,
    }
}

/// The compute pipelines and layouts, made once per context.
pub(crate) struct Pipelines {
    pub arena_bgl: wgpu::BindGroupLayout,
    pub trav_bgl: wgpu::BindGroupLayout,
    pub boxes_bgl: wgpu::BindGroupLayout,
    pub traverse: wgpu::ComputePipeline,
    /// traverse.wgsl's triangle pass (one listed triangle pair per invocation), with the exact
    /// path compiled in.
    pub triangles: wgpu::ComputePipeline,
    /// The triangle pass with the rotated path only (`EXACT_PATH = false`).
    pub triangles_rotated: wgpu::ComputePipeline,
    /// traverse.wgsl's one-pass traversal (`traverse_all`: every level and the triangle tests
    /// in one dispatch), its bindings, and its rotated-path-only form.
    pub one_pass_bgl: wgpu::BindGroupLayout,
    pub traverse_all: wgpu::ComputePipeline,
    pub traverse_all_rotated: wgpu::ComputePipeline,
    pub boxes: wgpu::ComputePipeline,
    pub sweep_bgl: wgpu::BindGroupLayout,
    /// sweep.wgsl's passes: keys, sort_local, sort_global, gather, sweep.
    pub sweep: [wgpu::ComputePipeline; 5],
}

/// A device and queue with frcd-gpgpu's pipelines, plus counters of submissions and readbacks.
///
/// `Send + Sync`; queries take `&self` and caller-owned scratch objects.
pub struct GpuContext {
    pub(crate) device: wgpu::Device,
    pub(crate) queue: wgpu::Queue,
    pub(crate) limits: wgpu::Limits,
    pub(crate) info: wgpu::AdapterInfo,
    pub(crate) pipes: Pipelines,
    pub(crate) arena: std::sync::Mutex<crate::mesh::Arena>,
    pub(crate) id: u64,
    submissions: AtomicU64,
    readbacks: AtomicU64,
    /// Batches record GPU timestamps around every pass (see [`GpuContext::enable_pass_timers`]).
    pub(crate) pass_timers: bool,
    /// Which reported pairs the CPU re-decides.
    pub(crate) recheck: Recheck,
    /// The triangle pass's exact reference-point path ([`GpuContext::set_exact_offsets`]).
    pub(crate) exact_offsets: bool,
    /// Box tests per level the CPU may take off the GPU at the top of a batch's pair trees
    /// ([`GpuContext::set_host_front`]).
    pub(crate) host_front: u32,
    /// Workgroups of the one-pass traversal, 0 for the level chain
    /// ([`GpuContext::set_one_pass`]).
    pub(crate) one_pass: u32,
    /// The one-pass traversal's loop budget per invocation ([`ONE_PASS_LOOP_BUDGET`]).
    pub(crate) one_pass_budget: u32,
    /// Last field: the GPU objects above are dropped under `frcd_gpu::creation_lock` (see the
    /// `Drop` impl).
    _release: frcd_gpu::ReleaseCreationLock,
}

/// Dropping a context releases its pipelines, arena and device handle under
/// `frcd_gpu::creation_lock`: NVIDIA's driver was seen to hang in `vkDestroyDevice` while other
/// threads created contexts.
impl Drop for GpuContext {
    fn drop(&mut self) {
        frcd_gpu::hold_creation_lock_for_drop();
    }
}

impl std::fmt::Debug for GpuContext {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuContext")
            .field("adapter", &self.info.name)
            .field("backend", &self.info.backend)
            .field("submissions", &self.submissions())
            .field("readbacks", &self.readbacks())
            .finish()
    }
}

fn unsupported(adapter: &str, what: &'static str, needed: u64, available: u64) -> GpuError {
    GpuError::Unsupported {
        adapter: adapter.to_string(),
        what,
        needed,
        available,
    }
}

/// frcd-gpu's setup errors as this crate's, with the driver's reason in the message.
fn setup_error(e: frcd_gpu::SetupError) -> GpuError {
    match e {
        frcd_gpu::SetupError::NoAdapter(source) => GpuError::NoAdapter(source.to_string()),
        frcd_gpu::SetupError::RequestDevice { adapter, source } => GpuError::RequestDevice {
            adapter,
            reason: source.to_string(),
        },
        other => GpuError::Internal(format!("GPU setup: {other}")),
    }
}

/// First limit of `have` below [`requirements`].
fn check_limits(have: &wgpu::Limits, adapter: &str) -> Result<(), GpuError> {
    let mut first: Option<GpuError> = None;
    requirements().check_limits_with_fail_fn(have, false, |what, needed, available| {
        if first.is_none() {
            first = Some(unsupported(adapter, what, needed, available));
        }
    });
    first.map_or(Ok(()), Err)
}

fn check_downlevel(caps: &wgpu::DownlevelCapabilities, adapter: &str) -> Result<(), GpuError> {
    for (flag, name) in [
        (
            wgpu::DownlevelFlags::COMPUTE_SHADERS,
            "downlevel flag COMPUTE_SHADERS",
        ),
        (
            wgpu::DownlevelFlags::INDIRECT_EXECUTION,
            "downlevel flag INDIRECT_EXECUTION",
        ),
    ] {
        if !caps.flags.contains(flag) {
            return Err(unsupported(adapter, name, 1, 0));
        }
    }
    Ok(())
}

impl GpuContext {
    /// A context on a new device of the best adapter (honours `WGPU_BACKEND`,
    /// `WGPU_ADAPTER_NAME`, `WGPU_POWER_PREF`). Asks for every limit the adapter offers, so the
    /// largest meshes fit.
    pub fn headless() -> Result<Self, GpuError> {
        Self::headless_with(&HeadlessOptions::default())
    }

    /// [`GpuContext::headless`] with options.
    pub fn headless_with(options: &HeadlessOptions) -> Result<Self, GpuError> {
        // Under the creation lock throughout: the adapter (and the wgpu instance it may hold
        // last, when the device is refused) is dropped before the lock is released.
        frcd_gpu::with_creation_lock((), |()| Self::headless_locked(options))
    }

    fn headless_locked(options: &HeadlessOptions) -> Result<Self, GpuError> {
        // Adapter and device through the shared setup of frcd-gpu.
        // Every indirect dispatch here takes arguments computed within
        // the device's limits (`QueryScratch::ensure` bounds the capacities, and a batch needing
        // more gets a typed `CapacityExceeded`), and the
        // shaders derive their grid from the counts, not `num_workgroups`: wgpu's validation of
        // them (a dispatch and a barrier per traversal level) is skipped.
        let adapter = frcd_gpu::request_adapter(&frcd_gpu::AdapterOptions {
            backends: options.backends,
            low_power: options.low_power,
            force_fallback_adapter: options.force_fallback_adapter,
            skip_indirect_validation: true,
        })
        .map_err(setup_error)?;
        let info = adapter.get_info();
        check_downlevel(&adapter.get_downlevel_capabilities(), &info.name)?;
        let limits = adapter.limits();
        check_limits(&limits, &info.name)?;
        let features = if options.pass_timers {
            adapter.features() & PASS_TIMER_FEATURES
        } else {
            wgpu::Features::empty()
        };
        let (device, queue) = frcd_gpu::request_device(&adapter, "frcd-gpgpu", features, limits)
            .map_err(setup_error)?;
        log::info!(
            "frcd-gpgpu: adapter '{}' ({:?}, {:?})",
            info.name,
            info.backend,
            info.device_type
        );
        let mut ctx = Self::from_device_with(device, queue, &options.arena)?;
        if options.pass_timers {
            ctx.enable_pass_timers();
        }
        ctx.recheck = options.recheck;
        Ok(ctx)
    }

    /// A context on the caller's device and queue (an engine's own). The device's limits are
    /// checked against [`requirements`]; the downlevel flags cannot be read from a device, use
    /// [`GpuContext::from_adapter`] to check them too. No wgpu backend is forced: the engine
    /// chooses the backends it compiles in (frcd-gpgpu enables none of wgpu's backend
    /// features itself).
    pub fn from_device(device: wgpu::Device, queue: wgpu::Queue) -> Result<Self, GpuError> {
        Self::from_device_with(device, queue, &crate::ArenaOptions::default())
    }

    /// [`GpuContext::from_device`] with the shape of the mesh arena.
    pub fn from_device_with(
        device: wgpu::Device,
        queue: wgpu::Queue,
        arena: &crate::ArenaOptions,
    ) -> Result<Self, GpuError> {
        // Under the creation lock from the first check on, so a refused device (and the
        // instance it may hold the last reference to) is released under it as well.
        frcd_gpu::with_creation_lock((device, queue), |(device, queue)| {
            Self::from_device_locked(device, queue, arena)
        })
    }

    fn from_device_locked(
        device: wgpu::Device,
        queue: wgpu::Queue,
        arena: &crate::ArenaOptions,
    ) -> Result<Self, GpuError> {
        let info = device.adapter_info();
        let exact_offsets = exact_offsets_default(&info);
        let one_pass = one_pass_default(&info);
        let host_front = if info.device_type == wgpu::DeviceType::Cpu {
            HOST_FRONT_SOFTWARE
        } else {
            0
        };
        let limits = device.limits();
        // One dispatch of G workgroups: at most the device's workgroups per dimension.
        let one_pass = one_pass.min(limits.max_compute_workgroups_per_dimension);
        check_limits(&limits, &info.name)?;
        // A driver that rejects a shader or pipeline gives a typed error, not a panic.
        let creating = frcd_gpu::creation_lock();
        // All three filters: a driver that fails to compile a pipeline reports an internal
        // error, not a validation one (NVIDIA's GL through EGL on an H200, once wgpu's own
        // indirect-validation pipelines no longer failed the device first).
        let validation = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let internal = device.push_error_scope(wgpu::ErrorFilter::Internal);
        let oom = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let pipes = Pipelines::new(&device, shader_variant());
        let arena = crate::mesh::Arena::new(&device, &pipes.arena_bgl, &limits, arena);
        let oom = pollster::block_on(oom.pop());
        let internal = pollster::block_on(internal.pop());
        let failed = oom.or(internal).or(pollster::block_on(validation.pop()));
        drop(creating);
        if let Some(e) = failed {
            // Display of a wgpu error is only its kind; the description names the cause.
            let reason = frcd_gpu::describe(&e);
            return Err(GpuError::Pipeline {
                adapter: info.name.clone(),
                reason,
            });
        }
        let arena = arena.map_err(|e| match e {
            GpuError::Unsupported {
                what,
                needed,
                available,
                ..
            } => unsupported(&info.name, what, needed, available),
            e => e,
        })?;
        Ok(Self {
            device,
            queue,
            limits,
            info,
            pipes,
            arena: std::sync::Mutex::new(arena),
            id: NEXT_CONTEXT_ID.fetch_add(1, Ordering::Relaxed),
            submissions: AtomicU64::new(0),
            readbacks: AtomicU64::new(0),
            pass_timers: false,
            recheck: Recheck::All,
            exact_offsets,
            host_front,
            one_pass,
            one_pass_budget: ONE_PASS_LOOP_BUDGET,
            _release: frcd_gpu::ReleaseCreationLock::default(),
        })
    }

    /// [`GpuContext::from_device`], also checking the adapter's downlevel capabilities.
    pub fn from_adapter(
        adapter: &wgpu::Adapter,
        device: wgpu::Device,
        queue: wgpu::Queue,
    ) -> Result<Self, GpuError> {
        frcd_gpu::with_creation_lock((device, queue), |(device, queue)| {
            check_downlevel(
                &adapter.get_downlevel_capabilities(),
                &adapter.get_info().name,
            )?;
            Self::from_device(device, queue)
        })
    }

    /// The device.
    pub fn device(&self) -> &wgpu::Device {
        &self.device
    }

    /// The queue.
    pub fn queue(&self) -> &wgpu::Queue {
        &self.queue
    }

    /// The adapter's description (name, backend, device type).
    pub fn adapter_info(&self) -> &wgpu::AdapterInfo {
        &self.info
    }

    /// The device's limits, as used for texture splitting and buffer capacities.
    pub fn limits(&self) -> &wgpu::Limits {
        &self.limits
    }

    /// Turns on GPU pass timers ([`crate::BatchTimings`]'s `gpu_*` fields) when the device was
    /// created with [`wgpu::Features::TIMESTAMP_QUERY`] and
    /// [`wgpu::Features::TIMESTAMP_QUERY_INSIDE_PASSES`]; returns whether they are on. Each
    /// batch then writes a timestamp before and after every pass and reads them back with its
    /// answer (a few hundred bytes).
    pub fn enable_pass_timers(&mut self) -> bool {
        self.pass_timers = self.device.features().contains(PASS_TIMER_FEATURES);
        self.pass_timers
    }

    /// Sets which reported triangle pairs the CPU re-decides ([`Recheck::All`] by default).
    pub fn set_recheck(&mut self, recheck: Recheck) {
        self.recheck = recheck;
    }

    /// Which reported triangle pairs the CPU re-decides.
    pub fn recheck(&self) -> Recheck {
        self.recheck
    }

    /// Turns the triangle pass's exact reference-point path on or off (default: on for hardware
    /// adapters, off for software ones such as lavapipe, where it costs more than it saves;
    /// [`EXACT_OFFSETS_ENV`] overrides the default). On, each
    /// body pair whose integer ranges hold computes `W = R c_B + t - c_A` (the triangles'
    /// reference points, see `pack`'s module docs) exactly in integer arithmetic and rotates
    /// only the small vertex offsets in f32, so its error bound scales with the triangles, not
    /// the meshes: far fewer uncertain pairs. Off (or where the ranges cannot hold), every pair
    /// takes the rotated path (B's vertices rotated into A's frame in f32).
    /// [`crate::GpuCollision::exact_offsets`] says which path a pair took. Answers are the same
    /// either way (the exact CPU oracle's). Each path has its own triangle pipeline (the integer
    /// work is compiled out of the rotated one).
    pub fn set_exact_offsets(&mut self, on: bool) {
        self.exact_offsets = on;
    }

    /// Whether the exact reference-point path is on ([`GpuContext::set_exact_offsets`]).
    pub fn exact_offsets(&self) -> bool {
        self.exact_offsets
    }

    /// Sets how much of the top of a batch's pair trees the CPU descends before the GPU
    /// starts: level by level, while a level's box tests over the whole batch stay within
    /// `tests` (0: none, the GPU starts at the roots). Each level taken off the GPU is one
    /// dispatch fewer; the answers are the same. Default: [`HOST_FRONT_SOFTWARE`] on software
    /// adapters such as lavapipe, where a level costs a dispatch's fixed 100-200 µs whatever
    /// its size; 0 on hardware adapters, where no figure says it pays (not measured yet).
    /// [`crate::BatchTimings::host_front`] is the time it takes.
    ///
    /// Set it before uploading: a mesh uploaded while the front is on keeps a copy of its tree
    /// on the host (about `frcd_obb::ObbTree::memory_bytes`), one uploaded while it is off
    /// keeps none, and its pairs start at their roots whatever the setting.
    pub fn set_host_front(&mut self, tests: u32) {
        self.host_front = tests;
    }

    /// Sets how a batch's traversal runs: `0`, one dispatch per level of the pair trees (the
    /// level chain: every level spread over the whole GPU); `n > 0`, one dispatch of `n`
    /// workgroups that each descend their share of the batch level by level and test their
    /// own triangle pairs (`traverse_all` in traverse.wgsl). The answers are the same. One pass
    /// is for drivers where a dispatch costs more than a level's work: a software driver such
    /// as lavapipe, where each level cost 100-200 µs before it did any work; on hardware it
    /// would leave most of the GPU idle. Default: one workgroup per thread of a software
    /// adapter (see [`ONE_PASS_SOFTWARE_MAX`]), 0 on hardware ones ([`ONE_PASS_ENV`] overrides
    /// both). Held at the device's `max_compute_workgroups_per_dimension`.
    ///
    /// ```no_run
    /// # fn main() -> Result<(), frcd_gpgpu::GpuError> {
    /// let mut ctx = frcd_gpgpu::GpuContext::headless()?;
    /// ctx.set_one_pass(0); // one dispatch per level, as on a hardware adapter
    /// assert_eq!(ctx.one_pass(), 0);
    /// # Ok(())
    /// # }
    /// ```
    pub fn set_one_pass(&mut self, workgroups: u32) {
        // One dispatch of `workgroups` along x: more than the device allows per dimension would
        // be a validation error at the dispatch, so it is held at the limit.
        self.one_pass = workgroups.min(self.limits.max_compute_workgroups_per_dimension);
    }

    /// Workgroups of the one-pass traversal, 0 for the level chain
    /// ([`GpuContext::set_one_pass`]).
    pub fn one_pass(&self) -> u32 {
        self.one_pass
    }

    /// Sets the one-pass traversal's loop budget per invocation (default and most
    /// [`ONE_PASS_LOOP_BUDGET`]: at most that is safe on llvmpipe, and it bounds a workgroup's
    /// list below 2^31 entries, see traverse.wgsl). For tests of the fallback to the level
    /// chain.
    #[doc(hidden)]
    pub fn set_one_pass_loop_budget(&mut self, iterations: u32) {
        self.one_pass_budget = iterations.min(ONE_PASS_LOOP_BUDGET);
    }

    /// The CPU's share of the top of the pair trees ([`GpuContext::set_host_front`]).
    pub fn host_front(&self) -> u32 {
        self.host_front
    }

    /// Whether batches time their GPU passes ([`GpuContext::enable_pass_timers`]).
    pub fn has_pass_timers(&self) -> bool {
        self.pass_timers
    }

    /// True when the adapter is a software rasterizer (lavapipe, llvmpipe, WARP).
    pub fn is_software(&self) -> bool {
        self.info.device_type == wgpu::DeviceType::Cpu
    }

    /// Command-buffer submissions made by this context so far (a query makes one, plus one per
    /// overflow re-run).
    pub fn submissions(&self) -> u64 {
        self.submissions.load(Ordering::Relaxed)
    }

    /// Buffer readbacks (maps for reading) made by this context so far (one per submission).
    pub fn readbacks(&self) -> u64 {
        self.readbacks.load(Ordering::Relaxed)
    }

    /// Submits one command buffer (counted); returns its index, the only thing a readback waits
    /// for.
    pub(crate) fn submit(&self, cmd: wgpu::CommandBuffer) -> wgpu::SubmissionIndex {
        self.submissions.fetch_add(1, Ordering::Relaxed);
        self.queue.submit([cmd])
    }

    /// Maps `staging[..len]` for reading, waits for submission `index` only (not for other work
    /// on the device, e.g. an engine's frame), and returns a copy of the bytes (counted).
    pub(crate) fn read_back(
        &self,
        staging: &wgpu::Buffer,
        len: u64,
        index: wgpu::SubmissionIndex,
    ) -> Result<Vec<u8>, GpuError> {
        self.readbacks.fetch_add(1, Ordering::Relaxed);
        frcd_gpu::read_back(&self.device, staging, len, index).map_err(GpuError::Readback)
    }

    /// [`GpuContext::read_back`] without the copy: `read` gets the mapped bytes in place.
    pub(crate) fn read_back_with<R>(
        &self,
        staging: &wgpu::Buffer,
        len: u64,
        index: wgpu::SubmissionIndex,
        read: impl FnOnce(&[u8]) -> R,
    ) -> Result<R, GpuError> {
        self.readbacks.fetch_add(1, Ordering::Relaxed);
        frcd_gpu::read_back_with(&self.device, staging, len, index, read)
            .map_err(GpuError::Readback)
    }

    /// Largest byte size of one storage buffer binding.
    pub(crate) fn max_storage_bytes(&self) -> u64 {
        self.limits
            .max_storage_buffer_binding_size
            .min(self.limits.max_buffer_size)
    }

    /// Checks that every named storage buffer fits the device's binding limit.
    pub(crate) fn check_storage(&self, sizes: &[(&'static str, u64)]) -> Result<(), GpuError> {
        let limit = self.max_storage_bytes();
        match sizes.iter().find(|(_, bytes)| *bytes > limit) {
            Some(&(what, needed)) => Err(GpuError::CapacityExceeded {
                what,
                needed,
                limit,
            }),
            None => Ok(()),
        }
    }

    /// An unmapped buffer.
    pub(crate) fn buffer(&self, label: &str, size: u64, usage: wgpu::BufferUsages) -> wgpu::Buffer {
        self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size,
            usage,
            mapped_at_creation: false,
        })
    }
}

/// A whole-buffer bind group entry.
pub(crate) fn entry(binding: u32, b: &wgpu::Buffer) -> wgpu::BindGroupEntry<'_> {
    wgpu::BindGroupEntry {
        binding,
        resource: b.as_entire_binding(),
    }
}

fn storage(binding: u32, read_only: bool) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

fn uniform(binding: u32) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

/// The pairs' poses: a 2D rgba32uint texture (`query::POSE_TEXELS` texels a pair).
fn pose_texture(binding: u32) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Uint,
            view_dimension: wgpu::TextureViewDimension::D2,
            multisampled: false,
        },
        count: None,
    }
}

fn texture(binding: u32, sample_type: wgpu::TextureSampleType) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Texture {
            sample_type,
            view_dimension: wgpu::TextureViewDimension::D2Array,
            multisampled: false,
        },
        count: None,
    }
}

impl Pipelines {
    /// `variant`: `traverse.wgsl`'s `VARIANT` ([`SHADER_VARIANT_ENV`]).
    fn new(device: &wgpu::Device, variant: u32) -> Self {
        let bgl = |label: &str, entries: &[wgpu::BindGroupLayoutEntry]| {
            device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some(label),
                entries,
            })
        };
        let arena_bgl = bgl(
            "frcd-gpgpu mesh arena",
            &[
                // Nodes (f32 bits and links), triangles.
                texture(0, wgpu::TextureSampleType::Uint),
                texture(1, wgpu::TextureSampleType::Float { filterable: false }),
                uniform(2),
            ],
        );
        let trav_bgl = bgl(
            "frcd-gpgpu traversal buffers",
            &[
                storage(0, true),
                storage(1, false),
                storage(2, false),
                storage(3, false),
                uniform(4),
                storage(5, true),
                storage(6, false),
                storage(7, false),
                uniform(8),
                // The pairs' poses as rgba32uint texels (`query::POSE_TEXELS`).
                pose_texture(9),
            ],
        );
        // The one-pass traversal: the first level's entries, the state, the triangle list, the
        // params, the pair table, the poses, the two frontier halves and the output.
        let one_pass_bgl = bgl(
            "frcd-gpgpu one-pass traversal buffers",
            &[
                storage(0, true),
                storage(2, false),
                storage(3, false),
                uniform(4),
                storage(5, true),
                pose_texture(9),
                storage(10, false),
                storage(11, false),
            ],
        );
        let boxes_bgl = bgl(
            "frcd-gpgpu boxes",
            &[
                storage(0, true),
                storage(1, false),
                storage(2, false),
                uniform(3),
            ],
        );
        let sweep_bgl = bgl(
            "frcd-gpgpu sweep",
            &[
                storage(0, true),
                storage(1, false),
                storage(2, false),
                uniform(3),
                storage(4, false),
                storage(5, false),
                wgpu::BindGroupLayoutEntry {
                    binding: 6,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: true,
                        min_binding_size: std::num::NonZeroU64::new(16),
                    },
                    count: None,
                },
            ],
        );
        let module = |label: &str, src: &str| {
            device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(label),
                source: wgpu::ShaderSource::Wgsl(frcd_gpu::with_prelude(src).into()),
            })
        };
        let traverse_mod = module("traverse.wgsl", shaders::TRAVERSE);
        let boxes_mod = module("boxes.wgsl", shaders::BOXES);
        let sweep_mod = module("sweep.wgsl", shaders::SWEEP);
        let layout = |label: &str, groups: &[&wgpu::BindGroupLayout]| {
            let groups: Vec<Option<&wgpu::BindGroupLayout>> =
                groups.iter().map(|g| Some(*g)).collect();
            device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some(label),
                bind_group_layouts: &groups,
                immediate_size: 0,
            })
        };
        let trav_layout = layout("frcd-gpgpu traverse", &[&arena_bgl, &trav_bgl]);
        let one_pass_layout = layout(
            "frcd-gpgpu one-pass traversal",
            &[&arena_bgl, &one_pass_bgl],
        );
        let boxes_layout = layout("frcd-gpgpu boxes", &[&boxes_bgl]);
        let sweep_layout = layout("frcd-gpgpu sweep", &[&sweep_bgl]);
        let specialized = |label: &str,
                           layout: &wgpu::PipelineLayout,
                           module: &wgpu::ShaderModule,
                           entry: &str,
                           constants: &[(&str, f64)]| {
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(label),
                layout: Some(layout),
                module,
                entry_point: Some(entry),
                compilation_options: wgpu::PipelineCompilationOptions {
                    constants,
                    ..Default::default()
                },
                cache: None,
            })
        };
        let pipeline =
            |label: &str,
             layout: &wgpu::PipelineLayout,
             module: &wgpu::ShaderModule,
             entry: &str| specialized(label, layout, module, entry, &[]);
        // traverse.wgsl's pipelines take the measurement hook's variant (0 unless asked).
        let v = f64::from(variant);
        Self {
            traverse: specialized(
                "frcd-gpgpu traverse",
                &trav_layout,
                &traverse_mod,
                "traverse",
                &[("VARIANT", v)],
            ),
            triangles: specialized(
                "frcd-gpgpu triangles",
                &trav_layout,
                &traverse_mod,
                "triangles",
                &[("VARIANT", v)],
            ),
            triangles_rotated: specialized(
                "frcd-gpgpu triangles (rotated path)",
                &trav_layout,
                &traverse_mod,
                "triangles",
                &[("EXACT_PATH", 0.0), ("VARIANT", v)],
            ),
            traverse_all: specialized(
                "frcd-gpgpu one-pass traversal",
                &one_pass_layout,
                &traverse_mod,
                "traverse_all",
                &[("VARIANT", v)],
            ),
            traverse_all_rotated: specialized(
                "frcd-gpgpu one-pass traversal (rotated path)",
                &one_pass_layout,
                &traverse_mod,
                "traverse_all",
                &[("EXACT_PATH", 0.0), ("VARIANT", v)],
            ),
            one_pass_bgl,
            boxes: pipeline("frcd-gpgpu boxes", &boxes_layout, &boxes_mod, "overlap"),
            sweep: ["make_keys", "sort_local", "sort_global", "gather", "sweep"]
                .map(|entry| pipeline("frcd-gpgpu sweep", &sweep_layout, &sweep_mod, entry)),
            sweep_bgl,
            arena_bgl,
            trav_bgl,
            boxes_bgl,
        }
    }
}
