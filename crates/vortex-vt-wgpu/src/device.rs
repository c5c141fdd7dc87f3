//! Device creation for tools and tests: one wgpu instance, adapter, device and queue, headless
//! or for a window's surface. Made
//! once, on the render thread (the thread that records and submits the frame's commands); the
//! handles are `Send + Sync`, but the rest of the crate expects one thread to drive them.
//!
//! The device asks for the adapter's own largest 2D texture side rather than wgpu's default
//! (8192), since the physical page cache is one big texture, and for BC texture sampling where
//! the adapter has it (a BC7 cache); everything else stays at wgpu's defaults. The instance reads
//! wgpu's environment variables (`WGPU_BACKEND`, `WGPU_DEBUG`, `WGPU_VALIDATION`, ...); the
//! Vulkan loader's `VK_DRIVER_FILES` pins a driver.
//!
//! Pinning lavapipe (Mesa's CPU Vulkan driver) lives here too, once, for everything that wants
//! the same pictures and counters on every machine: the tests, the measurement programs and the
//! command-line tests of `vortex-tiler render` ([`lavapipe_env`], [`prefer_lavapipe`]).

use std::path::Path;

/// Where Mesa's packages install lavapipe's Vulkan driver manifest (x86-64 Debian and Ubuntu,
/// `mesa-vulkan-drivers`).
pub const LAVAPIPE_ICD: &str = "/usr/share/vulkan/icd.d/lvp_icd.x86_64.json";

/// The environment variables that pin the Vulkan loader to lavapipe, given the environment as it
/// is: `VK_DRIVER_FILES` = [`LAVAPIPE_ICD`] when lavapipe is installed and no driver is chosen
/// already (neither `VK_DRIVER_FILES` nor the older `VK_ICD_FILENAMES` is set), and
/// `NODEVICE_SELECT=1` unless set (Mesa's device-select layer only picks the default adapter,
/// which wgpu does itself, and complains on stderr about display variables a headless run has
/// no use for). Empty when there is nothing to change. For a child process:
/// `command.envs(lavapipe_env())`.
pub fn lavapipe_env() -> Vec<(&'static str, &'static str)> {
    let unset = |name: &str| std::env::var_os(name).is_none();
    let mut vars = Vec::new();
    if unset("VK_DRIVER_FILES") && unset("VK_ICD_FILENAMES") && Path::new(LAVAPIPE_ICD).exists() {
        vars.push(("VK_DRIVER_FILES", LAVAPIPE_ICD));
    }
    if std::env::var_os("NODEVICE_SELECT").is_none() {
        vars.push(("NODEVICE_SELECT", "1"));
    }
    vars
}

/// Sets [`lavapipe_env`] in this process's environment, so that the next [`Gpu::headless`]
/// runs on lavapipe where it is installed and no driver was chosen.
///
/// # Safety
///
/// Setting environment variables is only sound while no other thread reads or writes the
/// environment: call it at the start of `main`, before any thread is spawned, or from a test
/// helper under a `std::sync::Once` that every test passes before it touches the environment or
/// Vulkan.
#[expect(unsafe_code, reason = "std::env::set_var is unsafe in edition 2024; the caller upholds its contract")]
pub unsafe fn prefer_lavapipe() {
    for (name, value) in lavapipe_env() {
        // SAFETY: the caller guarantees that no other thread uses the environment meanwhile.
        unsafe { std::env::set_var(name, value) };
    }
}

/// Why no device could be made, or why it stopped answering.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DeviceError {
    /// No adapter on any enabled backend (no driver, or none matching the environment).
    #[error("no GPU adapter found (is a Vulkan driver such as mesa-vulkan-drivers installed?): {0}")]
    NoAdapter(#[from] wgpu::RequestAdapterError),
    /// The adapter's largest 2D texture is smaller than the harness needs.
    #[error("the adapter's largest 2D texture is {have} texels per side; {need} are needed")]
    TextureTooSmall {
        /// Texels per side the adapter allows.
        have: u32,
        /// Texels per side needed.
        need: u32,
    },
    /// The adapter refused the device (features or limits it lacks).
    #[error("the adapter refused the device: {0}")]
    Device(#[from] wgpu::RequestDeviceError),
    /// Waiting for the GPU to finish its work failed (the device is lost, or the wait timed out).
    #[error("waiting for the GPU failed (is the device lost?): {0}")]
    Wait(#[from] wgpu::PollError),
}

/// A headless device and its queue.
#[derive(Debug)]
pub struct Gpu {
    /// The instance the adapter came from.
    pub instance: wgpu::Instance,
    /// The adapter.
    pub adapter: wgpu::Adapter,
    /// The device.
    pub device: wgpu::Device,
    /// Its queue.
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
        Gpu::new(wgpu::Instance::new(descriptor.with_env()), None, min_texture_side)
    }

    /// A device of `instance` on an adapter that can present to `surface` (a window's), as
    /// [`Gpu::headless`] otherwise.
    pub fn for_surface(
        instance: wgpu::Instance,
        surface: &wgpu::Surface<'_>,
        min_texture_side: u32,
    ) -> Result<Gpu, DeviceError> {
        Gpu::new(instance, Some(surface), min_texture_side)
    }

    fn new(
        instance: wgpu::Instance,
        surface: Option<&wgpu::Surface<'_>>,
        min_texture_side: u32,
    ) -> Result<Gpu, DeviceError> {
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            compatible_surface: surface,
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
        log::info!(
            "vortex-vt-wgpu: {} ({:?}, {:?}), 2D textures up to {have}",
            info.name,
            info.backend,
            info.device_type
        );
        Ok(Gpu { instance, adapter, device, queue })
    }

    /// The adapter's name, backend and type, for reports.
    pub fn adapter_info(&self) -> wgpu::AdapterInfo {
        self.adapter.get_info()
    }

    /// Waits until the GPU has finished all submitted work (and map callbacks have run).
    pub fn wait_idle(&self) -> Result<(), DeviceError> {
        self.device.poll(wgpu::PollType::wait_indefinitely())?;
        Ok(())
    }
}
