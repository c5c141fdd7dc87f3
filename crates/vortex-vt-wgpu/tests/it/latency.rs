//! Never stalls, shown without a clock: every page read waits at a gate the test holds closed
//! (`testing::gated`). Real-time frames go on regardless: each frame returns while the reads are
//! held, with the pages in flight, the picture falling back to coarser pages and no time spent
//! waiting for pages; once the test opens the gate the loads land and the picture converges to
//! the reference. How long such frames take is measured by `bench/render-latency.sh`, not here:
//! a busy machine must not fail a test.

use std::sync::Arc;
use std::time::Duration;

use vortex_pack::TileKind;
use vortex_vt::sampler::{self, Rgba8Image};
use vortex_vt_wgpu::harness::camera::Keyframe;
use vortex_vt_wgpu::harness::{Effects, FrameReport, Pose, Scene, SceneRenderer, SceneView, WindowKey};
use vortex_vt_wgpu::testing::{Gate, box_chain, gated, write_pack};
use vortex_vt_wgpu::{Pacing, PageSource, VirtualTexture};

use crate::common::gpu;

/// Loader threads: each holds one read at the gate.
const THREADS: usize = 4;
/// Frames drawn while the reads are held, after the first that has pages in flight.
const HELD_FRAMES: usize = 20;
/// Bounds against a hang, never reached when the runtime works, however slow the machine: in
/// frames where frames are drawn (a busy machine slows the frames as much as the loads), and a
/// wait for the loader's threads to reach the gate.
const MAX_FRAMES: usize = 100_000;
const FAIL_SAFE: Duration = Duration::from_secs(120);

#[test]
fn frames_never_wait_for_held_reads_and_converge_when_they_land() {
    let Some(gpu) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let lod0 = Rgba8Image::from_fn(248, 248, |x, y| [(x * 5) as u8, (y * 3) as u8, ((x ^ y) * 11) as u8, 255]);
    let texture = VirtualTexture::new(248, 248, 64, 1).unwrap();
    let chain = box_chain(lod0, texture.grid.lod_count());
    let pack = write_pack(&dir.path().join("held.vtpk"), &chain, &texture, TileKind::Raw).unwrap();
    // Open while the runtime pins the root before the first frame (a blocking load), then closed.
    let gate = Gate::opened();
    let held: Arc<dyn PageSource> = Arc::new(gated(pack, Arc::clone(&gate)));
    // The whole image, one texel per pixel: the 16 pages of LOD 0 and their 5 ancestors.
    let key = WindowKey { center: [0.5, 0.5], width: 1.0 };
    let scene = Scene {
        textures: vec![],
        layers: vec![],
        size: [248, 248],
        frames: 1,
        view: SceneView::Window { texture: 0, path: vec![Keyframe { frame: 0, at: key }] },
        effects: Effects { threads: THREADS, ..Effects::exact() },
    };
    let mut renderer = SceneRenderer::new(gpu, vec![held], &scene, Pacing::RealTime).unwrap();
    let pose = scene.pose(0, renderer.runtime().textures());
    gate.close();

    // Frames until one has asked for pages: the feedback comes back when the GPU has it, a
    // frame or a few later. Every frame returns although no read can finish.
    let mut frames: Vec<FrameReport> = Vec::new();
    let frame = |renderer: &mut SceneRenderer, frames: &mut Vec<FrameReport>| {
        let (report, _) = renderer.frame(&pose, false).unwrap();
        assert_eq!(report.io_wait_ms, 0.0, "frame {} waited for pages", report.frame);
        frames.push(report.clone());
        report
    };
    while frame(&mut renderer, &mut frames).in_flight == 0 {
        assert!(frames.len() < MAX_FRAMES, "no frame asked for a page in {} frames", frames.len());
    }
    // The loader's threads are all at the gate, and the frames go on.
    assert!(gate.wait_for_readers(THREADS, FAIL_SAFE), "{} reads at the gate", gate.waiting());
    for _ in 0..HELD_FRAMES {
        let report = frame(&mut renderer, &mut frames);
        assert!(report.in_flight > 0 && report.fallback_fraction > 0.0, "{report:?}");
        assert_eq!(report.loaded, 0, "frame {}: a page landed through a closed gate", report.frame);
    }
    assert_eq!(gate.waiting(), THREADS, "the reads stayed at the gate");

    // The reads land, and the picture converges.
    gate.open();
    loop {
        let report = frame(&mut renderer, &mut frames);
        if report.fallback_fraction == 0.0 && report.in_flight == 0 {
            break;
        }
        assert!(frames.len() < MAX_FRAMES, "did not converge in {} frames: {report:?}", frames.len());
        std::thread::yield_now(); // the loaders' turn
    }
    assert!(renderer.runtime().errors().is_empty(), "{:?}", renderer.runtime().errors());

    let picture = renderer.still(&pose, None).unwrap();
    let Pose::Window(window) = pose else { unreachable!() };
    for y in 0..248 {
        for x in 0..248 {
            let [u, v] = window.uv(x, y, (248, 248));
            let want = sampler::bilinear(&chain, 0, u as f32, v as f32);
            let got = picture.texels[(y * 248 + x) as usize];
            let off = (0..3).map(|c| got[c].abs_diff(want[c])).max().unwrap();
            assert!(off <= 2, "({x}, {y}): {got:?} against {want:?}");
        }
    }
}
