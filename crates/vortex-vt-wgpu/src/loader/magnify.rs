//! Absent tiles made from their nearest stored ancestor: "the runtime falls back to the parent
//! tile" (pack format), so the loader fills the page's slot with the ancestor magnified to the
//! page, as the GPU would sample the ancestor in its place. Its own file because it is pure
//! integer arithmetic on one tile, with its own tests, and nothing to do with threads or packs.

use vortex_vt::page::PageId;

use crate::texture::VirtualTexture;

/// The stored tile of `page`, built from `ancestor`, the RGBA8 tile of its ancestor `levels_up`
/// LODs coarser, by bilinear magnification.
///
/// Each stored texel of the page, borders included, is centred on a point of the virtual texture
/// (`x * payload - border + i + 0.5` at the page's LOD); it takes the ancestor's texels around the
/// same point, weighted bilinearly between texel centres, as the GPU does when it samples the
/// ancestor in the page's place. The page's stored area always lies inside the ancestor's stored
/// area, borders included (edge taps clamp to the tile). Filtering is on the stored values
/// (sRGB-encoded, straight alpha), in exact integer arithmetic (the weights are multiples of
/// 2^-(levels_up+1)), rounded half up, so a constant ancestor gives the same constant.
pub(super) fn magnify(ancestor: &[u8], texture: &VirtualTexture, page: PageId, levels_up: u8) -> Vec<u8> {
    let side = texture.tile_size as usize;
    let taps_x = magnify_taps(texture, page.x, levels_up);
    let taps_y = magnify_taps(texture, page.y, levels_up);
    let denominator = 1u64 << (2 * (u32::from(levels_up) + 1));
    let mut out = Vec::with_capacity(side * side * 4);
    for &(y0, y1, wy0, wy1) in &taps_y {
        for &(x0, x1, wx0, wx1) in &taps_x {
            for channel in 0..4 {
                let texel =
                    |x: usize, y: usize| u64::from(ancestor.get((y * side + x) * 4 + channel).copied().unwrap_or(0));
                let sum = wy0 * (wx0 * texel(x0, y0) + wx1 * texel(x1, y0))
                    + wy1 * (wx0 * texel(x0, y1) + wx1 * texel(x1, y1));
                out.push(((sum + denominator / 2) / denominator) as u8);
            }
        }
    }
    out
}

/// For each stored texel along one axis of the page at position `page_xy` of its LOD: the two
/// ancestor texels around its centre and their weights (summing to `2^(levels_up+1)`).
fn magnify_taps(texture: &VirtualTexture, page_xy: u16, levels_up: u8) -> Vec<(usize, usize, u64, u64)> {
    let (side, border, payload) =
        (i64::from(texture.tile_size), i64::from(texture.border), i64::from(texture.payload()));
    let scale = 1i64 << (levels_up + 1);
    let xy = i64::from(page_xy);
    let ancestor_xy = xy >> levels_up;
    let clamp = |j: i64| j.clamp(0, side - 1) as usize;
    (0..side)
        .map(|i| {
            // Centre of texel i at the page's LOD: xy * payload - border + i + 1/2. At the ancestor's
            // LOD, relative to the centre of its texel 0, scaled by `scale`:
            let position = 2 * (xy * payload - border + i) + 1 - scale * (ancestor_xy * payload - border) - scale / 2;
            let (j, fraction) = (position.div_euclid(scale), position.rem_euclid(scale));
            (clamp(j), clamp(j + 1), (scale - fraction) as u64, fraction as u64)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use vortex_vt::page::TextureGrid;

    use super::*;

    fn texture(tile_size: u32, border: u32, pages: u16) -> VirtualTexture {
        let grid = TextureGrid::new(pages.into(), pages.into()).unwrap();
        VirtualTexture { grid, width: 1, height: 1, tile_size, border }
    }

    #[test]
    fn taps_without_border_split_each_ancestor_texel_in_two() {
        // 4-texel tiles, no border, one level up: page x = 1 is the right half of ancestor 0.
        let taps = magnify_taps(&texture(4, 0, 2), 1, 1);
        // Centres 4.5..7.5 at LOD 0 are 2.25..3.75 at LOD 1, i.e. 1.75..3.25 past texel 0's centre.
        assert_eq!(taps, vec![(1, 2, 1, 3), (2, 3, 3, 1), (2, 3, 1, 3), (3, 3, 3, 1)]);
        let weights: Vec<u64> = taps.iter().map(|t| t.2 + t.3).collect();
        assert_eq!(weights, [4, 4, 4, 4]);
    }

    #[test]
    fn taps_stay_inside_the_ancestor_with_borders() {
        for (tile, border) in [(16u32, 2u32), (8, 1), (6, 0), (128, 4)] {
            let t = texture(tile, border, 64);
            for levels_up in 1..=6u8 {
                for xy in 0..64u16 {
                    for (j0, j1, w0, w1) in magnify_taps(&t, xy, levels_up) {
                        assert!(j0 < tile as usize && j1 < tile as usize);
                        assert_eq!(w0 + w1, 1 << (levels_up + 1));
                    }
                }
            }
        }
    }

    #[test]
    fn a_constant_ancestor_magnifies_to_the_same_constant() {
        let t = texture(8, 1, 4);
        let ancestor: Vec<u8> = [10u8, 200, 30, 128].repeat(64);
        for levels_up in 1..=2u8 {
            let out = magnify(&ancestor, &t, PageId::new(0, 0, 3, 1), levels_up);
            assert_eq!(out, ancestor);
        }
    }
}
