//! Anisotropic filtering against the CPU reference: windows stretched more one way than the
//! other (a pixel stepping 4 texels across and half a texel down, and the transpose) give a
//! footprint 8 times longer than wide, with exact derivatives, so the render can be compared with
//! `vortex_vt::sampler::anisotropic_linear` pixel by pixel. The texture (8x8 pages of 32-texel
//! tiles with a 1-texel border) is striped along the footprint's short axis, the detail that
//! isotropic filtering blurs away; the windows cross page edges, so a probe that read outside its
//! page's border would show as a seam. Then the default plane's still view, where each pixel's UV
//! and derivatives come from its camera ray (`Camera::plane_uv`): the mesh path against the same
//! reference, and against the supersampled ground truth.

use vortex_pack::TileKind;
use vortex_vt::page::TextureGrid;
use vortex_vt::sampler::{LodChain, Rgba8Image, anisotropic_linear, encode, supersampled_linear};
use vortex_vt_wgpu::harness::camera::Keyframe;
use vortex_vt_wgpu::harness::{Effects, Pose, Scene, SceneRenderer, SceneView, Window, WindowKey};
use vortex_vt_wgpu::testing::{box_chain, write_pack};
use vortex_vt_wgpu::{SampleFilter, VirtualTexture};

use crate::common::{diff, gpu, renderer};

const PAGES: u16 = 8;
const TILE: u32 = 32;
const BORDER: u32 = 1;
/// Texels per pixel along the footprint's long and short axes: 8 to 1.
const LONG: f64 = 4.0;
const SHORT: f64 = 0.5;

struct Fixture {
    chain: LodChain,
    texture: VirtualTexture,
    pack: std::sync::Arc<vortex_pack::Pack>,
    _dir: tempfile::TempDir,
}

impl Fixture {
    fn new() -> Fixture {
        let grid = TextureGrid::new(PAGES.into(), PAGES.into()).unwrap();
        let texture = VirtualTexture::filling(grid, TILE, BORDER);
        // A one-texel checker over a slow colour ramp: detail at LOD 0 that every coarser LOD
        // averages to grey.
        let lod0 = Rgba8Image::from_fn(texture.width, texture.height, |x, y| {
            let stripe = if (x + y) % 2 == 0 { 200 } else { 30 };
            [stripe, (x * 255 / texture.width) as u8, (y * 255 / texture.height) as u8, 255]
        });
        let chain = box_chain(lod0, grid.lod_count());
        let dir = tempfile::tempdir().unwrap();
        let pack = write_pack(&dir.path().join("t.vtpk"), &chain, &texture, TileKind::Raw).unwrap();
        Fixture { chain, texture, pack, _dir: dir }
    }

    /// A window of `size` pixels from LOD-0 texel `origin`, `step` texels per pixel (x, y).
    fn window(&self, origin: [f64; 2], step: [f64; 2], size: [u32; 2]) -> Window {
        let [w, h] = self.texture.size().map(f64::from);
        Window {
            texture: 0,
            origin: [origin[0] / w, origin[1] / h],
            extent: [step[0] * size[0] as f64 / w, step[1] * size[1] as f64 / h],
        }
    }

    /// A trilinear renderer with at most `anisotropy` probes, streamed until `window` has every
    /// page it asks for.
    fn converged(&self, window: &Window, size: [u32; 2], anisotropy: u32) -> SceneRenderer {
        let scene = Scene {
            textures: vec![],
            layers: vec![],
            size,
            frames: 1,
            view: SceneView::Window {
                texture: 0,
                path: vec![Keyframe { frame: 0, at: WindowKey { center: [0.5, 0.5], width: 1.0 } }],
            },
            effects: Effects {
                filter: Some(SampleFilter::Trilinear),
                cache_slots_per_side: 10,
                upload_budget: 128,
                // Every pixel writes feedback every frame: every page asked for at once.
                feedback_divisor: 1,
                anisotropy,
                ..Effects::exact()
            },
        };
        let mut r = renderer(gpu().unwrap(), &[&self.pack], &scene);
        for frame in 0.. {
            let (report, _) = r.frame(&Pose::Window(*window), false).unwrap();
            if report.loaded == 0 && report.requested > 0 && report.fallback_fraction == 0.0 {
                break;
            }
            assert!(frame < 10, "the pages never landed");
        }
        r
    }

