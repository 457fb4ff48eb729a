#![doc = include_str!("../README.md")]
#![warn(missing_docs)]
#![forbid(unsafe_code)]

pub mod layout;

/// The WGSL prelude prepended to every frcd shader (see [`with_prelude`]).
pub const PRELUDE: &str = include_str!("../shaders/prelude.wgsl");

/// `source` with the [`PRELUDE`] in front: the text a pipeline is created from.
pub fn with_prelude(source: &str) -> String {
    format!("{PRELUDE}\n{source}")
}

/// Holds the creation (and, through [`hold_creation_lock_for_drop`], the destruction) of GPU
/// objects in this process to one thread at a time; hold the guard while creating an instance,
/// adapter, device or pipelines. Re-entrant: a thread that already holds it gets a guard that
/// does nothing (so a device dropped inside a creation path cannot deadlock).
///
/// NVIDIA's Vulkan driver can hang when several threads create and drop devices at once: on an
/// H200 (driver 580.159), test binaries run on two threads, each test with its own context,
/// stopped in 4 runs of 5 with the GPU idle and every thread in a futex wait (one backtrace:
/// a thread in `vkDestroyDevice`); one thread at a time never hung. With creation under this
/// lock, 0 of 6 such runs hung (1 of 3 at 16 threads still did, before drops were covered;
/// 2 of 13 at 2 threads, before refused devices were dropped under it too, see
/// [`with_creation_lock`]; then 0 of 28).
/// wgpu issues 10010 and 10234 report crashes from the same pattern. frcd's GPU crates take
/// this lock in every constructor and while their contexts are dropped; both are rare, so it
/// costs nothing per frame. An engine creating or dropping its own devices or pipelines on
/// other threads may take it as well.
///
/// ```
/// let _guard = frcd_gpu::creation_lock();
/// // ... create the instance, device and pipelines ...
/// let _again = frcd_gpu::creation_lock(); // the same thread: no deadlock
/// ```
pub fn creation_lock() -> CreationGuard {
    static LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());
    if HELD.with(std::cell::Cell::get) {
        return CreationGuard { guard: None };
    }
    // A panic while holding it leaves nothing half-made that the next creator depends on.
    let guard = LOCK.lock().unwrap_or_else(|e| e.into_inner());
    HELD.with(|h| h.set(true));
    CreationGuard { guard: Some(guard) }
}

thread_local! {
    /// Whether this thread holds [`creation_lock`].
    static HELD: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
    /// Guards taken by [`hold_creation_lock_for_drop`], released by [`ReleaseCreationLock`].
    static HELD_FOR_DROP: std::cell::RefCell<Vec<CreationGuard>> =
        const { std::cell::RefCell::new(Vec::new()) };
}

/// The guard of [`creation_lock`]: the lock is released when the outermost guard of the thread
/// is dropped.
#[derive(Debug)]
#[must_use = "the lock is released when the guard is dropped"]
pub struct CreationGuard {
    guard: Option<std::sync::MutexGuard<'static, ()>>,
}

impl Drop for CreationGuard {
    fn drop(&mut self) {
        if self.guard.take().is_some() {
            HELD.with(|h| h.set(false));
        }
    }
}

/// Whether the calling thread holds [`creation_lock`].
pub fn creation_lock_held() -> bool {
    HELD.with(std::cell::Cell::get)
}

/// Runs `make` on `inputs` with [`creation_lock`] held throughout, so that whatever `make` does
/// not keep is dropped under the lock too: a constructor that takes a caller's device and refuses
/// it drops the device (and with its last reference the wgpu instance) inside `make`, before the
/// lock is released. Checking a device *before* taking the lock and returning early dropped it
/// outside: on an H200 that deadlocked in NVIDIA's driver against another thread's
/// `vkDestroyDevice` (2 test runs in 13; backtraces in `docs/performance/gpu.md`).
///
/// ```
/// let refused: Result<(), &str> =
///     frcd_gpu::with_creation_lock(vec![1u8; 4], |_device| Err("limits too small"));
/// assert!(refused.is_err() && !frcd_gpu::creation_lock_held());
/// ```
pub fn with_creation_lock<I, R>(inputs: I, make: impl FnOnce(I) -> R) -> R {
    let _creating = creation_lock();
    make(inputs)
}

