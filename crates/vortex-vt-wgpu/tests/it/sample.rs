//! The module's sampling (`vt_sample_texel_level`, from the harness's window shader) against the
//! CPU reference sampler: a small synthetic virtual texture (4x4 pages of 32-texel tiles with a
//! 1-texel border, 3 LODs), stored as a pack, is streamed by the runtime (paced offline) while
//! windows over chosen pages are drawn, so that the page table maps those pages and their
//! ancestors; then windows are drawn at a fixed LOD into a 128x128 sRGB target without streaming,
//! read back, and compared with `vortex_vt::sampler::bilinear` at the same UVs and at the LOD
//! each page-table entry names.
//!
//! The tests run on whatever adapter wgpu finds, pinned to lavapipe (Mesa's CPU Vulkan driver)
//! when it is installed and `VK_DRIVER_FILES` is not set. Without an adapter they print a note
//! and pass, except under `CI=true`, where they fail.

use crate::common::{gpu, renderer};
use vortex_pack::TileKind;
use vortex_vt::page::{PageId, TextureGrid};
use vortex_vt::page_table::PageTable;
use vortex_vt::sampler::{LodChain, Rgba8Image, bilinear};
use vortex_vt_wgpu::harness::camera::Keyframe;
use vortex_vt_wgpu::harness::{Effects, Pose, Scene, SceneRenderer, SceneView, Window, WindowKey};
use vortex_vt_wgpu::testing::write_pack;
use vortex_vt_wgpu::{Gpu, SampleFilter, VirtualTexture};

const PAGES: u16 = 4;
const TILE: u32 = 32;
const BORDER: u32 = 1;
const PAYLOAD: u32 = TILE - 2 * BORDER;
const CACHE_SIDE: u16 = 5;
const TARGET: u32 = 128;
/// Largest difference allowed in any channel, in code values, and the lowest PSNR.
const MAX_DIFF: u8 = 2;
const MIN_PSNR_DB: f64 = 50.0;

/// One virtual texture, its LOD chain, and a renderer whose runtime has streamed the pages that
/// some windows asked for.
struct Fixture {
    chain: LodChain,
    texture: VirtualTexture,
    renderer: SceneRenderer,
    _dir: tempfile::TempDir,
}

impl Fixture {
    /// The 4x4-page texture, after streaming `windows`.
    fn new(gpu: Gpu, windows: &[Window]) -> Fixture {
        let grid = TextureGrid::new(PAGES.into(), PAGES.into()).unwrap();
        let texture = VirtualTexture::filling(grid, TILE, BORDER);
        let chain = crate::common::pyramid::chain(PAGES as u32 * PAYLOAD, PAGES as u32 * PAYLOAD, grid.lod_count(), 0);
        Fixture::of(gpu, texture, chain, CACHE_SIDE, windows)
    }

    /// The fixture of `texture` (any shape), its LODs `chain`, in a cache of `cache_side²` slots,
    /// after streaming `windows` one after the other, each until its pages have landed.
    fn of(gpu: Gpu, texture: VirtualTexture, chain: LodChain, cache_side: u16, windows: &[Window]) -> Fixture {
        let dir = tempfile::tempdir().unwrap();
        let pack = write_pack(&dir.path().join("t.vtpk"), &chain, &texture, TileKind::Raw).unwrap();
        let scene = scene(cache_side);
        let mut renderer = renderer(gpu, &[&pack], &scene);
        for window in windows {
            for frame in 0.. {
                let (report, _) = renderer.frame(&Pose::Window(*window), false).unwrap();
                assert_eq!((report.deferred, report.evicted), (0, 0), "{window:?}: the cache holds every page");
                if report.loaded == 0 && report.requested > 0 {
                    break;
                }
                assert!(frame < 10, "{window:?}: the pages never landed");
            }
        }
        Fixture { chain, texture, renderer, _dir: dir }
    }

    fn table(&self) -> &PageTable {
        self.renderer.runtime().page_table()
    }

    /// Draws `window` at the fixed LOD `lod`, with the page table as the streaming left it.
    fn render(&self, window: &Window, lod: u8) -> Rgba8Image {
        self.renderer.still(&Pose::Window(*window), Some(lod as f32)).unwrap()
    }

