use crate::ImageError;

/// A wgpu device and queue the detector runs on, with what it was checked for.
///
/// Engines that already own a device pass it in with [`ImageContext::from_device`]; tools and tests
/// use [`ImageContext::headless`], which picks an adapter (a real GPU, or Mesa's software Vulkan
/// driver lavapipe on a machine without one) and requests a device with exactly the
/// [`ImageContext::required_features`] and limits read from the adapter.
///
/// ```no_run
/// let ctx = frcd_image::ImageContext::headless()?;
/// println!("running on {}", ctx.adapter_name());
/// # Ok::<(), frcd_image::ImageError>(())
/// ```
#[derive(Clone, Debug)]
pub struct ImageContext {
    device: wgpu::Device,
    queue: wgpu::Queue,
    adapter: Option<wgpu::AdapterInfo>,
    /// Last field: the device and queue are dropped under `frcd_gpu::creation_lock`.
    _release: frcd_gpu::ReleaseCreationLock,
}

/// Dropping a context releases its device and queue under `frcd_gpu::creation_lock` (NVIDIA's
/// driver was seen to hang in `vkDestroyDevice` while other threads created devices).
impl Drop for ImageContext {
    fn drop(&mut self) {
        frcd_gpu::hold_creation_lock_for_drop();
    }
}

/// Smallest `max_texture_dimension_2d` the detector accepts (a 64-pixel image must fit).
const MIN_TEXTURE_DIMENSION: u32 = 64;
/// Storage buffers the resolve pass binds (lengths, mask, counters).
const STORAGE_BUFFERS_PER_STAGE: u32 = 3;

impl ImageContext {
    /// Features the detector needs: `DEPTH32FLOAT_STENCIL8`. Depth peeling compares a fragment's
    /// depth with the previous layer's stored depth, which is exact only with a float depth buffer
    /// (a 24-bit unorm one rounds and would peel a layer twice).
    pub fn required_features() -> wgpu::Features {
        wgpu::Features::DEPTH32FLOAT_STENCIL8
    }

    /// The limits requested from an adapter with `adapter_limits`: WebGPU's downlevel defaults, with
    /// the texture and buffer sizes raised to what the adapter offers (they bound the resolution).
    pub fn required_limits(adapter_limits: &wgpu::Limits) -> wgpu::Limits {
        wgpu::Limits {
            max_texture_dimension_2d: adapter_limits.max_texture_dimension_2d,
            max_storage_buffer_binding_size: adapter_limits.max_storage_buffer_binding_size,
            max_buffer_size: adapter_limits.max_buffer_size,
            ..wgpu::Limits::downlevel_defaults()
        }
    }

    /// Wraps a device and queue the caller owns, after checking features and limits.
    pub fn from_device(device: wgpu::Device, queue: wgpu::Queue) -> Result<Self, ImageError> {
        // A refused device is dropped under the creation lock (see frcd_gpu::with_creation_lock).
        frcd_gpu::with_creation_lock((device, queue), |(device, queue)| {
            Self::check(&device)?;
            Ok(Self {
                adapter: Some(device.adapter_info()),
                device,
                queue,
                _release: frcd_gpu::ReleaseCreationLock::default(),
            })
        })
    }

    /// A device on the default adapter, honouring `WGPU_BACKEND`, `WGPU_ADAPTER_NAME` and the other
    /// wgpu environment variables. No adapter is [`ImageError::NoAdapter`].
    pub fn headless() -> Result<Self, ImageError> {
        let desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
        Self::headless_with(desc)
    }

    /// A device on an adapter of the instance described by `desc` (e.g. with `backends`
    /// restricted to `wgpu::Backends::VULKAN`): the first whose name contains
    /// `WGPU_ADAPTER_NAME` when that is set, else wgpu's choice for `WGPU_POWER_PREF` (no
    /// preference when unset); set up through `frcd_gpu` as frcd-gpgpu's context is.
    pub fn headless_with(desc: wgpu::InstanceDescriptor) -> Result<Self, ImageError> {
        // Under the creation lock throughout: a refused adapter (a GL one, say) and the wgpu
        // instance it holds are dropped before the lock is released (NVIDIA's EGL teardown
        // deadlocked against another thread's vkDestroyDevice outside it).
        frcd_gpu::with_creation_lock(desc, Self::headless_locked)
    }

