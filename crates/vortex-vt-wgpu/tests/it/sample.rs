//! The sampling pass against the CPU reference sampler: a small synthetic virtual texture (4x4
//! pages of 32-texel tiles with a 1-texel border, 3 LODs) is made resident through `vortex-vt`'s
//! residency and page table, drawn into a 128x128 sRGB target, read back, and compared with
//! `vortex_vt::sampler::bilinear` at the same UVs and at the LOD each page-table entry names.
//!
//! The tests run on whatever adapter wgpu finds, pinned to lavapipe (Mesa's CPU Vulkan driver)
//! when it is installed and `VK_DRIVER_FILES` is not set. Without an adapter they print a note
//! and pass, except under `CI=true`, where they fail.

use crate::common::{gpu, pyramid};
use vortex_vt::page::{PageId, TextureGrid};
use vortex_vt::page_table::PageTable;
use vortex_vt::residency::{Residency, ResidencyConfig};
use vortex_vt::sampler::{LodChain, Rgba8Image, bilinear};
use vortex_vt_wgpu::testing::bordered_tile;
use vortex_vt_wgpu::{
    CacheFormat, Gpu, GpuPageTable, PageCache, RenderTarget, SampleFilter, SamplePass, Sources, View, VirtualTexture,
    Window,
};

const PAGES: u16 = 4;
const TILE: u32 = 32;
const BORDER: u32 = 1;
const PAYLOAD: u32 = TILE - 2 * BORDER;
const CACHE_SIDE: u16 = 5;
const TARGET: u32 = 128;
/// Largest difference allowed in any channel, in code values, and the lowest PSNR.
const MAX_DIFF: u8 = 2;
const MIN_PSNR_DB: f64 = 50.0;

/// The GPU side of one virtual texture with the pages that one residency update makes resident
/// for `requests`, plus the CPU page table that the update produced.
struct Fixture {
    gpu: Gpu,
    chain: LodChain,
    cache: PageCache,
    gpu_table: GpuPageTable,
    textures: [VirtualTexture; 1],
    table: PageTable,
    pass: SamplePass,
    target: RenderTarget,
}

impl Fixture {
    fn new(gpu: Gpu, requests: &[PageId]) -> Fixture {
        let grid = TextureGrid::new(PAGES.into(), PAGES.into()).unwrap();
        let texture = VirtualTexture::filling(grid, TILE, BORDER);
        let chain = pyramid::chain(PAGES as u32 * PAYLOAD, PAGES as u32 * PAYLOAD, grid.lod_count(), 0);
        Fixture::of(gpu, texture, chain, CACHE_SIDE, requests)
    }

    /// The fixture of `texture` (any shape), its LODs `chain`, in a cache of `cache_side²` slots.
    fn of(gpu: Gpu, texture: VirtualTexture, chain: LodChain, cache_side: u16, requests: &[PageId]) -> Fixture {
        let grid = texture.grid;
        let textures = [texture];
        let slots = (cache_side as usize).pow(2);
        let mut residency = Residency::new(&[grid], ResidencyConfig::new(slots, slots)).unwrap();
        let mut table = PageTable::new(&[grid]);
        let cache = PageCache::new(&gpu.device, cache_side, TILE, BORDER, CacheFormat::Rgba8).unwrap();
        let gpu_table = GpuPageTable::new(&gpu.device, &gpu.queue, &[grid], cache_side).unwrap();
        let update = residency.update(0, requests);
        assert_eq!(update.stats.deferred, 0, "every requested page fits in one update");
        for &(page, slot) in &update.loads {
            cache.upload(&gpu.queue, slot, &bordered_tile(&chain, &textures[0], page));
        }
        let changes = table.apply(&update);
        gpu_table.write_changes(&gpu.queue, &changes);
        let pass = SamplePass::new(&gpu.device, SampleFilter::Bilinear);
        let target = RenderTarget::new(&gpu.device, TARGET, TARGET);
        Fixture { gpu, chain, cache, gpu_table, textures, table, pass, target }
    }

    fn render(&self, window: &Window, lod: u8) -> Rgba8Image {
        let sources = Sources { textures: &self.textures, table: &self.gpu_table, cache: &self.cache };
        self.pass.render_and_read(&self.gpu, &self.target, &sources, &View::Window(*window), Some(lod as f32)).unwrap()
    }

