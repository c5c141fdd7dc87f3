//! Transcoding at load: a page decoded to (premultiplied) RGBA8 is encoded to BC1 or BC7 on the
//! loader's thread, so that the physical cache holds BC whatever the pack stores: an eighth (BC1)
//! or a quarter (BC7) of RGBA8's GPU memory and upload bytes, as id Tech 5 transcoded its pages to
//! DXT on their way into the physical texture. Intel's ISPC texture compressor (vortex-bc), at its "very
//! fast" BC7 settings (the tiler offers the slower ones offline).

use crate::page_cache::CacheFormat;

/// `texels` (`tile_size²` RGBA8) as `format`'s blocks, rows of blocks top down; RGBA8 as it is.
/// BC1 keeps no alpha: it is for opaque textures.
#[cfg(not(target_arch = "wasm32"))]
#[expect(clippy::expect_used, reason = "the page cache refuses BC formats for tile sizes that are not multiples of 4")]
pub(super) fn transcode(texels: Vec<u8>, tile_size: u32, format: CacheFormat) -> Vec<u8> {
    let mut blocks = Vec::new();
    let encoded = match format {
        CacheFormat::Rgba8 => return texels,
        CacheFormat::Bc1 => vortex_bc::encode_bc1(&texels, tile_size, tile_size, &mut blocks),
        CacheFormat::Bc7 => {
            let alpha = texels.chunks_exact(4).any(|t| t[3] != 255);
            vortex_bc::encode_bc7(&texels, tile_size, tile_size, vortex_bc::Bc7Effort::VeryFast, alpha, &mut blocks)
        }
    };
    encoded.expect("a BC cache holds tiles of whole 4x4 blocks");
    blocks
}

/// In the browser, where Intel's kernels do not build, the runtime never asks for a transcoded
/// cache (`Runtime` refuses one); the loader still makes its stand-in tile in a BC7 cache of
/// stored blocks, which [`bc7::solid_blocks`] does without a transcoder. A BC1 cache cannot
/// occur; it gets BC7-sized blocks' worth of nothing only to keep the signature total, and never
/// reaches a texture (the cache was refused first).
#[cfg(target_arch = "wasm32")]
pub(super) fn transcode(texels: Vec<u8>, tile_size: u32, format: CacheFormat) -> Vec<u8> {
    match format {
        CacheFormat::Rgba8 => texels,
        CacheFormat::Bc7 => crate::bc7::solid_blocks(&texels, tile_size),
        CacheFormat::Bc1 => vec![0; format.tile_bytes(tile_size)],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blocks_have_the_formats_sizes_and_one_colour_stays_that_colour() {
        let texels = [40u8, 120, 200, 255].repeat(16 * 16);
        assert_eq!(transcode(texels.clone(), 16, CacheFormat::Rgba8), texels);
        let bc1 = transcode(texels.clone(), 16, CacheFormat::Bc1);
        let bc7 = transcode(texels.clone(), 16, CacheFormat::Bc7);
        assert_eq!((bc1.len(), bc7.len()), (CacheFormat::Bc1.tile_bytes(16), CacheFormat::Bc7.tile_bytes(16)));
        let mut decoded = vec![0u8; 16 * 16 * 4];
        for (i, block) in bc7.chunks_exact(16).enumerate() {
            let (bx, by) = (i % 4, i / 4);
            bcdec_rs::bc7(block, &mut decoded[(by * 4 * 16 + bx * 4) * 4..], 16 * 4);
        }
        assert!(
            decoded.chunks_exact(4).all(|t| t.iter().zip(&[40u8, 120, 200, 255]).all(|(a, b)| a.abs_diff(*b) <= 1))
        );
    }
}