/// Takes [`creation_lock`] for the rest of a value's drop. Call it first thing in the value's
/// `Drop::drop` and make a [`ReleaseCreationLock`] the value's **last** field: Rust drops the
/// fields after `drop` returns, in declaration order, so every GPU object before the marker is
/// released under the lock, the device too when the value held its last reference (wgpu
/// destroys a device with its last object).
pub fn hold_creation_lock_for_drop() {
    let guard = creation_lock();
    // During thread-local destruction (a context kept in a thread_local) the stash may be gone:
    // then the guard is dropped here and the fields drop without the lock.
    let _ = HELD_FOR_DROP.try_with(|held| held.borrow_mut().push(guard));
}

/// The last field of a value whose `Drop` calls [`hold_creation_lock_for_drop`]: releases that
/// lock once the fields before it are gone.
#[derive(Clone, Debug, Default)]
pub struct ReleaseCreationLock(());

impl Drop for ReleaseCreationLock {
    fn drop(&mut self) {
        let guard = HELD_FOR_DROP.try_with(|held| held.borrow_mut().pop());
        drop(guard);
    }
}

/// Setup and readback failures. Every variant keeps the typed wgpu cause as its source.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SetupError {
    /// No adapter (GPU or software driver) could be found.
    #[error("no GPU adapter found")]
    NoAdapter(#[source] wgpu::RequestAdapterError),
    /// The adapter refused to create a device.
    #[error("could not create a device on adapter '{adapter}'")]
    RequestDevice {
        /// Adapter name.
        adapter: String,
        /// The driver's reason.
        #[source]
        source: wgpu::RequestDeviceError,
    },
    /// Waiting for a submission failed (device lost, timeout).
    #[error("waiting for the GPU failed")]
    Poll(#[source] wgpu::PollError),
    /// Mapping a buffer for reading failed.
    #[error("mapping a GPU buffer for reading failed")]
    Map(#[source] wgpu::BufferAsyncError),
    /// The map callback was dropped without an answer.
    #[error("the GPU buffer map callback never ran")]
    MapDropped,
    /// The mapped range could not be read.
    #[error("reading the mapped GPU buffer failed")]
    MapRange(#[source] wgpu::MapRangeError),
}

/// Options of [`request_adapter`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct AdapterOptions {
    /// Restrict the instance to these backends; `None`: every backend compiled in, narrowed by
    /// `WGPU_BACKEND` (and `WGPU_ADAPTER_NAME` is honoured).
    pub backends: Option<wgpu::Backends>,
    /// Prefer an integrated / low-power adapter.
    pub low_power: bool,
    /// Ask for the fallback (software) adapter only.
    pub force_fallback_adapter: bool,
    /// Make the instance without wgpu's validation of indirect dispatch and draw arguments
    /// (`wgpu::InstanceFlags::VALIDATION_INDIRECT_CALL`), unless `WGPU_VALIDATION_INDIRECT_CALL`
    /// is set. wgpu validates each indirect call with an extra compute dispatch and barrier
    /// (about 10 µs per call on an H200); without it an out-of-limit argument is undefined
    /// behaviour, and on D3D12 `@builtin(num_workgroups)` reads 0. Only for callers whose every
    /// indirect call computes its arguments within the device's limits and whose shaders do not
    /// read `num_workgroups` (frcd-gpgpu's).
    pub skip_indirect_validation: bool,
}

/// A headless adapter (no surface).
pub fn request_adapter(options: &AdapterOptions) -> Result<wgpu::Adapter, SetupError> {
    let mut desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
    if let Some(b) = options.backends {
        desc.backends = b;
    }
    if options.skip_indirect_validation
        && std::env::var_os("WGPU_VALIDATION_INDIRECT_CALL").is_none()
    {
        desc.flags
            .remove(wgpu::InstanceFlags::VALIDATION_INDIRECT_CALL);
    }
    let from_env =
        options.backends.is_none() && !options.low_power && !options.force_fallback_adapter;
    pick_adapter(desc, from_env, options)
}

/// A headless adapter on an instance the caller describes (its backends, flags, ...), for
/// crates whose API takes a `wgpu::InstanceDescriptor`; `options.backends` is not read (set
/// `desc.backends`). With `low_power` and `force_fallback_adapter` unset, the first adapter
/// whose name contains `WGPU_ADAPTER_NAME` when that is set, else wgpu's choice for
/// `WGPU_POWER_PREF` (no preference when unset), as [`request_adapter`] with default options.
///
/// ```
/// let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
/// desc.backends = wgpu::Backends::empty();
/// let none = frcd_gpu::request_adapter_on(desc, &frcd_gpu::AdapterOptions::default());
/// assert!(matches!(none, Err(frcd_gpu::SetupError::NoAdapter(_))));
/// ```
pub fn request_adapter_on(
    desc: wgpu::InstanceDescriptor,
    options: &AdapterOptions,
) -> Result<wgpu::Adapter, SetupError> {
    let from_env = !options.low_power && !options.force_fallback_adapter;
    pick_adapter(desc, from_env, options)
}

/// The adapter of a new instance `desc`: by the wgpu environment variables (`from_env`), else by
/// `options`' power preference and fallback flag.
fn pick_adapter(
    desc: wgpu::InstanceDescriptor,
    from_env: bool,
    options: &AdapterOptions,
) -> Result<wgpu::Adapter, SetupError> {
    let _creating = creation_lock();
    let instance = wgpu::Instance::new(desc);
    if from_env {
        return pollster::block_on(wgpu::util::initialize_adapter_from_env_or_default(
            &instance, None,
        ))
        .map_err(SetupError::NoAdapter);
    }
    pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
        power_preference: if options.low_power {
            wgpu::PowerPreference::LowPower
        } else {
            wgpu::PowerPreference::HighPerformance
        },
        force_fallback_adapter: options.force_fallback_adapter,
        compatible_surface: None,
        ..Default::default()
    }))
    .map_err(SetupError::NoAdapter)
}