    /// At each pixel of `window`, `f(uv, ddx, ddy)`.
    fn expected(
        &self,
        window: &Window,
        size: [u32; 2],
        f: impl Fn([f32; 2], [f32; 2], [f32; 2]) -> [u8; 4],
    ) -> Rgba8Image {
        let ddx = [(window.extent[0] / size[0] as f64) as f32, 0.0];
        let ddy = [0.0, (window.extent[1] / size[1] as f64) as f32];
        Rgba8Image::from_fn(size[0], size[1], |x, y| {
            let [u, v] = window.uv(x, y, (size[0], size[1]));
            f([u as f32, v as f32], ddx, ddy)
        })
    }
}

/// The two stretched windows: long across (60 x 128 pixels over 240 x 64 texels) and long down,
/// both starting mid-page so that footprints straddle page edges.
fn windows(f: &Fixture) -> [(Window, [u32; 2]); 2] {
    [
        (f.window([0.0, 17.0], [LONG, SHORT], [60, 128]), [60, 128]),
        (f.window([13.0, 0.0], [SHORT, LONG], [128, 60]), [128, 60]),
    ]
}

#[test]
fn anisotropic_windows_match_the_reference_without_seams() {
    if gpu().is_none() {
        return;
    }
    let f = Fixture::new();
    for (window, size) in windows(&f) {
        for n in [2, 4, 8] {
            let r = f.converged(&window, size, n);
            let got = r.still(&Pose::Window(window), None).unwrap();
            let want =
                f.expected(&window, size, |uv, dx, dy| encode(anisotropic_linear(&f.chain, uv, dx, dy, n, true)));
            let (max, psnr) = diff(&got, &want);
            eprintln!("{size:?} anisotropy {n}: max difference {max}/255, PSNR {psnr:.1} dB");
            assert!(max <= 2, "{size:?} anisotropy {n}: {max} code values off the reference (PSNR {psnr:.1} dB)");
        }
    }
}

#[test]
fn anisotropy_comes_closer_to_the_ground_truth_than_trilinear() {
    if gpu().is_none() {
        return;
    }
    let f = Fixture::new();
    for (window, size) in windows(&f) {
        let truth = f.expected(&window, size, |uv, dx, dy| encode(supersampled_linear(&f.chain, uv, dx, dy, 64)));
        let psnr: Vec<f64> = [1, 2, 4, 8]
            .iter()
            .map(|&n| diff(&f.converged(&window, size, n).still(&Pose::Window(window), None).unwrap(), &truth).1)
            .collect();
        eprintln!("{size:?}: PSNR against the supersampled truth, 1x 2x 4x 8x: {psnr:.1?} dB");
        // 2x samples LOD 1, where the one-texel checker is already grey: no better than 1x.
        assert!(psnr.windows(2).all(|p| p[1] >= p[0] - 0.1), "{size:?}: no doubling is worse: {psnr:.1?}");
        assert!(psnr[3] - psnr[0] >= 6.0, "{size:?}: 8x gains at least 6 dB over trilinear: {psnr:.1?}");
    }
}

#[test]
fn feedback_asks_for_the_lod_the_probes_read() {
    if gpu().is_none() {
        return;
    }
    let f = Fixture::new();
    let (window, size) = windows(&f)[0];
    // 4 texels across, 0.5 down: trilinear wants LOD 2; 8x wants max(4 / 8, 0.5) texels: LOD 0.
    for (n, lod) in [(1, 2), (2, 1), (4, 0), (8, 0)] {
        let r = f.converged(&window, size, n);
        let table = r.runtime().page_table();
        // The pages under the window's centre row (texel row 17 + 32), every column.
        let row = ((17.0 + 64.0 * SHORT) as u32 / f.texture.payload()) >> lod;
        for x in 0..(PAGES >> lod) {
            let entry = table.entry(0, lod, x, row as u16);
            assert_eq!(entry.lod, lod, "anisotropy {n}: page ({x}, {row}) of LOD {lod} is resident");
        }
        if lod > 0 {
            let finer = table.entry(0, lod - 1, 0, (row << 1) as u16);
            assert!(finer.lod >= lod, "anisotropy {n}: LOD {} was not asked for", lod - 1);
        }
    }
}

