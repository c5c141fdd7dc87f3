//! The memory tier in the runtime: a view that flies away (far enough that a small page cache
//! evicts its pages) and comes back is served from RAM on the way back, with the tier on; with it
//! off the pack is read again. Either way the picture it comes back to matches the reference
//! sampler, and the two pictures are identical: the tier changes what is read, never what is
//! drawn.

use std::sync::Arc;

use vortex_pack::TileKind;
use vortex_vt::sampler::{self, Rgba8Image};
use vortex_vt_wgpu::harness::camera::Keyframe;
use vortex_vt_wgpu::harness::{Effects, FrameReport, Pose, Scene, SceneRenderer, SceneView, WindowKey};
use vortex_vt_wgpu::testing::{box_chain, write_pack};
use vortex_vt_wgpu::{Pacing, PageSource, VirtualTexture};

use crate::common::gpu;

/// Frames of the way there and of the stay at B; the return leg starts at `BACK` (the camera
/// leaves B) and the camera is still at A from `HOME`.
const BACK: u32 = 30;
const HOME: u32 = 38;

/// A window one texel per pixel over region A, flown to region B at the other corner and back
/// (the shape of bench/scenes/away-and-back.json, sized for a small texture), with a cache of 6²
/// slots: A's pages and their ancestors fill most of it, so B's evict them.
fn away_and_back(texture: &VirtualTexture, memory_tier_mib: u32) -> Scene {
    let [w, h] = texture.size().map(f64::from);
    let key = |x: f64, y: f64| WindowKey { center: [x / w, y / h], width: 96.0 / w };
    let (a, b) = (key(90.0, 80.0), key(420.0, 430.0));
    let path = [(0, a), (6, a), (14, b), (BACK, b), (HOME, a)];
    Scene {
        textures: vec![],
        layers: vec![],
        size: [96, 72],
        frames: HOME + 10,
        view: SceneView::Window {
            texture: 0,
            path: path.into_iter().map(|(frame, at)| Keyframe { frame, at }).collect(),
        },
        effects: Effects { cache_slots_per_side: 6, memory_tier_mib, ..Effects::exact() },
    }
}

/// Each frame's counters and the last picture.
fn run(scene: &Scene, pack: &Arc<vortex_pack::Pack>) -> (Vec<FrameReport>, Rgba8Image, Pose) {
    let sources = vec![Arc::clone(pack) as Arc<dyn PageSource>];
    let mut renderer = SceneRenderer::new(gpu().unwrap(), sources, scene, Pacing::Offline).unwrap();
    let mut frames = Vec::new();
    renderer
        .run::<vortex_vt_wgpu::RuntimeError>(scene, false, |f, _| {
            frames.push(f.clone());
            Ok(())
        })
        .unwrap();
    assert!(renderer.runtime().errors().is_empty());
    let pose = scene.pose(scene.frames - 1, renderer.runtime().textures());
    (frames, renderer.still(&pose, None).unwrap(), pose)
}

#[test]
fn a_view_that_comes_back_is_served_from_the_memory_tier() {
    let Some(_) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let texture = VirtualTexture::new(512, 512, 32, 1).unwrap();
    let lod0 = Rgba8Image::from_fn(512, 512, |x, y| [(x * 3) as u8, (y * 5) as u8, ((x ^ y) * 7) as u8, 255]);
    let chain = box_chain(lod0, texture.grid.lod_count());
    let pack = write_pack(&dir.path().join("t.vtpk"), &chain, &texture, TileKind::Raw).unwrap();

    let (on, on_picture, pose) = run(&away_and_back(&texture, 64), &pack);
    let (off, off_picture, _) = run(&away_and_back(&texture, 0), &pack);
    let sum = |frames: &[FrameReport], from: u32, f: fn(&FrameReport) -> u64| -> u64 {
        frames.iter().filter(|r| r.frame >= u64::from(from)).map(f).sum()
    };
    let (hits, misses, read) =
        (|r: &FrameReport| r.tier_hits as u64, |r: &FrameReport| r.tier_misses as u64, |r: &FrameReport| r.bytes_read);
    eprintln!(
        "away and back: tier on: {} hits, {} misses, {} bytes read on the way back; off: {} misses, {} bytes",
        sum(&on, BACK, hits),
        sum(&on, BACK, misses),
        sum(&on, BACK, read),
        sum(&off, BACK, misses),
        sum(&off, BACK, read)
    );
    assert!(sum(&on, 0, |r| r.evicted as u64) > 0 && sum(&off, 0, |r| r.evicted as u64) > 0, "nothing evicted");
    assert_eq!(sum(&off, 0, hits), 0, "the tier is off");
    assert!(sum(&off, BACK, read) > 0, "without the tier, A is read again");
    assert!(sum(&on, BACK, hits) > 0, "A comes back from RAM");
    assert!(
        sum(&on, BACK, read) < sum(&off, BACK, read) / 2,
        "{} against {}",
        sum(&on, BACK, read),
        sum(&off, BACK, read)
    );
    // The way there reads the same either way (nothing evicted has come back yet).
    assert_eq!(sum(&on, 0, read) - sum(&on, BACK, read), sum(&off, 0, read) - sum(&off, BACK, read));

    assert!(on_picture == off_picture, "the tier changed the picture");
    assert!(on.last().unwrap().fallback_fraction == 0.0, "{:?}", on.last());
    let Pose::Window(window) = pose else { unreachable!() };
    let size = (on_picture.width, on_picture.height);
    for y in 0..size.1 {
        for x in 0..size.0 {
            let [u, v] = window.uv(x, y, size);
            let want = sampler::bilinear(&chain, 0, u as f32, v as f32);
            let got = on_picture.texels[(y * size.0 + x) as usize];
            let off = (0..3).map(|c| got[c].abs_diff(want[c])).max().unwrap();
            assert!(off <= 2, "({x}, {y}): {got:?} against {want:?}");
        }
    }
}

#[test]
fn the_bench_scene_reads_and_turns_the_tier_on() {
    let json = include_str!("../../../../bench/scenes/away-and-back.json");
    let scene: Scene = serde_json::from_str(json).unwrap();
    scene.check().unwrap();
    assert_eq!(scene.effects.memory_tier_mib, 64);
    assert!(scene.effects.cache_slots_per_side <= 8, "small enough that the way out evicts the start");
}
