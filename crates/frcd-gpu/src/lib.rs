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

/// Holds the creation of GPU objects in this process to one thread at a time; hold the guard
/// while creating an instance, adapter, device or pipelines.
///
/// NVIDIA's Vulkan driver can hang when several threads create and drop devices at once: on an
/// H200 (driver 580.159), test binaries run on two threads, each test with its own context,
/// stopped in 4 runs of 5 with the GPU idle and every thread in a futex wait (one backtrace:
/// a thread in `vkDestroyDevice`); one thread at a time never hung. With creation under this
/// lock, 0 of 6 such runs hung (1 of 3 at 16 threads still did: dropping is not covered).
/// wgpu issues 10010 and 10234 report crashes from the same pattern. frcd's GPU crates take
/// this lock in every constructor; creation is rare, so it costs nothing per frame. An engine
/// creating its own devices or pipelines on other threads may take it as well.
///
/// ```
/// let _guard = frcd_gpu::creation_lock();
/// // ... create the instance, device and pipelines ...
/// ```
pub fn creation_lock() -> std::sync::MutexGuard<'static, ()> {
    static LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());
    // A panic while holding it leaves nothing half-made that the next creator depends on.
    LOCK.lock().unwrap_or_else(|e| e.into_inner())
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
}

/// A headless adapter (no surface).
pub fn request_adapter(options: &AdapterOptions) -> Result<wgpu::Adapter, SetupError> {
    let _creating = creation_lock();
    let mut desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
    if let Some(b) = options.backends {
        desc.backends = b;
    }
    let instance = wgpu::Instance::new(desc);
    if *options == AdapterOptions::default() {
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
