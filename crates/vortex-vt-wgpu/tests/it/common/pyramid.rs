//! Synthetic virtual textures for the runtime and sampling tests: a LOD chain whose LOD 0 is made
//! here (smooth colour with detail that differs from page to page), reduced and cut into a pack
//! of bordered tiles by `vortex_vt_wgpu::testing`, stored raw (or BC7) so that what the cache holds
//! can be compared exactly.

use std::path::Path;
use std::sync::Arc;

use vortex_pack::{Pack, TileKind};
use vortex_vt::page::{PageId, TextureGrid};
use vortex_vt::sampler::{LodChain, Rgba8Image};
use vortex_vt_wgpu::VirtualTexture;
use vortex_vt_wgpu::testing::{bordered_tile, box_chain, write_pack};

/// A texture with its LOD chain and its pack.
pub struct Synthetic {
    pub chain: LodChain,
    pub texture: VirtualTexture,
    pub pack: Arc<Pack>,
}

impl Synthetic {
    /// `seed` varies the content, so that two textures differ.
    pub fn new(dir: &Path, name: &str, pages: u16, tile_size: u32, border: u32, seed: u32) -> Synthetic {
        Synthetic::with_kind(dir, name, pages, tile_size, border, seed, TileKind::Raw)
    }

    /// As [`Synthetic::new`], the tiles stored as `kind`: `Raw`, or `Bc7` (each 4x4 block one
    /// colour, its top-left texel's: what `vortex_vt_wgpu::bc7` encodes exactly).
    pub fn with_kind(
        dir: &Path,
        name: &str,
        pages: u16,
        tile_size: u32,
        border: u32,
        seed: u32,
        kind: TileKind,
    ) -> Synthetic {
        let grid = TextureGrid::new(pages.into(), pages.into()).unwrap();
        let texture = VirtualTexture::filling(grid, tile_size, border);
        Synthetic::of(dir, name, texture, seed, kind)
    }

    fn of(dir: &Path, name: &str, texture: VirtualTexture, seed: u32, kind: TileKind) -> Synthetic {
        let chain = chain(texture.width, texture.height, texture.grid.lod_count(), seed);
        let pack = write_pack(&dir.join(name), &chain, &texture, kind).unwrap();
        Synthetic { chain, texture, pack }
    }

    /// The stored tile of `page` (RGBA8, border included).
    pub fn tile(&self, page: PageId) -> Vec<u8> {
        bordered_tile(&self.chain, &self.texture, page)
    }
}

/// LOD 0 of `width x height` texels (smooth colour with finer detail, opaque), then each LOD
/// the mean of the (up to) 2x2 texels it covers of the one above, `lods` in all.
pub fn chain(width: u32, height: u32, lods: u8, seed: u32) -> LodChain {
    let code = |x: f64| x.round().clamp(0.0, 255.0) as u8;
    let s = seed as f64;
    let lod0 = Rgba8Image::from_fn(width, height, |x, y| {
        let (x, y) = (x as f64, y as f64);
        [
            code(127.5 + 100.0 * (x * 0.021 + y * 0.013 + s).sin() + 20.0 * (x * 0.31).sin()),
            code(127.5 + 100.0 * (y * 0.017 - x * 0.009 + 2.0 * s).cos() + 20.0 * (y * 0.27).cos()),
            code((x + y) * 255.0 / ((width + height).max(3) - 2) as f64),
            255,
        ]
    });
    box_chain(lod0, lods)
}
