//! Building blocks for tests and measurement programs (behind the `testing` feature): a LOD
//! chain reduced as the tiler's `box` filter reduces it, a page's stored tile with its border
//! laid out as the tiler lays it out, and a pack of every page. With them a test knows exactly
//! what the page cache must hold and what the reference sampler must give, without running the
//! tiler.
//!
//! A feature rather than a test helper so that the crate's own tests and the measurement crate
//! (`vortex-bench`) share one definition; it pulls in the pack writer, which the runtime itself
//! never needs. Lavapipe pinning is not here but in [`crate::device`], since the command-line
//! tests of `vortex-tiler render` need it without this feature.

use std::path::Path;
use std::sync::Arc;

use vortex_pack::format::pyramid_levels;
use vortex_pack::{Description, NewTile, Pack, PackError, PackWriter, TileId, TileKind, WriteOptions};
use vortex_vt::page::PageId;
use vortex_vt::sampler::{LodChain, LodImages, Rgba8Image};

use crate::texture::VirtualTexture;

/// `lods` levels: `lod0`, then each level the 2x2 mean of the one above in code values, rounded
/// half up (the tiler's `box` filter on an image that fills its page grid). `lod0`'s sides must
/// be divisible by `2^(lods-1)`.
pub fn box_chain(lod0: Rgba8Image, lods: u8) -> LodChain {
    let mut levels = vec![lod0];
    while levels.len() < lods as usize {
        let Some(fine) = levels.last() else { break };
        let texel = |x: u32, y: u32| fine.texels[(y * fine.width + x) as usize];
        let coarse = Rgba8Image::from_fn(fine.width / 2, fine.height / 2, |x, y| {
            let quad =
                [texel(2 * x, 2 * y), texel(2 * x + 1, 2 * y), texel(2 * x, 2 * y + 1), texel(2 * x + 1, 2 * y + 1)];
            std::array::from_fn(|c| ((quad.iter().map(|t| u32::from(t[c])).sum::<u32>() + 2) / 4) as u8)
        });
        levels.push(coarse);
    }
    LodChain(levels)
}

/// The stored tile of `page` of `texture`: its payload and `border` texels of its neighbours on
/// each side, texels beyond the level's edge repeating the edge (the tiler's layout); RGBA8
/// row-major, `tile_size²` texels.
pub fn bordered_tile(chain: &LodChain, texture: &VirtualTexture, page: PageId) -> Vec<u8> {
    let (w, h) = chain.size(page.lod);
    let (side, border, payload) =
        (i64::from(texture.tile_size), i64::from(texture.border), i64::from(texture.payload()));
    let mut out = Vec::with_capacity((side * side * 4) as usize);
    for j in 0..side {
        let y = (i64::from(page.y) * payload + j - border).clamp(0, i64::from(h) - 1) as u32;
        for i in 0..side {
            let x = (i64::from(page.x) * payload + i - border).clamp(0, i64::from(w) - 1) as u32;
            out.extend_from_slice(&chain.texel(page.lod, x, y));
        }
    }
    out
}

/// Writes a pack at `path` of every page of `texture` (texture id 0), each the
/// [bordered tile](bordered_tile) of `chain` stored as `kind`: `Raw`, or `Bc7` (the tile encoded
/// by [`crate::bc7::solid_blocks`], exact when each 4x4 block is one colour). Opens it.
pub fn write_pack(
    path: &Path,
    chain: &LodChain,
    texture: &VirtualTexture,
    kind: TileKind,
) -> Result<Arc<Pack>, PackError> {
    let side = texture.side_texels() as u32;
    let d = Description {
        width: side,
        height: side,
        tile_size: texture.tile_size,
        border: texture.border,
        level_count: u32::from(texture.grid.lod_count),
        channels: 4,
        sample_bytes: 1,
    };
    let levels = pyramid_levels(&d, u32::from(texture.grid.pages));
    let mut writer = PackWriter::create(path, d, levels.clone(), b"{}", WriteOptions::default())?;
    for (lod, level) in levels.iter().enumerate() {
        for y in 0..level.tiles_h {
            for x in 0..level.tiles_w {
                let mut bytes = bordered_tile(chain, texture, PageId::new(0, lod as u8, x as u16, y as u16));
                if kind == TileKind::Bc7 {
                    bytes = crate::bc7::solid_blocks(&bytes, texture.tile_size);
                }
                writer.add(TileId { lod: lod as u32, x, y }, NewTile::Data(kind, &bytes))?;
            }
        }
    }
    writer.finish()?;
    Ok(Arc::new(Pack::open(path)?))
}
