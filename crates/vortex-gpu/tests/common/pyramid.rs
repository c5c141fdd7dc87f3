//! Synthetic virtual textures for the runtime tests: a LOD chain made here (smooth colour with
//! detail that differs from page to page, each LOD the 2x2 mean of the one above) and a pack of
//! its bordered tiles, laid out as the tiler lays them out (edge texels repeated beyond the
//! texture), stored raw so that what the cache holds can be compared exactly.
#![allow(dead_code)]

use std::path::Path;
use std::sync::Arc;

use vortex_gpu::VirtualTexture;
use vortex_pack::format::pyramid_levels;
use vortex_pack::{Description, NewTile, Pack, PackWriter, TileId, TileKind, WriteOptions};
use vortex_vt::page::{PageId, TextureGrid};
use vortex_vt::sampler::{LodChain, LodImages, Rgba8Image};

/// A square texture of `pages` pages of `payload` texels, with its pack.
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
    /// colour, its top-left texel's: what `vortex_gpu::bc7` encodes exactly).
    pub fn with_kind(
        dir: &Path,
        name: &str,
        pages: u16,
        tile_size: u32,
        border: u32,
        seed: u32,
        kind: TileKind,
    ) -> Synthetic {
        let grid = TextureGrid::new(pages).unwrap();
        let texture = VirtualTexture::square(grid, tile_size, border);
        let chain = chain(texture.side_texels() as u32, grid.lod_count, seed);
        let pack = write_pack(&dir.join(name), &chain, &texture, kind);
        Synthetic { chain, texture, pack }
    }

    /// The stored tile of `page` (RGBA8, border included).
    pub fn tile(&self, page: PageId) -> Vec<u8> {
        tile(&self.chain, &self.texture, page)
    }
}

/// LOD 0 of `side²` texels (smooth colour with finer detail, opaque), then each LOD the 2x2
/// mean of the one above, `lods` in all.
pub fn chain(side: u32, lods: u8, seed: u32) -> LodChain {
    let code = |x: f64| x.round().clamp(0.0, 255.0) as u8;
    let s = seed as f64;
    let lod0 = Rgba8Image::from_fn(side, side, |x, y| {
        let (x, y) = (x as f64, y as f64);
        [
            code(127.5 + 100.0 * (x * 0.021 + y * 0.013 + s).sin() + 20.0 * (x * 0.31).sin()),
            code(127.5 + 100.0 * (y * 0.017 - x * 0.009 + 2.0 * s).cos() + 20.0 * (y * 0.27).cos()),
            code((x + y) * 255.0 / (2.0 * (side - 1) as f64)),
            255,
        ]
    });
    let mut levels = vec![lod0];
    while levels.len() < lods as usize {
        let prev = levels.last().unwrap();
        let next = Rgba8Image::from_fn(prev.width / 2, prev.height / 2, |x, y| {
            let t = |dx, dy| prev.texels[((2 * y + dy) * prev.width + 2 * x + dx) as usize];
            std::array::from_fn(|c| {
                let sum: u32 = [t(0, 0), t(1, 0), t(0, 1), t(1, 1)].iter().map(|t| t[c] as u32).sum();
                ((sum + 2) / 4) as u8
            })
        });
        levels.push(next);
    }
    LodChain(levels)
}

/// The stored tile of `page`: its payload plus the border from its neighbours, the texture's
/// edge texels repeated beyond the edge (the tiler's layout), RGBA8 row-major.
pub fn tile(chain: &LodChain, t: &VirtualTexture, page: PageId) -> Vec<u8> {
    let (w, h) = chain.size(page.lod);
    let (ts, b, p) = (t.tile_size as i64, t.border as i64, t.payload() as i64);
    let mut out = Vec::with_capacity((ts * ts * 4) as usize);
    for j in 0..ts {
        for i in 0..ts {
            let x = (page.x as i64 * p + i - b).clamp(0, w as i64 - 1) as u32;
            let y = (page.y as i64 * p + j - b).clamp(0, h as i64 - 1) as u32;
            out.extend_from_slice(&chain.texel(page.lod, x, y));
        }
    }
    out
}

fn write_pack(path: &Path, chain: &LodChain, t: &VirtualTexture, kind: TileKind) -> Arc<Pack> {
    let side = t.side_texels() as u32;
    let d = Description {
        width: side,
        height: side,
        tile_size: t.tile_size,
        border: t.border,
        level_count: t.grid.lod_count as u32,
        channels: 4,
        sample_bytes: 1,
    };
    let levels = pyramid_levels(&d, t.grid.pages as u32);
    let mut w = PackWriter::create(path, d, levels.clone(), b"{}", WriteOptions::default()).unwrap();
    for (lod, level) in levels.iter().enumerate() {
        for y in 0..level.tiles_h {
            for x in 0..level.tiles_w {
                let mut bytes = tile(chain, t, PageId::new(0, lod as u8, x as u16, y as u16));
                if kind == TileKind::Bc7 {
                    bytes = vortex_gpu::bc7::solid_blocks(&bytes, t.tile_size);
                }
                w.add(TileId { lod: lod as u32, x, y }, NewTile::Data(kind, &bytes)).unwrap();
            }
        }
    }
    w.finish().unwrap();
    Arc::new(Pack::open(path).unwrap())
}
