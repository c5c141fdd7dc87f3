//! Never stalls: every page read takes 200 ms (`source::Delayed`), and real-time frames go on
//! regardless. No frame waits for a read (each frame's CPU time is far below one read, and its
//! measured wait for pages is zero), the picture falls back to coarser pages meanwhile, and once
//! the loads land it converges to the reference.

use std::sync::Arc;
use std::time::{Duration, Instant};

use vortex_pack::TileKind;
use vortex_vt::sampler::{self, Rgba8Image};
use vortex_vt_wgpu::harness::camera::Keyframe;
use vortex_vt_wgpu::harness::{Effects, Pose, Scene, SceneRenderer, SceneView, WindowKey};
use vortex_vt_wgpu::source::Delayed;
use vortex_vt_wgpu::testing::{box_chain, write_pack};
use vortex_vt_wgpu::{Pacing, PageSource, VirtualTexture};

use crate::common::gpu;

const LATENCY: Duration = Duration::from_millis(200);

#[test]
fn frames_never_wait_for_slow_reads_and_converge_when_they_land() {
    let Some(gpu) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let lod0 = Rgba8Image::from_fn(248, 248, |x, y| [(x * 5) as u8, (y * 3) as u8, ((x ^ y) * 11) as u8, 255]);
    let texture = VirtualTexture::new(248, 248, 64, 1).unwrap();
    let chain = box_chain(lod0, texture.grid.lod_count());
    let pack = write_pack(&dir.path().join("slow.vtpk"), &chain, &texture, TileKind::Raw).unwrap();
    let slow: Arc<dyn PageSource> = Arc::new(Delayed::new(pack, LATENCY));
    // The whole image, one texel per pixel: the 16 pages of LOD 0 and their 5 ancestors.
    let key = WindowKey { center: [0.5, 0.5], width: 1.0 };
    let scene = Scene {
        textures: vec![],
        layers: vec![],
        size: [248, 248],
        frames: 1,
        view: SceneView::Window { texture: 0, path: vec![Keyframe { frame: 0, at: key }] },
        effects: Effects { threads: 4, ..Effects::exact() },
    };
    let mut renderer = SceneRenderer::new(gpu, vec![slow], &scene, Pacing::RealTime).unwrap();
    let pose = scene.pose(0, renderer.runtime().textures());

    let started = Instant::now();
    let mut frames = Vec::new();
    loop {
        let (report, _) = renderer.frame(&pose, false).unwrap();
        frames.push(report.clone());
        let done = report.fallback_fraction == 0.0 && report.in_flight == 0 && report.requested > 0;
        if done || started.elapsed() > Duration::from_secs(20) {
            break;
        }
        // A display's refresh: the frame loop has other work than streaming.
        std::thread::sleep(Duration::from_millis(4));
    }
    for f in &frames {
        assert_eq!(f.io_wait_ms, 0.0, "frame {} waited for pages", f.frame);
        assert!(f.cpu_ms < LATENCY.as_secs_f64() * 1e3 / 2.0, "frame {} took {} ms of CPU", f.frame, f.cpu_ms);
    }
    let waiting = frames.iter().filter(|f| f.fallback_fraction > 0.0 && f.in_flight > 0).count();
    assert!(waiting >= 5, "frames went on while the pages were read: {waiting}");
    let last = frames.last().unwrap();
    assert!(last.fallback_fraction == 0.0 && last.in_flight == 0, "did not converge in 20 s: {last:?}");

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
