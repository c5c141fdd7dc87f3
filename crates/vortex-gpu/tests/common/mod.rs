//! What the GPU tests share: the device, pinned to lavapipe (Mesa's CPU Vulkan driver) when it
//! is installed and `VK_DRIVER_FILES` is not set, and wgpu's warnings on stderr. Without an
//! adapter a test prints a note and passes, except under `CI=true`, where it fails.

use std::sync::Once;

use vortex_gpu::Gpu;

const LAVAPIPE_ICD: &str = "/usr/share/vulkan/icd.d/lvp_icd.x86_64.json";

/// Prints wgpu's warnings and errors (validation messages come through `log`).
struct StderrLogger;

impl log::Log for StderrLogger {
    fn enabled(&self, m: &log::Metadata) -> bool {
        m.level() <= log::Level::Warn || (m.level() <= log::Level::Info && m.target().starts_with("vortex"))
    }
    fn log(&self, r: &log::Record) {
        if self.enabled(r.metadata()) {
            eprintln!("[{} {}] {}", r.level(), r.target(), r.args());
        }
    }
    fn flush(&self) {}
}

static SETUP: Once = Once::new();

/// The device for one test, or `None` (with a note) when there is no adapter outside CI.
pub fn gpu() -> Option<Gpu> {
    SETUP.call_once(|| {
        let _ = log::set_logger(&StderrLogger);
        log::set_max_level(log::LevelFilter::Info);
        // SAFETY: every test calls `gpu()` before anything else that reads the environment or
        // touches Vulkan, and `Once` holds the other test threads here until these writes are done,
        // so no other thread reads the environment (through libc or std) while it is modified.
        unsafe {
            if std::env::var_os("VK_DRIVER_FILES").is_none()
                && std::env::var_os("VK_ICD_FILENAMES").is_none()
                && std::path::Path::new(LAVAPIPE_ICD).exists()
            {
                std::env::set_var("VK_DRIVER_FILES", LAVAPIPE_ICD);
            }
            if std::env::var_os("NODEVICE_SELECT").is_none() {
                std::env::set_var("NODEVICE_SELECT", "1");
            }
        }
    });
    match Gpu::headless(1024) {
        Ok(gpu) => Some(gpu),
        Err(e) if std::env::var("CI").is_ok_and(|v| v == "true") => panic!("CI=true and no GPU device: {e}"),
        Err(e) => {
            // Straight to stderr, past the harness's capture, so the skip shows in a passing run.
            use std::io::Write;
            let _ = writeln!(std::io::stderr(), "note: skipping a GPU test (set CI=true to fail instead): {e}");
            None
        }
    }
}

pub mod pyramid;
