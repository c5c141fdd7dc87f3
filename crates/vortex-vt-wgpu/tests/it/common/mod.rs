//! What the GPU tests share: the device, pinned to lavapipe (Mesa's CPU Vulkan driver) when it
//! is installed and no Vulkan driver is chosen (`vortex_vt_wgpu::device::prefer_lavapipe`), and
//! wgpu's warnings on stderr. Without an adapter a test prints a note and passes, except under
//! `CI=true`, where it fails.

use std::sync::{Arc, Once};

use vortex_pack::Pack;
use vortex_vt::sampler::Rgba8Image;
use vortex_vt_wgpu::harness::{FrameReport, Scene, SceneRenderer};
use vortex_vt_wgpu::{Gpu, Pacing, PageSource};

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

/// Whether this run is CI's (`CI=true`), where every outside part is installed and a test that
/// lacks one fails rather than skips.
pub fn under_ci() -> bool {
    std::env::var("CI").is_ok_and(|v| v == "true")
}

/// Outside CI a test that lacks something (a feature of the adapter, a driver) skips with a
/// note on stderr; under `CI=true` it fails instead, saying what was missing. (The tiler's own
/// tests have the same rule in `tests/it/common`.)
pub fn skip_unless_ci(what: &str, why: &str) {
    assert!(!under_ci(), "CI=true and {why}");
    // Straight to stderr, past the harness's capture, so the skip shows in a passing run.
    use std::io::Write;
    let _ = writeln!(std::io::stderr(), "note: skipping {what} (set CI=true to fail instead): {why}");
}

/// The device for one test, or `None` (with a note) when there is no adapter outside CI.
#[expect(unsafe_code, reason = "pinning the Vulkan driver sets environment variables")]
pub fn gpu() -> Option<Gpu> {
    SETUP.call_once(|| {
        let _ = log::set_logger(&StderrLogger);
        log::set_max_level(log::LevelFilter::Info);
        // SAFETY: every test calls `gpu()` before anything else that reads the environment or
        // touches Vulkan, and `Once` holds the other test threads here until these writes are done,
        // so no other thread reads the environment (through libc or std) while it is modified.
        // (The loader's tests read no environment.)
        unsafe { vortex_vt_wgpu::device::prefer_lavapipe() };
    });
    match Gpu::headless(1024) {
        Ok(gpu) => Some(gpu),
        Err(e) => {
            skip_unless_ci("a GPU test", &format!("no GPU device: {e}"));
            None
        }
    }
}

/// The renderer of `scene` over `packs` (texture id = index), paced offline (each frame's
/// feedback is read back and its pages land before the next frame: the same counters and
/// pictures on every run), checking the residency's and the page table's invariants after every
/// frame.
pub fn renderer(gpu: Gpu, packs: &[&Arc<Pack>], scene: &Scene) -> SceneRenderer {
    let sources = packs.iter().map(|&p| p.clone() as Arc<dyn PageSource>).collect();
    let mut renderer = SceneRenderer::new(gpu, sources, scene, Pacing::Offline).unwrap();
    renderer.runtime_mut().check_invariants = true;
    renderer
}

/// `frames` without their timings, which differ from run to run: the counters alone.
pub fn untimed(frames: &[FrameReport]) -> Vec<FrameReport> {
    frames.iter().map(|f| FrameReport { cpu_ms: 0.0, io_wait_ms: 0.0, ..f.clone() }).collect()
}

pub mod pyramid;

/// Largest difference in any channel, and PSNR over all channels in dB.
pub fn diff(got: &Rgba8Image, want: &Rgba8Image) -> (u8, f64) {
    let mut max = 0;
    let mut sq = 0.0;
    for (g, w) in got.texels.iter().zip(&want.texels) {
        for c in 0..4 {
            max = max.max(g[c].abs_diff(w[c]));
            sq += (g[c] as f64 - w[c] as f64).powi(2);
        }
    }
    let mse = sq / (got.texels.len() * 4) as f64;
    (max, if mse == 0.0 { f64::INFINITY } else { 10.0 * (255.0f64.powi(2) / mse).log10() })
}