    /// What the render must be: at each pixel's UV, the reference bilinear sample at the LOD of
    /// the page-table entry the shader reads (the finest resident ancestor of the wanted page);
    /// off the image (a window hanging past its edge), the background, transparent.
    fn expected(&self, window: &Window, lod: u8) -> Rgba8Image {
        let size = (TARGET, TARGET);
        let origin = window.origin_texels(&self.texture, size);
        Rgba8Image::from_fn(TARGET, TARGET, |x, y| {
            let [u, v] = window.uv(x, y, size);
            let texture = &self.texture;
            if !origin.on_image(x as f32 + 0.5, y as f32 + 0.5, texture.size()) {
                return [0; 4];
            }
            let at = origin.at(x as f32 + 0.5, y as f32 + 0.5, lod, texture.size(), texture.payload());
            let entry = self.table().entry(0, lod, at.page[0] as u16, at.page[1] as u16);
            bilinear(&self.chain, entry.lod, u as f32, v as f32)
        })
    }

    /// Renders `window` at `lod` and checks it against [`Fixture::expected`].
    fn check(&self, what: &str, window: &Window, lod: u8) -> Diff {
        let got = self.render(window, lod);
        let want = self.expected(window, lod);
        let d = Diff::of(&got, &want);
        eprintln!("{what}: {d}");
        assert!(
            d.max <= MAX_DIFF && d.psnr_db >= MIN_PSNR_DB,
            "{what}: {d} (limits: max {MAX_DIFF}, PSNR >= {MIN_PSNR_DB} dB)"
        );
        d
    }
}

/// A still 128x128 window scene, bilinear, in a cache of `cache_side²` slots (its path is not
/// followed: the tests draw their own windows).
fn scene(cache_side: u16) -> Scene {
    Scene {
        textures: vec![],
        layers: vec![],
        size: [TARGET, TARGET],
        frames: 1,
        view: SceneView::Window {
            texture: 0,
            path: vec![Keyframe { frame: 0, at: WindowKey { center: [0.5, 0.5], width: 1.0 } }],
        },
        effects: Effects {
            filter: Some(SampleFilter::Bilinear),
            cache_slots_per_side: cache_side,
            upload_budget: 128,
            ..Effects::exact()
        },
    }
}

/// A window of `texture` whose top-left corner is LOD-0 texel `origin`, `step` texels per pixel
/// across and `step_y` down.
fn texels(texture: &VirtualTexture, origin: [f64; 2], step: f64, step_y: f64) -> Window {
    let [w, h] = texture.size().map(f64::from);
    let span = TARGET as f64;
    Window { texture: 0, origin: [origin[0] / w, origin[1] / h], extent: [step * span / w, step_y * span / h] }
}

/// A magnified window (LOD 0) inside LOD-0 page (`x`, `y`), asking for it alone.
fn inside_page(texture: &VirtualTexture, x: u16, y: u16) -> Window {
    let p = texture.payload() as f64;
    texels(texture, [x as f64 * p + 1.5, y as f64 * p + 1.5], 0.05, 0.05)
}

/// A window asking for LOD-1 page (`x`, `y`) alone, from the left edge (`x` = 0) or the right
/// edge of the texture: about 2 texels per pixel across (LOD 1), hanging past the edge, where
/// addresses clamp to the edge's page, and fine down, within the page's rows.
fn lod1_edge_page(texture: &VirtualTexture, x: u16, y: u16) -> Window {
    let p = 2.0 * texture.payload() as f64;
    let step = 2.03;
    let left = if x == 0 { -250.0 } else { x as f64 * p + 1.0 };
    texels(texture, [left, y as f64 * p + 2.0], step, (p - 4.0) / TARGET as f64)
}

/// How far a render is from the reference, over all four channels.
#[derive(Debug)]
struct Diff {
    max: u8,
    /// (x, y, got, want) of the first texel at the largest difference.
    worst: Option<(u32, u32, [u8; 4], [u8; 4])>,
    psnr_db: f64,
    differing: usize,
}

impl Diff {
    fn of(got: &Rgba8Image, want: &Rgba8Image) -> Diff {
        assert_eq!((got.width, got.height), (want.width, want.height));
        let (mut max, mut worst, mut sq, mut differing) = (0, None, 0.0, 0);
        for (i, (g, w)) in got.texels.iter().zip(&want.texels).enumerate() {
            let d = (0..4).map(|c| g[c].abs_diff(w[c])).max().unwrap();
            if d > max || worst.is_none() {
                max = d;
                worst = Some((i as u32 % got.width, i as u32 / got.width, *g, *w));
            }
            differing += (d > 0) as usize;
            sq += (0..4).map(|c| (g[c] as f64 - w[c] as f64).powi(2)).sum::<f64>();
        }
        let mse = sq / (got.texels.len() * 4) as f64;
        let psnr_db = if mse == 0.0 { f64::INFINITY } else { 10.0 * (255.0f64.powi(2) / mse).log10() };
        Diff { max, worst, psnr_db, differing }
    }
}

