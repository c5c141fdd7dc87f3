//! The feedback word, and the math a shader uses to choose the LOD a sample wants.
//!
//! The feedback pass renders the scene into a small `R32Uint` buffer, writing per pixel the
//! page it would sample. The word is 32 bits, least significant first:
//!
//! ```text
//!  31    28 27    24 23                                           0
//! +--------+--------+----------------------------------------------+
//! | tex id |  LOD   |     page index: y * pages_per_row(LOD) + x   |
//! +--------+--------+----------------------------------------------+
//!   4 bits   4 bits                     24 bits
//! ```
//!
//! The page is its index in its LOD's grid, row by row, rather than fixed-width x and y fields,
//! so that the 24 bits serve any aspect ratio: a 2^20 x 2^10-texel texture in 120-texel pages
//! has 8739 x 9 pages, which 12-bit x and y fields (4096 pages per side) could not name, and
//! the limit is the area, 2^24 pages at LOD 0 ([`MAX_PAGES_AT_LOD0`], as many as a square
//! 4096 x 4096 grid), whatever the shape. Decoding a page needs its texture's grid (the row
//! width); [`Request::page`] checks the page against it. A WGSL shader produces the word with
//! one multiply-add and shifts: `(y * row + x) | (lod << 24u) | (tex << 28u)`.
//!
//! LOD 15 is "no request": [`decode`] returns `None` for every word whose LOD field is 15,
//! whatever its other bits, so [`NO_REQUEST`] (all ones) can never alias a page. The buffer
//! must be cleared to [`NO_REQUEST`], not to 0: word 0 is page (0, 0) of LOD 0 of texture 0.
//!
//! [`lod_for`] and [`feedback_bias`] mirror the shader so that tests can compare a CPU
//! prediction with what the GPU wrote (the page itself is `address::uv_at`'s or
//! `address::WindowOrigin::at`'s). They use f32, like the shader; within about one ulp of a LOD
//! boundary the two may still disagree (WGSL's `log2` is not correctly rounded).

use crate::page::{MAX_LODS, MAX_PAGES_AT_LOD0, MAX_TEXTURES, PageId, TextureGrid};

/// Bit position of the page index (24 bits).
pub const INDEX_SHIFT: u32 = 0;
/// Bit position of the LOD (4 bits).
pub const LOD_SHIFT: u32 = 24;
/// Bit position of the texture id (4 bits).
pub const TEXTURE_SHIFT: u32 = 28;
/// The page index field.
pub const INDEX_MASK: u32 = (MAX_PAGES_AT_LOD0 - 1) as u32;
const NIBBLE_MASK: u32 = 0xF;
/// The LOD field value that means "no request".
pub const NO_REQUEST_LOD: u8 = 15;
/// The clear value of the feedback buffer: a pixel that wants no page (LOD field 15).
pub const NO_REQUEST: u32 = 0xFFFF_FFFF;

/// The fields of a feedback word that asks for a page: texture id, LOD and page index in that
/// LOD's grid (row by row), not yet checked against any grid.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Request {
    /// The texture id.
    pub texture: u8,
    /// The LOD.
    pub lod: u8,
    /// The page's index in that LOD's grid, row by row.
    pub index: u32,
}

impl Request {
    /// The page asked for, if texture `texture` is in `grids` and the LOD and index are in its
    /// grid.
    pub fn page(self, grids: &[TextureGrid]) -> Option<PageId> {
        grids.get(self.texture as usize)?.page_at_index(self.texture, self.lod, self.index)
    }
}

/// The word of page index `index` of `lod` of texture `texture`. The fields must be within the
/// word's limits (texture < 16, LOD < 15, index < 2^24); this is checked in debug builds only.
pub fn encode_index(texture: u8, lod: u8, index: u32) -> u32 {
    debug_assert!(texture < MAX_TEXTURES, "texture id {texture} out of range");
    debug_assert!(lod < MAX_LODS, "LOD {lod} out of range");
    debug_assert!(index <= INDEX_MASK, "page index {index} out of range");
    (index & INDEX_MASK) << INDEX_SHIFT
        | (lod as u32 & NIBBLE_MASK) << LOD_SHIFT
        | (texture as u32 & NIBBLE_MASK) << TEXTURE_SHIFT
}

