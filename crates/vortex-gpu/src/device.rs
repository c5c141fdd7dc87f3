//! Headless device creation: one wgpu instance, adapter, device and queue with no surface. Made
//! once, on the render thread (the thread that records and submits the frame's commands); the
//! handles are `Send + Sync`, but the rest of the crate expects one thread to drive them.
//!
//! The device asks for the adapter's own largest 2D texture side rather than wgpu's default
//! (8192), since the physical page cache is one big texture, and for BC texture sampling where
//! the adapter has it (a BC7 cache); everything else stays at wgpu's defaults. The instance reads wgpu's environment variables (`WGPU_BACKEND`, `WGPU_DEBUG`,
//! `WGPU_VALIDATION`, ...); the Vulkan loader's `VK_DRIVER_FILES` pins a driver, e.g. lavapipe in
//! tests.

/// Why no device could be made.
#[derive(Debug, thiserror::Error)]
pub enum DeviceError {
    /// No adapter on any enabled backend (no driver, or none matching the environment).
    #[error("no GPU adapter found (is a Vulkan driver such as mesa-vulkan-drivers installed?): {0}")]
    NoAdapter(#[from] wgpu::RequestAdapterError),
    #[error("the adapter's largest 2D texture is {have} texels per side; {need} are needed")]
    TextureTooSmall { have: u32, need: u32 },
    #[error("the adapter refused the device: {0}")]
    Device(#[from] wgpu::RequestDeviceError),
}

/// A headless device and its queue.
#[derive(Debug)]
pub struct Gpu {
    pub instance: wgpu::Instance,
    pub adapter: wgpu::Adapter,
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
}

impl Gpu {
    /// A device on the adapter wgpu prefers (high performance, no surface), whose 2D textures may
    /// be `min_texture_side` texels per side at least. Blocks until the device is ready.
    pub fn headless(min_texture_side: u32) -> Result<Gpu, DeviceError> {
        // Vulkan, Metal or DX12 unless `WGPU_BACKEND` says otherwise: the GL backend's EGL probe
        // only adds noise on headless machines.
        let descriptor = wgpu::InstanceDescriptor {
            backends: wgpu::Backends::PRIMARY,
            ..wgpu::InstanceDescriptor::new_without_display_handle()
        };
        let instance = wgpu::Instance::new(descriptor.with_env());
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            ..Default::default()
        }))?;
        let have = adapter.limits().max_texture_dimension_2d;
        if have < min_texture_side {
            return Err(DeviceError::TextureTooSmall { have, need: min_texture_side });
        }
        let required_limits = wgpu::Limits::default().using_resolution(adapter.limits());
        // BC sampling where the adapter has it: the page cache can then hold BC7 blocks.
        let required_features = adapter.features() & wgpu::Features::TEXTURE_COMPRESSION_BC;
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("vortex"),
            required_limits,
            required_features,
            ..Default::default()
        }))?;
        let info = adapter.get_info();
        log::info!("vortex-gpu: {} ({:?}, {:?}), 2D textures up to {have}", info.name, info.backend, info.device_type);
        Ok(Gpu { instance, adapter, device, queue })
    }

    /// The adapter's name, backend and type, for reports.
    pub fn adapter_info(&self) -> wgpu::AdapterInfo {
        self.adapter.get_info()
    }

    /// Waits until the GPU has finished all submitted work (and map callbacks have run).
    pub fn wait_idle(&self) {
        self.device.poll(wgpu::PollType::wait_indefinitely()).expect("device lost while waiting for the GPU");
    }
}