impl std::fmt::Display for Diff {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        write!(f, "max difference {}/255, PSNR {:.1} dB, {} texels differ", self.max, self.psnr_db, self.differing)?;
        if let Some((x, y, g, w)) = self.worst {
            write!(f, "; worst at ({x}, {y}): got {g:?}, want {w:?}")?;
        }
        Ok(())
    }
}

/// Windows of `texture` at LOD 0 (0.9 texels per pixel) that together cover its whole image.
fn lod0_tiling(texture: &VirtualTexture) -> Vec<Window> {
    let span = 0.9 * TARGET as f64;
    let [w, h] = texture.size();
    let starts = |n: u32| (0..).map(move |i| i as f64 * span).take_while(move |&o| o < n as f64);
    starts(h).flat_map(|y| starts(w).map(move |x| texels(texture, [x, y], 0.9, 0.9))).collect()
}

/// A rectangular texture of `width x height` texels (sides not multiples of the payload nor
/// of any power of two beyond 2), after streaming the windows `windows` gives for it.
fn rectangular(gpu: Gpu, width: u32, height: u32, windows: impl Fn(&VirtualTexture) -> Vec<Window>) -> Fixture {
    let texture = VirtualTexture::new(width, height, TILE, BORDER).unwrap();
    let chain = crate::common::pyramid::chain(width, height, texture.grid.lod_count(), 3);
    let windows = windows(&texture);
    let side = (texture.grid.page_count() as f64).sqrt().ceil() as u16;
    Fixture::of(gpu, texture, chain, side, &windows)
}

/// Windows over a rectangular texture: the whole image stretched at LODs 0 to 2 (LOD 2 of an
/// odd side ends inside its last texel), square-pixel windows over its far corner, where the
/// last page holds padding, and over an inner page corner.
fn check_rectangle(fx: &Fixture, name: &str) {
    let t = fx.texture;
    assert!(
        !t.width.is_multiple_of(t.payload()) && !t.height.is_multiple_of(t.payload()),
        "{name}: the last pages are partial"
    );
    assert!(fx.table().level(0, 0).iter().all(|e| e.lod == 0), "{name}: LOD 0 is resident");
    for lod in 0..3 {
        fx.check(&format!("{name}, whole image at LOD {lod}"), &Window::whole(0), lod);
    }
    let size = (TARGET, TARGET);
    let corner = Window::square_pixels(0, t.size(), [0.97, 0.95], 0.15, size);
    fx.check(&format!("{name}, far corner at LOD 0"), &corner, 0);
    let seam = [t.payload() as f64 / t.width as f64, t.payload() as f64 / t.height as f64];
    let inner = Window::square_pixels(0, t.size(), seam, 0.1, size);
    fx.check(&format!("{name}, page corner at LOD 0"), &inner, 0);
}

#[test]
fn a_4_to_1_texture_matches_the_reference() {
    let Some(gpu) = gpu() else { return };
    // 430 x 107 texels: 15 x 4 pages of 30, LOD 1 8 x 2, ... 5 LODs.
    let fx = rectangular(gpu, 430, 107, lod0_tiling);
    assert_eq!(fx.texture.grid.pages(), [15, 4]);
    check_rectangle(&fx, "4:1");
}

#[test]
fn a_1_to_3_texture_matches_the_reference() {
    let Some(gpu) = gpu() else { return };
    // 97 x 293 texels: 4 x 10 pages of 30.
    let fx = rectangular(gpu, 97, 293, lod0_tiling);
    assert_eq!(fx.texture.grid.pages(), [4, 10]);
    check_rectangle(&fx, "1:3");
}

