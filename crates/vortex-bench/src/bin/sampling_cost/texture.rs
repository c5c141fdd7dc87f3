//! The synthetic texture and its packs: one deterministic 2048² RGBA8 image with smooth colour,
//! a fine grating, thin lines and noise; its box LOD chain; and one raw-tile pack per border.

use std::path::Path;
use std::sync::Arc;

use crate::PAGES;
use crate::api::{
    Description, LodChain, LodImages, NewTile, Pack, PackWriter, PageId, Rgba8Image, TileId, TileKind, WriteOptions,
    pyramid_levels,
};

/// An integer hash of a texel position, for noise that is the same on every run.
pub fn hash(x: u32, y: u32) -> u32 {
    let mut h = x.wrapping_mul(0x2c1b_3c6d) ^ y.wrapping_mul(0x297a_2d39) ^ 0x5bd1_e995;
    h ^= h >> 15;
    h = h.wrapping_mul(0x85eb_ca6b);
    h ^= h >> 13;
    h = h.wrapping_mul(0xc2b2_ae35);
    h ^ (h >> 16)
}

/// LOD 0, texel (`x`, `y`), of a `side`-texel texture: slow colour waves and a diagonal ramp,
/// a diagonal grating of 4.7 texels whose contrast varies slowly, dark lines one texel wide every
/// 37 texels across and 29 down, and a little noise.
pub fn source_texel(x: u32, y: u32, side: u32) -> [u8; 4] {
    let (fx, fy) = (x as f64, y as f64);
    let ramp = (fx + fy) / (2.0 * (side - 1) as f64);
    let base = [
        128.0 + 70.0 * (fx * 0.0041 + fy * 0.0023).sin(),
        120.0 + 70.0 * (fy * 0.0037 - fx * 0.0013 + 1.7).sin(),
        50.0 + 150.0 * ramp,
    ];
    let contrast = 0.5 + 0.5 * (fx * 0.0029 - fy * 0.0051 + 0.4).sin();
    let grating = 38.0 * contrast * ((fx * 0.8 + fy * 0.6) * std::f64::consts::TAU / 4.7).sin();
    let line = if x % 37 == 11 || y % 29 == 5 { -70.0 } else { 0.0 };
    let noise = (hash(x, y) % 17) as f64 - 8.0;
    let code = |v: f64| v.round().clamp(0.0, 255.0) as u8;
    let detail = grating + line + noise;
    [code(base[0] + detail), code(base[1] + detail), code(base[2] + 0.6 * detail), 255]
}

/// The texture's LODs: LOD 0 from [`source_texel`], each further LOD the 2x2 mean of the one
/// before in code values, rounded half up (the tiler's `box` filter on an image that fills its
/// page grid).
pub fn lod_chain(side: u32, lods: u8) -> LodChain {
    let mut levels = vec![Rgba8Image::from_fn(side, side, |x, y| source_texel(x, y, side))];
    for _ in 1..lods {
        let fine = levels.last().unwrap();
        let texel = |x: u32, y: u32| fine.texels[(y * fine.width + x) as usize];
        let coarse = Rgba8Image::from_fn(fine.width / 2, fine.height / 2, |x, y| {
            let quad =
                [texel(2 * x, 2 * y), texel(2 * x + 1, 2 * y), texel(2 * x, 2 * y + 1), texel(2 * x + 1, 2 * y + 1)];
            std::array::from_fn(|c| ((quad.iter().map(|t| t[c] as u32).sum::<u32>() + 2) / 4) as u8)
        });
        levels.push(coarse);
    }
    LodChain(levels)
}

/// The stored tile of `page`: its payload and `border` texels of its neighbours on each side,
/// texels beyond the level's edge repeating the edge (the tiler's layout), RGBA8.
pub fn stored_tile(chain: &LodChain, page: PageId, tile_size: u32, border: u32) -> Vec<u8> {
    let (w, h) = chain.size(page.lod);
    let payload = (tile_size - 2 * border) as i64;
    let mut bytes = Vec::with_capacity((tile_size * tile_size * 4) as usize);
    for j in 0..tile_size as i64 {
        let y = (page.y as i64 * payload + j - border as i64).clamp(0, h as i64 - 1) as u32;
        for i in 0..tile_size as i64 {
            let x = (page.x as i64 * payload + i - border as i64).clamp(0, w as i64 - 1) as u32;
            bytes.extend_from_slice(&chain.texel(page.lod, x, y));
        }
    }
    bytes
}

/// A pack of every page of `chain` in `tile_size`-texel raw tiles with `border`.
pub fn write_pack(path: &Path, chain: &LodChain, tile_size: u32, border: u32) -> Arc<Pack> {
    let (side, _) = chain.size(0);
    let d = Description {
        width: side,
        height: side,
        tile_size,
        border,
        level_count: chain.lod_count() as u32,
        channels: 4,
        sample_bytes: 1,
    };
    let levels = pyramid_levels(&d, PAGES as u32);
    let mut writer = PackWriter::create(path, d, levels.clone(), b"{}", WriteOptions::default()).expect("a pack");
    for (lod, level) in levels.iter().enumerate() {
        for y in 0..level.tiles_h {
            for x in 0..level.tiles_w {
                let tile = stored_tile(chain, PageId::new(0, lod as u8, x as u16, y as u16), tile_size, border);
                writer.add(TileId { lod: lod as u32, x, y }, NewTile::Data(TileKind::Raw, &tile)).expect("a tile");
            }
        }
    }
    writer.finish().expect("the pack is written");
    Arc::new(Pack::open(path).expect("the pack opens"))
}
