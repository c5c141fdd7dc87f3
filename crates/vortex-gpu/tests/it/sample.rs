//! The sampling pass against the CPU reference sampler: a small synthetic virtual texture (4x4
//! pages of 32-texel tiles with a 1-texel border, 3 LODs) is made resident through `vortex-vt`'s
//! residency and page table, drawn into a 128x128 sRGB target, read back, and compared with
//! `vortex_vt::sampler::bilinear` at the same UVs and at the LOD each page-table entry names.
//!
//! The tests run on whatever adapter wgpu finds, pinned to lavapipe (Mesa's CPU Vulkan driver)
//! when it is installed and `VK_DRIVER_FILES` is not set. Without an adapter they print a note
//! and pass, except under `CI=true`, where they fail.

use crate::common::{gpu, pyramid};
use vortex_gpu::testing::bordered_tile;
use vortex_gpu::{
    CacheFormat, Gpu, GpuPageTable, PageCache, RenderTarget, SampleFilter, SamplePass, Sources, View, VirtualTexture,
    Window,
};
use vortex_vt::page::{PageId, TextureGrid};
use vortex_vt::page_table::PageTable;
use vortex_vt::residency::{Residency, ResidencyConfig};
use vortex_vt::sampler::{LodChain, Rgba8Image, bilinear};

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
        let grid = TextureGrid::new(PAGES).unwrap();
        let textures = [VirtualTexture::square(grid, TILE, BORDER)];
        let chain = pyramid::chain(PAGES as u32 * PAYLOAD, grid.lod_count, 0);
        let slots = (CACHE_SIDE as usize).pow(2);
        let mut residency = Residency::new(&[grid], ResidencyConfig::new(slots, slots)).unwrap();
        let mut table = PageTable::new(&[grid]);
        let cache = PageCache::new(&gpu.device, CACHE_SIDE, TILE, BORDER, CacheFormat::Rgba8).unwrap();
        let gpu_table = GpuPageTable::new(&gpu.device, &gpu.queue, &[grid], CACHE_SIDE);
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
            let at = origin.at(x as f32 + 0.5, y as f32 + 0.5, lod, PAGES as u32, PAYLOAD);
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
    let root = TextureGrid::new(PAGES).unwrap().lod_count - 1;
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