/// The feedback word of `page`, a page of `grid` (its texture's); checked in debug builds only.
pub fn encode(page: PageId, grid: &TextureGrid) -> u32 {
    debug_assert!(grid.contains(page), "{page:?} is outside its grid {grid:?}");
    encode_index(page.texture, page.lod, grid.index(page.lod, page.x, page.y))
}

/// The fields of a feedback word, or `None` for "no request" (any word with LOD field 15). The
/// page is not checked against any texture's grid: [`Request::page`] does that.
pub fn decode(word: u32) -> Option<Request> {
    let lod = ((word >> LOD_SHIFT) & NIBBLE_MASK) as u8;
    (lod != NO_REQUEST_LOD).then_some(Request {
        texture: ((word >> TEXTURE_SHIFT) & NIBBLE_MASK) as u8,
        lod,
        index: (word >> INDEX_SHIFT) & INDEX_MASK,
    })
}

/// The LOD a sample wants, from its UV derivatives per pixel (`dpdx = (dudx, dvdx)`,
/// `dpdy = (dudy, dvdy)`), isotropically as GPUs do: the footprint is the longer of the two
/// derivative vectors in texels, and the LOD is `floor(log2(footprint) + bias)` clamped to
/// `[0, lod_count - 1]`. A footprint of exactly 2^k texels gives LOD k (with bias 0); anything
/// below 1 texel, zero or NaN gives LOD 0; infinity gives the coarsest LOD.
///
/// The thesis took the smaller derivative instead; the larger is what the GPU's own isotropic
/// LOD selection does, so the page asked for is the one the filtered sample will read.
///
/// UV spans the image, `texels` (width, height) at LOD 0, so a derivative is scaled per axis
/// into texels: on a 4:1 image a step of 0.01 in u is four times as many texels as in v.
///
/// In WGSL: `let s = uv * vec2<f32>(size); let f = max(length(dpdx(s)), length(dpdy(s)));`
/// `let lod = clamp(floor(log2(f) + bias), 0.0, f32(lod_count - 1u));`.
pub fn lod_for(dudx: f32, dvdx: f32, dudy: f32, dvdy: f32, texels: [f32; 2], bias: f32, lod_count: u8) -> u8 {
    let length = |a: f32, b: f32| {
        let (a, b) = (a * texels[0], b * texels[1]);
        (a * a + b * b).sqrt()
    };
    lod_from_footprint(length(dudx, dvdx).max(length(dudy, dvdy)), bias, lod_count)
}

/// The LOD an anisotropic sample with at most `max_anisotropy` probes wants: the LOD its probes
/// read ([`crate::anisotropy::Probes`]), finer than [`lod_for`]'s by up to `log2(max_anisotropy)`
/// on oblique surfaces. Feedback must ask for this LOD, or the finer pages the probes read would
/// never be loaded. With `max_anisotropy` 1 it is [`lod_for`].
pub fn lod_for_anisotropic(
    ddx: [f32; 2],
    ddy: [f32; 2],
    texels: [f32; 2],
    max_anisotropy: u32,
    bias: f32,
    lod_count: u8,
) -> u8 {
    let probes = crate::anisotropy::Probes::new(ddx, ddy, texels, max_anisotropy);
    lod_from_footprint(probes.footprint, bias, lod_count)
}

/// `floor(log2(footprint) + bias)` clamped to `[0, lod_count - 1]`, for a footprint in LOD-0
/// texels per pixel (what [`lod_for`] computes from derivatives, and a 2D window from its step).
pub fn lod_from_footprint(footprint: f32, bias: f32, lod_count: u8) -> u8 {
    let max_lod = lod_count.saturating_sub(1);
    let lod = (footprint.log2() + bias).floor();
    // NaN (e.g. a zero footprint with an infinite bias) counts as magnified.
    if lod.is_nan() || lod < 0.0 {
        0
    } else if lod >= max_lod as f32 {
        max_lod
    } else {
        lod as u8
    }
}