    /// What the render must be: at each pixel's UV, the reference bilinear sample at the LOD of
    /// the page-table entry the shader reads (the finest resident ancestor of the wanted page).
    fn expected(&self, window: &Window, lod: u8) -> Rgba8Image {
        let size = (TARGET, TARGET);
        let origin = window.origin_texels(&self.textures[0], size);
        Rgba8Image::from_fn(TARGET, TARGET, |x, y| {
            let [u, v] = window.uv(x, y, size);
            let texture = &self.textures[0];
            let at = origin.at(x as f32 + 0.5, y as f32 + 0.5, lod, texture.size(), texture.payload());
            let entry = self.table.entry(0, lod, at.page[0] as u16, at.page[1] as u16);
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

fn all_pages(lod: u8) -> Vec<PageId> {
    let side = PAGES >> lod;
    (0..side * side).map(|i| PageId::new(0, lod, i % side, i / side)).collect()
}

/// Every page of `lod` of `grid`.
fn level(grid: TextureGrid, lod: u8) -> Vec<PageId> {
    (0..grid.level_len(lod) as u32).filter_map(|i| grid.page_at_index(0, lod, i)).collect()
}

/// A rectangular texture of `width x height` texels (sides not multiples of the payload nor
/// of any power of two beyond 2), with LOD 0 resident, or only `requests` when given.
fn rectangular(gpu: Gpu, width: u32, height: u32, requests: Option<&[PageId]>) -> Fixture {
    let texture = VirtualTexture::new(width, height, TILE, BORDER).unwrap();
    let chain = pyramid::chain(width, height, texture.grid.lod_count(), 3);
    let all = level(texture.grid, 0);
    let side = (texture.grid.page_count() as f64).sqrt().ceil() as u16;
    Fixture::of(gpu, texture, chain, side, requests.unwrap_or(&all))
}

/// Windows over a rectangular texture: the whole image stretched at LODs 0 to 2 (LOD 2 of an
/// odd side ends inside its last texel), square-pixel windows over its far corner, where the
/// last page holds padding, and over an inner page corner.
fn check_rectangle(fx: &Fixture, name: &str) {
    let t = fx.textures[0];
    assert!(
        !t.width.is_multiple_of(t.payload()) && !t.height.is_multiple_of(t.payload()),
        "{name}: the last pages are partial"
    );
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
    let fx = rectangular(gpu, 430, 107, None);
    assert_eq!(fx.textures[0].grid.pages(), [15, 4]);
    check_rectangle(&fx, "4:1");
}

#[test]
fn a_1_to_3_texture_matches_the_reference() {
    let Some(gpu) = gpu() else { return };
    // 97 x 293 texels: 4 x 10 pages of 30.
    let fx = rectangular(gpu, 97, 293, None);
    assert_eq!(fx.textures[0].grid.pages(), [4, 10]);
    check_rectangle(&fx, "1:3");
}

#[test]
fn a_partly_resident_rectangle_falls_back_within_its_grid() {
    let Some(gpu) = gpu() else { return };
    // The last page of each row and column (half padding) and a LOD-1 page at the odd edge.
    let wanted = [PageId::new(0, 0, 14, 3), PageId::new(0, 0, 14, 0), PageId::new(0, 0, 0, 3), PageId::new(0, 1, 7, 1)];
    let fx = rectangular(gpu, 430, 107, Some(&wanted));
    let lods: std::collections::BTreeSet<u8> = fx.table.level(0, 0).iter().map(|e| e.lod).collect();
    assert!(lods.len() >= 3, "the view mixes LODs: {lods:?}");
    fx.check("4:1 partly resident, whole image at LOD 0", &Window::whole(0), 0);
    let corner = Window::square_pixels(0, fx.textures[0].size(), [0.95, 0.9], 0.2, (TARGET, TARGET));
    fx.check("4:1 partly resident, far corner at LOD 0", &corner, 0);
}

#[test]
fn all_resident_matches_the_reference_at_lod_0() {
    let Some(gpu) = gpu() else { return };
    eprintln!("adapter: {:?}", gpu.adapter_info().name);
    let fx = Fixture::new(gpu, &all_pages(0));
    assert_eq!(fx.table.entry(0, 0, 3, 2).lod, 0, "LOD 0 is resident");
    fx.check("all resident, whole texture at LOD 0", &Window::whole(0), 0);
    fx.check("all resident, whole texture at LOD 1", &Window::whole(0), 1);
    // Magnified across the corner of four pages: page seams are where borders matter.
    let zoom = Window { texture: 0, origin: [0.37, 0.41], extent: [0.21, 0.17] };
    fx.check("all resident, magnified window over a page corner at LOD 0", &zoom, 0);
}

#[test]
fn only_the_root_falls_back_to_the_coarsest_lod() {
    let Some(gpu) = gpu() else { return };
    let fx = Fixture::new(gpu, &[]);
    let root = TextureGrid::new(PAGES.into(), PAGES.into()).unwrap().lod_count() - 1;
    assert!(fx.table.level(0, 0).iter().all(|e| e.lod == root), "every entry points at the root");
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
    let fx = Fixture::new(gpu, &[PageId::new(0, 0, 1, 1), PageId::new(0, 0, 2, 1), PageId::new(0, 1, 0, 1)]);
    let lods: std::collections::BTreeSet<u8> = fx.table.level(0, 0).iter().map(|e| e.lod).collect();
    assert_eq!(lods.into_iter().collect::<Vec<_>>(), [0, 1, 2], "the view mixes three LODs");
    fx.check("mixed residency, whole texture at LOD 0", &Window::whole(0), 0);
}
