//! Defaults that agree: with every default (the scene's `auto` filter, the tiler's default border
//! of 1) a magnified window across page edges matches the reference sampler, so no page edge
//! shows as a seam; a pack without a border gets the nearest filter, which has none either. And
//! no alpha fringes: magnified 16x across the edge between opaque red and transparent green, not
//! a trace of green, because the cache holds premultiplied colour.

use std::sync::Arc;

use vortex_pack::TileKind;
use vortex_vt::sampler::{self, LodChain, Rgba8Image};
use vortex_vt_wgpu::harness::camera::Keyframe;
use vortex_vt_wgpu::harness::{Effects, Pose, Scene, SceneRenderer, SceneView, WindowKey};
use vortex_vt_wgpu::testing::{box_chain, write_pack};
use vortex_vt_wgpu::{Gpu, Pacing, PageSource, SampleFilter, VirtualTexture};

use crate::common::gpu;

/// A still window of `size` centred on texel `center` of `texture`, `magnify` pixels per texel.
pub(crate) fn window_scene(texture: &VirtualTexture, size: [u32; 2], center: [f64; 2], magnify: f64) -> Scene {
    let [w, h] = texture.size().map(f64::from);
    let key = WindowKey { center: [center[0] / w, center[1] / h], width: size[0] as f64 / magnify / w };
    Scene {
        textures: vec![],
        layers: vec![],
        size,
        frames: 1,
        view: SceneView::Window { texture: 0, path: vec![Keyframe { frame: 0, at: key }] },
        effects: Effects::exact(),
    }
}

/// The renderer of `scene` over `chain` stored as a raw pack, run until nothing falls back.
pub(crate) fn converged(
    gpu: Gpu,
    dir: &std::path::Path,
    chain: &LodChain,
    texture: &VirtualTexture,
    scene: &Scene,
) -> SceneRenderer {
    let pack = write_pack(&dir.join("t.vtpk"), chain, texture, TileKind::Raw).unwrap();
    let mut renderer = SceneRenderer::new(gpu, vec![pack as Arc<dyn PageSource>], scene, Pacing::Offline).unwrap();
    let pose = scene.pose(0, renderer.runtime().textures());
    for _ in 0..30 {
        let (report, _) = renderer.frame(&pose, false).unwrap();
        if report.fallback_fraction == 0.0 && report.frame > 0 {
            break;
        }
    }
    renderer
}

/// The largest difference in any colour channel between the picture and `expected(u, v)` at each
/// pixel's UV, with the pixel.
fn worst(picture: &Rgba8Image, pose: &Pose, expected: impl Fn(f32, f32) -> [u8; 4]) -> (u8, u32, u32) {
    let Pose::Window(window) = pose else { panic!("a window scene") };
    let size = (picture.width, picture.height);
    let mut worst = (0, 0, 0);
    for y in 0..picture.height {
        for x in 0..picture.width {
            let [u, v] = window.uv(x, y, size);
            let want = expected(u as f32, v as f32);
            let got = picture.texels[(y * picture.width + x) as usize];
            let off = (0..3).map(|c| got[c].abs_diff(want[c])).max().unwrap();
            if off > worst.0 {
                worst = (off, x, y);
            }
        }
    }
    worst
}

fn detailed(width: u32, height: u32) -> Rgba8Image {
    Rgba8Image::from_fn(width, height, |x, y| {
        [(x * 9 + y * 3) as u8, ((x * x) / 5 + y * 7) as u8, ((x ^ y) * 29) as u8, 255]
    })
}

#[test]
fn all_defaults_show_no_seam_at_page_edges() {
    let Some(gpu) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    // The tiler's default border: 1. Pages of 62 texels; the window is centred on the corner of
    // four pages, magnified 4x, so both page edges cross it.
    let texture = VirtualTexture::new(250, 200, 64, 1).unwrap();
    let chain = box_chain(detailed(250, 200), texture.grid.lod_count());
    let scene = window_scene(&texture, [128, 96], [124.0, 62.0], 4.0);
    let renderer = converged(gpu, dir.path(), &chain, &texture, &scene);
    assert_eq!(renderer.runtime().filter(), SampleFilter::Trilinear, "auto with a border");
    let pose = scene.pose(0, renderer.runtime().textures());
    let picture = renderer.still(&pose, None).unwrap();
    // Magnified: LOD 0, where trilinear is bilinear.
    let (off, x, y) = worst(&picture, &pose, |u, v| sampler::bilinear(&chain, 0, u, v));
    assert!(off <= 2, "{off} code values off the reference at ({x}, {y}): a seam");
}

#[test]
fn a_pack_without_border_gets_the_nearest_filter_and_no_seam() {
    let Some(gpu) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let texture = VirtualTexture::new(250, 200, 64, 0).unwrap();
    let chain = box_chain(detailed(250, 200), texture.grid.lod_count());
    let scene = window_scene(&texture, [128, 96], [128.0, 64.0], 4.0);
    let renderer = converged(gpu, dir.path(), &chain, &texture, &scene);
    assert_eq!(renderer.runtime().filter(), SampleFilter::Nearest, "auto without a border");
    assert!(SampleFilter::Bilinear.seams_with(0) && !SampleFilter::Nearest.seams_with(0));
    let pose = scene.pose(0, renderer.runtime().textures());
    let picture = renderer.still(&pose, None).unwrap();
    let (off, x, y) = worst(&picture, &pose, |u, v| sampler::nearest(&chain, 0, u, v));
    assert_eq!(off, 0, "nearest is exact; ({x}, {y}) is off");
}

#[test]
fn magnified_cut_outs_have_no_fringe_of_the_colour_under_alpha_0() {
    let Some(gpu) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    // Opaque red on the left, transparent green (alpha 0, its colour still stored) on the right.
    let image = Rgba8Image::from_fn(128, 64, |x, _| if x < 64 { [255, 0, 0, 255] } else { [0, 255, 0, 0] });
    let texture = VirtualTexture::new(128, 64, 32, 1).unwrap();
    let chain = box_chain(image, texture.grid.lod_count());
    let scene = window_scene(&texture, [128, 64], [64.0, 32.0], 16.0);
    let renderer = converged(gpu, dir.path(), &chain, &texture, &scene);
    let pose = scene.pose(0, renderer.runtime().textures());
    let picture = renderer.still(&pose, None).unwrap();
    let edge = picture.texels.iter().filter(|t| t[3] > 0 && t[3] < 255).count();
    assert!(edge > 0, "the window must cross the filtered edge");
    for (i, t) in picture.texels.iter().enumerate() {
        if t[3] > 0 {
            assert!(t[1] <= 1 && t[0] >= 254, "pixel {i} is {t:?}: a fringe of the colour under alpha 0");
        }
    }
}