#[test]
fn a_partly_resident_rectangle_falls_back_within_its_grid() {
    let Some(gpu) = gpu() else { return };
    // The last page of each row and column (half padding) and a LOD-1 page at the odd edge.
    let windows = |t: &VirtualTexture| {
        vec![inside_page(t, 14, 3), inside_page(t, 14, 0), inside_page(t, 0, 3), lod1_edge_page(t, 7, 1)]
    };
    let fx = rectangular(gpu, 430, 107, windows);
    let grid = fx.texture.grid;
    let mapped: Vec<PageId> =
        fx.renderer.runtime().residency().resident().map(|(p, _)| p).filter(|p| p.lod < grid.lod_count() - 1).collect();
    let wanted = [PageId::new(0, 0, 14, 3), PageId::new(0, 0, 14, 0), PageId::new(0, 0, 0, 3), PageId::new(0, 1, 7, 1)];
    for p in wanted {
        assert_eq!(fx.table().get(p).lod, p.lod, "{p:?} is mapped");
    }
    assert!(!mapped.iter().any(|p| p.lod == 0 && !wanted.contains(p)), "only the LOD-0 pages asked for: {mapped:?}");
    let lods: std::collections::BTreeSet<u8> = fx.table().level(0, 0).iter().map(|e| e.lod).collect();
    assert!(lods.len() >= 3, "the view mixes LODs: {lods:?}");
    fx.check("4:1 partly resident, whole image at LOD 0", &Window::whole(0), 0);
    let corner = Window::square_pixels(0, fx.texture.size(), [0.95, 0.9], 0.2, (TARGET, TARGET));
    fx.check("4:1 partly resident, far corner at LOD 0", &corner, 0);
}

#[test]
fn all_resident_matches_the_reference_at_lod_0() {
    let Some(gpu) = gpu() else { return };
    eprintln!("adapter: {:?}", gpu.adapter_info().name);
    // The whole texture, 120 texels over 128 pixels: LOD 0 and its ancestors, 21 pages.
    let fx = Fixture::new(gpu, &[Window::whole(0)]);
    assert_eq!(fx.renderer.runtime().residency().resident_count(), 21);
    assert_eq!(fx.table().entry(0, 0, 3, 2).lod, 0, "LOD 0 is resident");
    fx.check("all resident, whole texture at LOD 0", &Window::whole(0), 0);
    fx.check("all resident, whole texture at LOD 1", &Window::whole(0), 1);
    // Magnified across the corner of four pages: page seams are where borders matter.
    let zoom = Window { texture: 0, origin: [0.37, 0.41], extent: [0.21, 0.17] };
    fx.check("all resident, magnified window over a page corner at LOD 0", &zoom, 0);
}

#[test]
fn only_the_root_falls_back_to_the_coarsest_lod() {
    let Some(gpu) = gpu() else { return };
    // Nothing streamed: the runtime loads the root before the first frame, and nothing else.
    let fx = Fixture::new(gpu, &[]);
    let root = TextureGrid::new(PAGES.into(), PAGES.into()).unwrap().lod_count() - 1;
    assert_eq!(fx.renderer.runtime().residency().resident_count(), 1);
    assert!(fx.table().level(0, 0).iter().all(|e| e.lod == root), "every entry points at the root");
    // The expectation is the reference sampler at the root's LOD everywhere.
    let view = Window::whole(0);
    let root_only = Rgba8Image::from_fn(TARGET, TARGET, |x, y| {
        let [u, v] = view.uv(x, y, (TARGET, TARGET));
        bilinear(&fx.chain, root, u as f32, v as f32)
    });
    assert_eq!(fx.expected(&view, 0), root_only);
    fx.check("root only, whole texture requested at LOD 0", &view, 0);
}

#[test]
fn partly_resident_samples_the_finest_resident_ancestor() {
    let Some(gpu) = gpu() else { return };
    // Two LOD 0 pages and one LOD 1 page elsewhere (each brings its ancestors).
    let t = VirtualTexture::filling(TextureGrid::new(PAGES.into(), PAGES.into()).unwrap(), TILE, BORDER);
    let fx = Fixture::new(gpu, &[inside_page(&t, 1, 1), inside_page(&t, 2, 1), lod1_edge_page(&t, 0, 1)]);
    let resident: std::collections::BTreeSet<PageId> =
        fx.renderer.runtime().residency().resident().map(|(p, _)| p).collect();
    let want = [
        PageId::new(0, 0, 1, 1),
        PageId::new(0, 0, 2, 1),
        PageId::new(0, 1, 0, 0),
        PageId::new(0, 1, 1, 0),
        PageId::new(0, 1, 0, 1),
        PageId::new(0, 2, 0, 0),
    ];
    assert_eq!(resident, want.into_iter().collect(), "the windows asked for these pages and their ancestors");
    let lods: std::collections::BTreeSet<u8> = fx.table().level(0, 0).iter().map(|e| e.lod).collect();
    assert_eq!(lods.into_iter().collect::<Vec<_>>(), [0, 1, 2], "the view mixes three LODs");
    fx.check("mixed residency, whole texture at LOD 0", &Window::whole(0), 0);
}