/// A device and queue on `adapter` with exactly `features` and `limits`.
pub fn request_device(
    adapter: &wgpu::Adapter,
    label: &str,
    features: wgpu::Features,
    limits: wgpu::Limits,
) -> Result<(wgpu::Device, wgpu::Queue), SetupError> {
    let _creating = creation_lock();
    pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        label: Some(label),
        required_features: features,
        required_limits: limits,
        ..Default::default()
    }))
    .map_err(|source| SetupError::RequestDevice {
        adapter: adapter.get_info().name,
        source,
    })
}

/// The driver's full description of a wgpu error (its `Display` is only the kind).
pub fn describe(e: &wgpu::Error) -> String {
    match e {
        wgpu::Error::Validation { description, .. } | wgpu::Error::Internal { description, .. } => {
            description.clone()
        }
        other => other.to_string(),
    }
}

/// Maps `buffer[..len]` for reading once submission `index` has finished, waiting for that
/// submission only (not for other work queued on the device, e.g. an engine's frame), and
/// returns a copy of the bytes.
pub fn read_back(
    device: &wgpu::Device,
    buffer: &wgpu::Buffer,
    len: u64,
    index: wgpu::SubmissionIndex,
) -> Result<Vec<u8>, SetupError> {
    read_back_with(device, buffer, len, index, <[u8]>::to_vec)
}

/// [`read_back`] without the copy: `read` is given the mapped bytes in place (the readback
/// buffer's host memory) and its answer is returned; the buffer is unmapped afterwards. For
/// large readbacks (an image-space query's 32 MB at 2,048² pixels) that are converted anyway.
pub fn read_back_with<R>(
    device: &wgpu::Device,
    buffer: &wgpu::Buffer,
    len: u64,
    index: wgpu::SubmissionIndex,
    read: impl FnOnce(&[u8]) -> R,
) -> Result<R, SetupError> {
    let slice = buffer.slice(..len);
    let (tx, rx) = std::sync::mpsc::channel();
    slice.map_async(wgpu::MapMode::Read, move |r| {
        let _ = tx.send(r);
    });
    device
        .poll(wgpu::PollType::Wait {
            submission_index: Some(index),
            timeout: None,
        })
        .map_err(SetupError::Poll)?;
    // The callback normally ran inside that poll; if another thread's poll holds it, poll
    // without waiting until it has run.
    let mapped = loop {
        match rx.try_recv() {
            Ok(r) => break r,
            Err(std::sync::mpsc::TryRecvError::Empty) => {
                device
                    .poll(wgpu::PollType::Poll)
                    .map_err(SetupError::Poll)?;
                std::thread::yield_now();
            }
            Err(std::sync::mpsc::TryRecvError::Disconnected) => {
                return Err(SetupError::MapDropped);
            }
        }
    };
    mapped.map_err(SetupError::Map)?;
    let answer = read(&slice.get_mapped_range().map_err(SetupError::MapRange)?);
    buffer.unmap();
    Ok(answer)
}