/// A pixel's UV and its derivatives across and down.
type Footprint = ([f32; 2], [f32; 2], [f32; 2]);

/// The default plane's still view (low, toward the plane's far edge) over the checker texture:
/// each pixel's UV from the camera ray, its derivatives from its 2x2 quad's neighbours as the
/// GPU takes them, or `None` off the plane or within 2 pixels of its edge.
fn plane_pixels(scene: &Scene) -> Vec<Option<Footprint>> {
    let SceneView::Camera { fov_y_deg, path, .. } = &scene.view else { unreachable!("the plane scene") };
    let camera = path.last().unwrap().at;
    let [w, h] = scene.size;
    let uv = |x: u32, y: u32| camera.plane_uv(*fov_y_deg, [w as f32, h as f32], 1.0, x as f32 + 0.5, y as f32 + 0.5);
    let on = |x: i64, y: i64| {
        (0..w as i64).contains(&x)
            && (0..h as i64).contains(&y)
            && uv(x as u32, y as u32).is_some_and(|p| p.iter().all(|c| (0.0..1.0).contains(c)))
    };
    (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .map(|(x, y)| {
            let (xi, yi) = (x as i64, y as i64);
            let inside = (-2..=2).all(|d| on(xi + d, yi) && on(xi, yi + d));
            inside.then(|| {
                let (x0, y0) = (x & !1, y & !1);
                let (a, b, c) = (uv(x0, y).unwrap(), uv(x0 + 1, y).unwrap(), uv(x, y0 + 1).unwrap());
                let top = uv(x, y0).unwrap();
                (uv(x, y).unwrap(), [b[0] - a[0], b[1] - a[1]], [c[0] - top[0], c[1] - top[1]])
            })
        })
        .collect()
}

#[test]
fn a_plane_toward_the_horizon_matches_the_reference_and_beats_trilinear() {
    if gpu().is_none() {
        return;
    }
    let f = Fixture::new();
    let mut scene = Scene::default_plane();
    scene.size = [256, 192];
    scene.effects = Effects {
        filter: Some(SampleFilter::Trilinear),
        cache_slots_per_side: 10,
        upload_budget: 128,
        feedback_divisor: 1,
        ..Effects::exact()
    };
    let pixels = plane_pixels(&scene);
    let compare = |got: &Rgba8Image, want: &dyn Fn([f32; 2], [f32; 2], [f32; 2]) -> [u8; 4]| {
        let (mut sq, mut n, mut max) = (0.0, 0usize, 0u8);
        for (i, p) in pixels.iter().enumerate() {
            let Some((uv, dx, dy)) = *p else { continue };
            let (g, w) = (got.texels[i], want(uv, dx, dy));
            for c in 0..3 {
                max = max.max(g[c].abs_diff(w[c]));
                sq += (g[c] as f64 - w[c] as f64).powi(2);
                n += 1;
            }
        }
        (max, 10.0 * (255.0f64.powi(2) / (sq / n as f64)).log10())
    };
    let truth = |uv, dx, dy| encode(supersampled_linear(&f.chain, uv, dx, dy, 64));
    let mut to_truth = Vec::new();
    for n in [1, 4] {
        scene.effects.anisotropy = n;
        let mut r = renderer(gpu().unwrap(), &[&f.pack], &scene);
        let pose = scene.pose(scene.frames - 1, r.runtime().textures());
        for _ in 0..10 {
            r.frame(&pose, false).unwrap();
        }
        let got = r.still(&pose, None).unwrap();
        let (max, psnr) = compare(&got, &|uv, dx, dy| encode(anisotropic_linear(&f.chain, uv, dx, dy, n, true)));
        let (_, truth_psnr) = compare(&got, &truth);
        eprintln!(
            "plane, anisotropy {n}: against the reference max {max}, PSNR {psnr:.1} dB; against the truth {truth_psnr:.1} dB"
        );
        // Measured: 1 code value at most, 54.5 dB and more.
        assert!(max <= 2 && psnr >= 50.0, "anisotropy {n}: {max} code values off the reference ({psnr:.1} dB)");
        to_truth.push(truth_psnr);
    }
    // Measured: 31.1 dB for trilinear, 46.7 dB for 4x.
    assert!(to_truth[1] >= to_truth[0] + 10.0, "4x comes at least 10 dB closer to the truth: {to_truth:.1?}");
}