/// The LOD bias that makes a feedback buffer smaller than the frame ask for the LODs the frame
/// needs: `log2(min(fw / FW, fh / FH))`, to be added to any bias of the frame itself.
///
/// The sign is negative (zero at full resolution): at 1/8 of the frame's size each feedback
/// pixel spans 8 frame pixels, so its UV derivatives are 8 times larger and `lod_for` would
/// answer 3 LODs too coarse; -3 brings it back. With unequal ratios the smaller one (the axis
/// scaled down most) sets the bias, so the feedback never asks coarser than the frame needs.
pub fn feedback_bias(feedback_w: u32, feedback_h: u32, frame_w: u32, frame_h: u32) -> f32 {
    let rx = feedback_w as f32 / frame_w as f32;
    let ry = feedback_h as f32 / frame_h as f32;
    rx.min(ry).log2()
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn golden_bit_layout() {
        let g = TextureGrid::new(8739, 9).unwrap();
        let p = |tex, lod, x, y| encode(PageId::new(tex, lod, x, y), &g);
        assert_eq!(p(0, 0, 0, 0), 0);
        assert_eq!(p(0, 0, 1, 0), 0x0000_0001);
        assert_eq!(p(0, 0, 0, 1), 8739);
        assert_eq!(p(0, 1, 0, 1), 0x0100_0000 | 4370);
        assert_eq!(p(1, 0, 0, 0), 0x1000_0000);
        assert_eq!(p(0xA, 0, 8738, 8), 0xA000_0000 | (8 * 8739 + 8738));
        assert_eq!(encode_index(15, 14, INDEX_MASK), 0xFEFF_FFFF);
        assert_eq!(encode_index(0xA, 3, 0x45_6123), 0xA345_6123);
        assert_eq!(decode(0xA345_6123), Some(Request { texture: 0xA, lod: 3, index: 0x45_6123 }));
        // The WGSL expression in the module doc, written out.
        let (x, y, row, lod, tex) = (0x123u32, 0x45u32, 8739u32, 3u32, 0xAu32);
        assert_eq!((y * row + x) | (lod << 24) | (tex << 28), encode_index(0xA, 3, 0x45 * 8739 + 0x123));
    }

    #[test]
    fn requests_are_checked_against_their_grid() {
        let grids = [TextureGrid::new(8739, 9).unwrap(), TextureGrid::new(3, 1).unwrap()];
        let page = PageId::new(0, 0, 8738, 8);
        assert_eq!(decode(encode(page, &grids[0])).and_then(|r| r.page(&grids)), Some(page));
        let r = |texture, lod, index| Request { texture, lod, index };
        assert_eq!(r(0, 0, 8739 * 9).page(&grids), None, "past the last row");
        assert_eq!(r(1, 0, 2).page(&grids), Some(PageId::new(1, 0, 2, 0)));
        assert_eq!(r(1, 0, 3).page(&grids), None, "the next row of a one-row grid");
        assert_eq!(r(1, 2, 0).page(&grids), Some(PageId::new(1, 2, 0, 0)), "the root of 3, 2, 1 pages");
        assert_eq!(r(1, 3, 0).page(&grids), None, "LOD past the root");
        assert_eq!(r(2, 0, 0).page(&grids), None, "unknown texture");
    }

    #[test]
    fn anisotropic_feedback_asks_for_the_finer_lod() {
        let texels = [1024.0, 1024.0];
        // 32 texels per pixel along x, 4 along y: isotropic LOD 5, 8x anisotropic LOD 2.
        let (ddx, ddy) = ([32.0 / 1024.0, 0.0], [0.0, 4.0 / 1024.0]);
        assert_eq!(lod_for(ddx[0], ddx[1], ddy[0], ddy[1], texels, 0.0, 11), 5);
        let lods: Vec<u8> =
            [1, 2, 4, 8, 16].iter().map(|&n| lod_for_anisotropic(ddx, ddy, texels, n, 0.0, 11)).collect();
        assert_eq!(lods, [5, 4, 3, 2, 2], "never finer than the minor axis");
        assert_eq!(lod_for_anisotropic(ddx, ddy, texels, 8, -1.0, 11), 1, "the bias applies");
        assert_eq!(lod_for_anisotropic(ddx, ddy, texels, 8, 0.0, 2), 1, "clamped to the chain");
    }

    #[test]
    fn lod_15_is_never_a_page() {
        assert_eq!(decode(NO_REQUEST), None);
        assert_eq!(NO_REQUEST >> LOD_SHIFT & 0xF, NO_REQUEST_LOD as u32);
        // Every word with LOD field 15: 4 texture bits x 24 coordinate bits, sampled densely.
        for tex in 0..16u32 {
            for xy in (0..1u32 << 24).step_by(4093).chain([0xFF_FFFF]) {
                assert_eq!(decode(tex << 28 | 15 << 24 | xy), None);
            }
        }
    }

    #[test]
    fn every_lod_below_15_decodes() {
        for lod in 0..15u32 {
            assert_eq!(decode(lod << 24).map(|r| r.lod), Some(lod as u8));
        }
    }

    proptest! {
        #[test]
        fn round_trip_of_valid_pages(
            tex in 0u8..16, w in 1u32..=16384, h in 1u32..=1024, lod in 0u8..15, x in any::<u16>(), y in any::<u16>(),
        ) {
            let g = TextureGrid::new(w, h).unwrap();
            let lod = lod % g.lod_count();
            let [pw, ph] = g.pages_at(lod);
            let p = PageId::new(tex, lod, x % pw, y % ph);
            let mut grids = vec![g; 16];
            grids[tex as usize] = g;
            prop_assert_eq!(decode(encode(p, &g)).and_then(|r| r.page(&grids)), Some(p));
        }

        #[test]
        fn words_with_lod_15_decode_to_none(word in any::<u32>()) {
            let w = word | 15 << LOD_SHIFT;
            prop_assert_eq!(decode(w), None);
        }

        #[test]
        fn decode_then_encode_is_identity(word in any::<u32>()) {
            if let Some(r) = decode(word) {
                prop_assert_eq!(encode_index(r.texture, r.lod, r.index), word);
            }
        }

        #[test]
        fn lod_is_monotonic_in_the_footprint(a in 1e-9f32..10.0, b in 1e-9f32..10.0) {
            let (lo, hi) = if a <= b { (a, b) } else { (b, a) };
            let l = |f: f32| lod_for(f / 65536.0, 0.0, 0.0, 0.0, [65536.0; 2], 0.0, 17);
            prop_assert!(l(lo) <= l(hi));
        }
    }

    /// The LOD of a footprint of `texels` along u, on a 65536-texel texture with 17 LODs.
    fn lod_of(texels: f32) -> u8 {
        lod_for(texels / 65536.0, 0.0, 0.0, 0.0, [65536.0; 2], 0.0, 17)
    }

    #[test]
    fn powers_of_two_are_exact() {
        for k in 0..17 {
            let f = (k as f32).exp2();
            assert_eq!(lod_of(f), k as u8, "2^{k}");
            // The same footprint along v, along a diagonal of the y derivative, or split
            // between x and y derivatives (the larger one counts).
            assert_eq!(lod_for(0.0, f / 65536.0, 0.0, 0.0, [65536.0; 2], 0.0, 17), k as u8);
            assert_eq!(lod_for(0.0, 0.0, 0.0, f / 65536.0, [65536.0; 2], 0.0, 17), k as u8);
            assert_eq!(lod_for(f / 131072.0, 0.0, 0.0, f / 65536.0, [65536.0; 2], 0.0, 17), k as u8);
            if k > 0 {
                assert_eq!(lod_of(f * 0.999), k as u8 - 1, "just below 2^{k}");
            }
            assert_eq!(lod_of(f * 1.001), k as u8, "just above 2^{k}");
            assert_eq!(lod_of(f * 1.999), k.min(16) as u8, "just below 2^{}", k + 1);
        }
        // A 3-4-5 triangle: footprint 5 texels, LOD 2.
        assert_eq!(lod_for(3.0, 4.0, 0.0, 0.0, [1.0; 2], 0.0, 10), 2);
        // Bias moves by whole LODs, and half a LOD of bias rounds by the usual floor.
        assert_eq!(lod_for(4.0, 0.0, 0.0, 0.0, [1.0; 2], 1.0, 10), 3);
        assert_eq!(lod_for(4.0, 0.0, 0.0, 0.0, [1.0; 2], -1.0, 10), 1);
        assert_eq!(lod_for(4.0, 0.0, 0.0, 0.0, [1.0; 2], 0.5, 10), 2);
        assert_eq!(lod_for(4.0, 0.0, 0.0, 0.0, [1.0; 2], -0.5, 10), 1);
    }

    #[test]
    fn derivatives_scale_per_axis_on_rectangular_images() {
        // A 4:1 image of 4096 x 1024 texels: the same UV step is 4x the texels along u.
        assert_eq!(lod_for(1.0 / 256.0, 0.0, 0.0, 0.0, [4096.0, 1024.0], 0.0, 13), 4);
        assert_eq!(lod_for(0.0, 1.0 / 256.0, 0.0, 0.0, [4096.0, 1024.0], 0.0, 13), 2);
        // Square pixels over it: u steps 1/4096 and v steps 1/1024 per pixel are one texel each.
        assert_eq!(lod_for(1.0 / 4096.0, 0.0, 0.0, 1.0 / 1024.0, [4096.0, 1024.0], 0.0, 13), 0);
        assert_eq!(lod_for(8.0 / 4096.0, 0.0, 0.0, 8.0 / 1024.0, [4096.0, 1024.0], 0.0, 13), 3);
    }

    #[test]
    fn lod_is_clamped() {
        assert_eq!(lod_of(0.5), 0, "magnified");
        assert_eq!(lod_of(1e-30), 0);
        assert_eq!(lod_for(0.0, 0.0, 0.0, 0.0, [65536.0; 2], 0.0, 17), 0, "zero footprint");
        assert_eq!(lod_for(f32::NAN, 0.0, 0.0, 0.0, [65536.0; 2], 0.0, 17), 0, "NaN");
        assert_eq!(lod_for(0.0, 0.0, 0.0, 0.0, [65536.0; 2], f32::INFINITY, 17), 0, "-inf + inf");
        assert_eq!(lod_of(65536.0 * 4.0), 16, "beyond the coarsest");
        assert_eq!(lod_for(f32::INFINITY, 0.0, 0.0, 0.0, [65536.0; 2], 0.0, 17), 16);
        assert_eq!(lod_for(1.0, 0.0, 0.0, 0.0, [8.0; 2], 0.0, 3), 2, "8 texels, 3 LODs");
        assert_eq!(lod_for(1.0, 0.0, 0.0, 0.0, [8.0; 2], 0.0, 1), 0, "one LOD");
        assert_eq!(lod_for(1.0, 0.0, 0.0, 0.0, [8.0; 2], -100.0, 4), 0, "big negative bias");
    }

    #[test]
    fn feedback_bias_is_negative_for_a_smaller_buffer() {
        assert_eq!(feedback_bias(1280, 720, 1280, 720), 0.0);
        assert_eq!(feedback_bias(160, 90, 1280, 720), -3.0);
        assert_eq!(feedback_bias(320, 180, 1280, 720), -2.0);
        // Unequal ratios: the axis scaled down most sets the bias.
        assert_eq!(feedback_bias(160, 180, 1280, 720), -3.0);
        assert!((feedback_bias(128, 72, 1280, 720) - (0.1f32).log2()).abs() < 1e-6);
        // The point of it: a feedback pixel at 1/8 size has 8x the derivatives, and with the
        // bias it asks for the same LOD as the frame pixel.
        for k in 0..14 {
            let d = (k as f32).exp2() / 65536.0 * 1.3;
            let frame = lod_for(d, 0.0, 0.0, d, [65536.0; 2], 0.0, 17);
            let fb = lod_for(8.0 * d, 0.0, 0.0, 8.0 * d, [65536.0; 2], feedback_bias(160, 90, 1280, 720), 17);
            assert_eq!(fb, frame, "2^{k} * 1.3 texels");
            assert_eq!(lod_for(8.0 * d, 0.0, 0.0, 8.0 * d, [65536.0; 2], 0.0, 17), (frame + 3).min(16));
        }
    }
}