#[cfg(test)]
mod lock_tests {
    use super::*;
    use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

    /// Records whether the creation lock was held when it was dropped.
    struct DropProbe(std::rc::Rc<std::cell::Cell<Option<bool>>>);

    impl Drop for DropProbe {
        fn drop(&mut self) {
            self.0.set(Some(creation_lock_held()));
        }
    }

    #[test]
    fn inputs_a_constructor_refuses_are_dropped_under_the_lock() {
        let seen = std::rc::Rc::new(std::cell::Cell::new(None));
        assert!(!creation_lock_held());
        let refused: Result<(), &str> =
            with_creation_lock(DropProbe(seen.clone()), |_probe| Err("refused"));
        assert!(refused.is_err());
        assert_eq!(seen.get(), Some(true), "dropped without the lock");
        assert!(!creation_lock_held(), "the lock outlived the call");
        // What the constructor keeps is not dropped; the old pattern (check, early return,
        // then lock) drops outside the lock, which this probe also sees.
        let kept = with_creation_lock(DropProbe(seen.clone()), Some);
        seen.set(None);
        drop(kept);
        assert_eq!(seen.get(), Some(false));
    }

    static HELD_DURING_FIELD_DROP: AtomicBool = AtomicBool::new(false);

    /// Records whether this thread held the lock when it was dropped.
    struct Probe;
    impl Drop for Probe {
        fn drop(&mut self) {
            HELD_DURING_FIELD_DROP.store(HELD.with(std::cell::Cell::get), Ordering::SeqCst);
        }
    }

    struct Owner {
        _probe: Probe,
        _release: ReleaseCreationLock,
    }
    impl Drop for Owner {
        fn drop(&mut self) {
            hold_creation_lock_for_drop();
        }
    }

    /// The fields before the marker drop under the lock; the lock is free afterwards, also when
    /// the owner is dropped while the thread already holds the lock (re-entrant, no deadlock).
    #[test]
    fn fields_drop_under_the_lock_and_it_is_released_after() {
        drop(Owner {
            _probe: Probe,
            _release: ReleaseCreationLock::default(),
        });
        assert!(HELD_DURING_FIELD_DROP.load(Ordering::SeqCst));
        assert!(!HELD.with(std::cell::Cell::get), "released after the drop");
        {
            let _outer = creation_lock();
            drop(Owner {
                _probe: Probe,
                _release: ReleaseCreationLock::default(),
            });
            assert!(
                HELD.with(std::cell::Cell::get),
                "the outer guard still holds it"
            );
        }
        assert!(!HELD.with(std::cell::Cell::get));
    }

    /// One thread at a time inside the lock, across threads.
    #[test]
    fn threads_take_turns() {
        static INSIDE: AtomicUsize = AtomicUsize::new(0);
        static MAX: AtomicUsize = AtomicUsize::new(0);
        let threads: Vec<_> = (0..4)
            .map(|_| {
                std::thread::spawn(|| {
                    for _ in 0..50 {
                        let _g = creation_lock();
                        let now = INSIDE.fetch_add(1, Ordering::SeqCst) + 1;
                        MAX.fetch_max(now, Ordering::SeqCst);
                        std::thread::yield_now();
                        INSIDE.fetch_sub(1, Ordering::SeqCst);
                    }
                })
            })
            .collect();
        for t in threads {
            t.join().expect("no panic");
        }
        assert_eq!(MAX.load(Ordering::SeqCst), 1);
    }
}