    fn headless_locked(desc: wgpu::InstanceDescriptor) -> Result<Self, ImageError> {
        let adapter = frcd_gpu::request_adapter_on(desc, &frcd_gpu::AdapterOptions::default())
            .map_err(|e| ImageError::NoAdapter(driver_reason(&e)))?;
        let info = adapter.get_info();
        if info.backend == wgpu::Backend::Gl {
            return Err(ImageError::UnsupportedBackend {
                adapter: info.name,
                backend: info.backend,
                reason: "GLSL cannot textureLoad a depth texture nor read its stencil aspect",
            });
        }
        let missing = Self::required_features() - adapter.features();
        if !missing.is_empty() {
            return Err(ImageError::MissingFeatures { missing });
        }
        if !adapter
            .get_downlevel_capabilities()
            .flags
            .contains(wgpu::DownlevelFlags::COMPUTE_SHADERS)
        {
            return Err(ImageError::DeviceRequest {
                adapter: info.name.clone(),
                reason: "adapter has no compute shaders".into(),
            });
        }
        let (device, queue) = frcd_gpu::request_device(
            &adapter,
            "frcd-image",
            Self::required_features(),
            Self::required_limits(&adapter.limits()),
        )
        .map_err(|e| ImageError::DeviceRequest {
            adapter: info.name.clone(),
            reason: driver_reason(&e),
        })?;
        Self::check(&device)?;
        log::info!(
            "frcd-image: adapter '{}' ({:?}, {:?})",
            info.name,
            info.device_type,
            info.backend
        );
        Ok(Self {
            device,
            queue,
            adapter: Some(info),
            _release: frcd_gpu::ReleaseCreationLock::default(),
        })
    }

    fn check(device: &wgpu::Device) -> Result<(), ImageError> {
        let info = device.adapter_info();
        if info.backend == wgpu::Backend::Gl {
            return Err(ImageError::UnsupportedBackend {
                adapter: info.name,
                backend: info.backend,
                reason: "GLSL cannot textureLoad a depth texture nor read its stencil aspect",
            });
        }
        let missing = Self::required_features() - device.features();
        if !missing.is_empty() {
            return Err(ImageError::MissingFeatures { missing });
        }
        let l = device.limits();
        let checks: [(&'static str, u64, u64); 3] = [
            (
                "max_texture_dimension_2d",
                l.max_texture_dimension_2d as u64,
                MIN_TEXTURE_DIMENSION as u64,
            ),
            (
                "max_storage_buffers_per_shader_stage",
                l.max_storage_buffers_per_shader_stage as u64,
                STORAGE_BUFFERS_PER_STAGE as u64,
            ),
            (
                "max_compute_invocations_per_workgroup",
                l.max_compute_invocations_per_workgroup as u64,
                64,
            ),
        ];
        for (name, have, need) in checks {
            if have < need {
                return Err(ImageError::LimitTooLow { name, have, need });
            }
        }
        Ok(())
    }

    /// The device.
    pub fn device(&self) -> &wgpu::Device {
        &self.device
    }

    /// The queue.
    pub fn queue(&self) -> &wgpu::Queue {
        &self.queue
    }

    /// The adapter description: the adapter this context created the device on
    /// ([`ImageContext::headless`]) or the caller's device's ([`ImageContext::from_device`]).
    pub fn adapter_info(&self) -> Option<&wgpu::AdapterInfo> {
        self.adapter.as_ref()
    }

    /// A short adapter name for reports ("caller's device" when no adapter description is
    /// known).
    pub fn adapter_name(&self) -> String {
        match &self.adapter {
            Some(i) => format!("{} ({:?}, {:?})", i.name, i.device_type, i.backend),
            None => "caller's device".into(),
        }
    }

    /// True when the adapter is a software rasterizer (device type `Cpu`, e.g. lavapipe).
    pub fn is_software(&self) -> bool {
        matches!(
            self.adapter.as_ref().map(|i| i.device_type),
            Some(wgpu::DeviceType::Cpu)
        )
    }
}

/// What the driver said (the setup error's source and its sources, "a: b"): the variant of
/// [`ImageError`] it goes into already says which step failed, and on which adapter.
fn driver_reason(e: &frcd_gpu::SetupError) -> String {
    let Some(first) = std::error::Error::source(e) else {
        return e.to_string();
    };
    let mut out = first.to_string();
    let mut next = first.source();
    while let Some(s) = next {
        out.push_str(": ");
        out.push_str(&s.to_string());
        next = s.source();
    }
    out
}
