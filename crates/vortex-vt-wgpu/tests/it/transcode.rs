//! Transcoding at load: pages stored raw are decoded and encoded to BC1 or BC7 on the loader's
//! threads, so the cache holds BC whatever the pack stores. The picture stays close to the
//! reference sampler's (BC is lossy: held to a PSNR, not to code values), the cache takes an eighth
//! or a quarter of RGBA8's bytes, alpha stays premultiplied through BC7 (no fringes), and BC1, which
//! has no alpha, is refused for textures that have one.

use std::sync::Arc;

use vortex_pack::TileKind;
use vortex_vt::sampler::{self, Rgba8Image};
use vortex_vt_wgpu::harness::{Effects, Pose, Scene, SceneRenderer};
use vortex_vt_wgpu::testing::{box_chain, write_opaque_pack, write_pack};
use vortex_vt_wgpu::{CacheFormat, Pacing, PageSource, RuntimeError, VirtualTexture};

use crate::common::gpu;
use crate::defaults::{converged, window_scene};

/// PSNR of the picture's colour against `expected(u, v)`, over the pixels the picture covers.
fn psnr(picture: &Rgba8Image, pose: &Pose, expected: impl Fn(f32, f32) -> [u8; 4]) -> f64 {
    let Pose::Window(window) = pose else { panic!("a window scene") };
    let size = (picture.width, picture.height);
    let (mut sum, mut n) = (0.0, 0.0);
    for y in 0..picture.height {
        for x in 0..picture.width {
            let [u, v] = window.uv(x, y, size);
            let want = expected(u as f32, v as f32);
            let got = picture.texels[(y * picture.width + x) as usize];
            for c in 0..3 {
                sum += (f64::from(got[c]) - f64::from(want[c])).powi(2);
                n += 1.0;
            }
        }
    }
    10.0 * (255.0f64.powi(2) / (sum / n).max(1e-9)).log10()
}

fn with_format(mut scene: Scene, format: CacheFormat) -> Scene {
    scene.effects.cache_format = Some(format);
    scene
}

#[test]
fn bc1_and_bc7_caches_stay_close_to_the_reference_in_less_memory() {
    let Some(_) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let texture = VirtualTexture::new(250, 200, 64, 1).unwrap();
    // Smooth colour with a little detail: what BC is made for (the grating of `detailed` is not).
    let lod0 =
        Rgba8Image::from_fn(250, 200, |x, y| [(x / 2 + 40) as u8, (y + 30) as u8, ((x + y) / 3 + 60) as u8, 255]);
    let chain = box_chain(lod0, texture.grid.lod_count());
    let scene = window_scene(&texture, [128, 96], [124.0, 62.0], 2.0);
    let pack = write_opaque_pack(&dir.path().join("rgb.vtpk"), &chain, &texture).unwrap();
    for (format, least_db) in [(CacheFormat::Bc1, 38.0), (CacheFormat::Bc7, 44.0)] {
        let scene = with_format(scene.clone(), format);
        let sources = vec![Arc::clone(&pack) as Arc<dyn PageSource>];
        let mut renderer = SceneRenderer::new(gpu().unwrap(), sources, &scene, Pacing::Offline).unwrap();
        let pose = scene.pose(0, renderer.runtime().textures());
        for _ in 0..20 {
            renderer.frame(&pose, false).unwrap();
        }
        let cache = renderer.runtime().cache();
        assert_eq!(cache.format(), format);
        assert_eq!(format.tile_bytes(64) * if format == CacheFormat::Bc1 { 8 } else { 4 }, 64 * 64 * 4);
        let picture = renderer.still(&pose, None).unwrap();
        let db = psnr(&picture, &pose, |u, v| sampler::bilinear(&chain, 0, u, v));
        assert!(db >= least_db, "{}: {db:.1} dB against the reference, under {least_db}", format.name());
        assert!(renderer.runtime().errors().is_empty());
    }
}

#[test]
fn alpha_stays_premultiplied_through_bc7_and_bc1_refuses_it() {
    let Some(gpu) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let image = Rgba8Image::from_fn(128, 64, |x, _| if x < 64 { [255, 0, 0, 255] } else { [0, 255, 0, 0] });
    let texture = VirtualTexture::new(128, 64, 32, 1).unwrap();
    let chain = box_chain(image, texture.grid.lod_count());
    let scene = with_format(window_scene(&texture, [128, 64], [64.0, 32.0], 16.0), CacheFormat::Bc7);
    let renderer = converged(gpu, dir.path(), &chain, &texture, &scene);
    let pose = scene.pose(0, renderer.runtime().textures());
    let picture = renderer.still(&pose, None).unwrap();
    assert!(picture.texels.iter().any(|t| t[3] > 0 && t[3] < 255), "the window crosses the edge");
    for (i, t) in picture.texels.iter().enumerate() {
        if t[3] > 8 {
            assert!(t[1] <= 4, "pixel {i} is {t:?}: green from under alpha 0");
        }
    }

    let pack = write_pack(&dir.path().join("alpha.vtpk"), &chain, &texture, TileKind::Raw).unwrap();
    let sources = vec![pack as Arc<dyn PageSource>];
    let bc1 = with_format(scene, CacheFormat::Bc1);
    match SceneRenderer::new(crate::common::gpu().unwrap(), sources, &bc1, Pacing::Offline) {
        Err(RuntimeError::Config(message)) => assert!(message.contains("BC1"), "{message}"),
        Err(e) => panic!("{e}"),
        Ok(_) => panic!("a BC1 cache for a texture with alpha"),
    }
}

#[test]
fn the_automatic_cache_is_bc1_for_opaque_textures_and_bc7_for_alpha() {
    let Some(gpu) = gpu() else { return };
    if !gpu.device.features().contains(wgpu::Features::TEXTURE_COMPRESSION_BC) {
        crate::common::skip_unless_ci(
            "the automatic cache test",
            "the adapter samples no BC formats (TEXTURE_COMPRESSION_BC); the automatic cache is RGBA8 there",
        );
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let texture = VirtualTexture::new(96, 64, 32, 1).unwrap();
    let lod0 = Rgba8Image::from_fn(96, 64, |x, y| [(x * 2) as u8, (y * 3) as u8, 90, 255]);
    let chain = box_chain(lod0, texture.grid.lod_count());
    let mut scene = window_scene(&texture, [96, 64], [48.0, 32.0], 1.0);
    scene.effects = Effects::default();
    assert_eq!(scene.effects.cache_format, None, "scenes default to the automatic cache");
    let opaque = write_opaque_pack(&dir.path().join("rgb.vtpk"), &chain, &texture).unwrap();
    let alpha = write_pack(&dir.path().join("rgba.vtpk"), &chain, &texture, TileKind::Raw).unwrap();
    for (pack, format) in [(opaque, CacheFormat::Bc1), (alpha, CacheFormat::Bc7)] {
        let sources = vec![pack as Arc<dyn PageSource>];
        let renderer = SceneRenderer::new(crate::common::gpu().unwrap(), sources, &scene, Pacing::Offline).unwrap();
        assert_eq!(renderer.runtime().cache().format(), format);
    }
}
