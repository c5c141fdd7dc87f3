//! Address translation: where a sample of a virtual texture lands, as a page and a position in
//! that page's payload at one LOD, computed exactly as the shaders do (`vortex-vt-wgpu`'s
//! `shaders/virtual.wgsl`) so that tests can mirror them. Runs on any thread.
//!
//! UV 0..1 spans the real image on both axes, whatever its size: the LOD-0 texel of `u` is
//! `u * width`, and LOD k's is that divided by 2^k (the pyramid is anchored at the top-left, so
//! LOD k texel `c` covers LOD-0 texels `[c 2^k, (c + 1) 2^k)`). The page is the texel position
//! divided by the payload `P`, which need not be a power of two, nor need the image's sides.
//!
//! A single f32 UV cannot address a large texture finely: its resolution is 2^-24 of the
//! texture near u = 1, a sixteenth of a texel at 2^20 texels and a quarter at 2^22. So:
//!
//! - the **2D window** (a viewer's pan and zoom) carries its origin as an integer LOD-0 texel
//!   plus an f32 remainder, and per pixel only adds a small f32 offset; the integer part is
//!   shifted down to the LOD exactly, and split into page and position by integer division.
//!   The error stays a small fraction of a texel at every size a grid can have (2^14 pages of
//!   any payload along an axis; `window_translation_stays_within_a_sixty_fourth...` holds it
//!   under 1/64 texel at 2^20 and 2^22 texels against f64);
//! - **meshes** carry f32 UVs in their vertices, which sets their precision (2^-24 of the
//!   image, 1/16 texel at 2^20 texels). Translating such a UV adds one rounding: `uv * (size /
//!   2^k)` (the scale is exact, an integer times a power of two, for sides up to 2^24 texels) is
//!   one correctly rounded product, off by at most half an ulp of the result, so at most 2^-24
//!   of the side (1/16 texel at 2^20). Dividing by a payload that is not a power of two rounds
//!   again, but only to choose the page: the position in it is the product minus the page's
//!   first texel, exact in f32, and a quotient rounded across a page boundary is corrected by
//!   one page, so page and position always describe the product exactly (`0 <= within < P`).
//!   In all, a mesh sample lands within 2^-23 of the side of where its f64 UV points
//!   (`mesh_translation_is_within_two_ulps_at_2_20_texels`).

use crate::page::MAX_LODS;

/// The largest f32 below 1: keeps u = 1 inside the last page.
pub const BELOW_ONE: f32 = 1.0 - f32::EPSILON / 2.0;

/// A sample's address at one LOD: its page and its position in the page's payload, in texels
/// of that LOD (`0 <= within < payload`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct At {
    /// The page, column and row in that LOD's grid.
    pub page: [u32; 2],
    /// The position in the page's payload, in texels of that LOD.
    pub within: [f32; 2],
}

impl At {
    /// The same sample `levels` LODs coarser: in the ancestor page, at half the position per LOD.
    /// Exact for the page; the position loses nothing but the f32 rounding of one division.
    pub fn ancestor(self, levels: u8, payload: u32) -> At {
        let scale = 1.0 / (1u32 << levels) as f32;
        let mask = (1u32 << levels) - 1;
        let axis = |i: usize| ((self.page[i] & mask) as f32 * payload as f32 + self.within[i]) * scale;
        At { page: [self.page[0] >> levels, self.page[1] >> levels], within: [axis(0), axis(1)] }
    }
}

/// 1 / 2^lod, exact in f32.
fn lod_scale(lod: u8) -> f32 {
    1.0 / (1u32 << lod) as f32
}

/// Splits a texel position of one LOD into page and position in the page's payload. The
/// quotient is rounded (and WGSL's division is not even correctly rounded), so its floor may be
/// one page off near a boundary; the position, computed exactly from that page, shows which
/// way and moves one page back or forth (also exact: both are multiples of the position's ulp
/// well below 2^24 of them).
fn split(p: f32, payload: f32) -> (u32, f32) {
    let mut page = (p / payload).floor();
    let mut within = p - page * payload;
    if within < 0.0 {
        page -= 1.0;
        within += payload;
    } else if within >= payload {
        page += 1.0;
        within -= payload;
    }
    (page as u32, within)
}

/// The address of image UV (`u`, `v`) at `lod` in a texture whose image is `size` texels at
/// LOD 0 (UV 0..1 spans it) cut into pages of `payload` texels: the mesh path. `u` and `v` are
/// clamped to `[0, BELOW_ONE]` first (NaN to 0).
pub fn uv_at(u: f32, v: f32, lod: u8, size: [u32; 2], payload: u32) -> At {
    let axis = |t: f32, n: u32| split(t.clamp(0.0, BELOW_ONE).max(0.0) * (n as f32 * lod_scale(lod)), payload as f32);
    let ((px, wx), (py, wy)) = (axis(u, size[0]), axis(v, size[1]));
    At { page: [px, py], within: [wx, wy] }
}

/// A 2D window onto one virtual texture as the shaders receive it: the LOD-0 texel position of
/// the frame's top-left corner, split into an integer and an f32 part, and the LOD-0 texels per
/// frame pixel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WindowOrigin {
    /// The integer part of the top-left corner's LOD-0 texel position.
    pub int: [u32; 2],
    /// Its fractional part.
    pub frac: [f32; 2],
    /// LOD-0 texels per frame pixel, along x and y.
    pub step: [f32; 2],
}

impl WindowOrigin {
    /// The window whose top-left corner is at LOD-0 texel `origin` and that advances `step`
    /// texels per pixel. A negative origin (a view hanging over the texture's top or left edge)
    /// is kept in the f32 part, where it is small; the integer part stops at `i32::MAX`, which
    /// the shaders' signed arithmetic can still hold (far past any texture's edge).
    pub fn new(origin: [f64; 2], step: [f64; 2]) -> WindowOrigin {
        let split = |o: f64| {
            let int = o.floor().clamp(0.0, i32::MAX as f64);
            (int as u32, (o - int) as f32)
        };
        let ((ix, fx), (iy, fy)) = (split(origin[0]), split(origin[1]));
        WindowOrigin { int: [ix, iy], frac: [fx, fy], step: [step[0] as f32, step[1] as f32] }
    }

    /// The LOD of a window sample: `floor(log2(max(step)) + bias)`, clamped to `[0, lod_count - 1]`
    /// (what `feedback::lod_for` gives for a window's derivatives).
    pub fn lod(&self, bias: f32, lod_count: u8) -> u8 {
        crate::feedback::lod_from_footprint(self.step[0].abs().max(self.step[1].abs()), bias, lod_count)
    }

    /// The address at `lod` of frame position (`x`, `y`) (pixel centres at .5) in a texture whose
    /// image is `size` texels at LOD 0, in pages of `payload` texels; positions beyond the image
    /// clamp to its edges: to texel 0 before it, and just inside its far edge after it (LOD k's
    /// image ends at `size / 2^k`, inside its last texel when the side is not a multiple of 2^k).
    pub fn at(&self, x: f32, y: f32, lod: u8, size: [u32; 2], payload: u32) -> At {
        debug_assert!(lod < MAX_LODS);
        let scale = lod_scale(lod);
        let mask = (1u32 << lod) - 1;
        let axis = |i: usize, p: f32| {
            let rel = self.frac[i] + p * self.step[i];
            let r = ((self.int[i] & mask) as f32 + rel) * scale;
            let fl = r.floor();
            let t = (self.int[i] >> lod) as i64 + fl as i64;
            // The texel holding the image's last LOD-0 texel, and how far into it the image goes.
            let last = ((size[i].max(1) - 1) >> lod) as i64;
            let end = (((size[i].max(1) - 1) & mask) + 1) as f32 * scale * BELOW_ONE;
            let f = r - fl;
            let (t, f) = if t < 0 {
                (0, 0.0)
            } else if t > last || (t == last && f > end) {
                (last, end)
            } else {
                (t, f)
            };
            ((t / payload as i64) as u32, (t % payload as i64) as f32 + f)
        };
        let ((px, wx), (py, wy)) = (axis(0, x), axis(1, y));
        At { page: [px, py], within: [wx, wy] }
    }

    /// Whether frame position (`x`, `y`) lies on an image of `size` LOD-0 texels: `[0, size)` on
    /// each axis. [`WindowOrigin::at`] clamps positions beyond the image to its edges, so a
    /// window that shows more than the image draws its background where this is false (the
    /// shaders' `vt_texel_on_image`, in the same f32 arithmetic).
    pub fn on_image(&self, x: f32, y: f32, size: [u32; 2]) -> bool {
        let axis = |i: usize, p: f32| {
            let at = self.int[i] as i64 + (self.frac[i] + p * self.step[i]).floor() as i64;
            (0..size[i] as i64).contains(&at)
        };
        axis(0, x) && axis(1, y)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// The exact LOD-`lod` texel position of a window sample, in f64.
    fn exact(o: [f64; 2], step: [f64; 2], x: f64, lod: u8) -> f64 {
        (o[0] + x * step[0]) / (1u64 << lod) as f64
    }

    fn texel_of(at: At, payload: u32, axis: usize) -> f64 {
        at.page[axis] as f64 * payload as f64 + at.within[axis] as f64
    }

    #[test]
    fn window_translation_stays_within_a_sixty_fourth_of_a_texel_at_the_largest_sizes() {
        // 2^14 pages of 256-texel payloads (2^22 texels, the widest grid with 264-texel tiles),
        // and 2^20 x 2^10 texels in 120-texel pages (8739 x 9 pages). Non-dyadic origins and
        // steps, non-power-of-two payloads and sizes.
        let mut worst: f64 = 0.0;
        for (size, payload) in [([1u32 << 22, 1000], 256u32), ([1 << 20, 1 << 10], 120), ([4_000_037, 999], 1016)] {
            let side = size[0] as f64;
            for (k, &(ox, step, lod)) in [
                (side * 0.7316514, 0.371, 0u8),
                (side * 0.9999137, 0.913, 0),
                (side * 0.5123417, 1.37, 0),
                (side * 0.3331, 3.1, 1),
                (side * 0.8711, 27.3, 4),
            ]
            .iter()
            .enumerate()
            {
                let w = WindowOrigin::new([ox, 100.25 + k as f64], [step, step]);
                for x in 0..256 {
                    let x = x as f32 + 0.5;
                    let at = w.at(x, 0.5, lod, size, payload);
                    assert!(at.within[0] >= 0.0 && at.within[0] < payload as f32);
                    let want = exact([ox, 0.0], [step, step], x as f64, lod).min(side / (1u64 << lod) as f64);
                    worst = worst.max((texel_of(at, payload, 0) - want).abs());
                }
            }
        }
        assert!(worst < 1.0 / 64.0, "worst error {worst} texels");
    }

    #[test]
    fn one_f32_uv_would_not_be_precise_enough() {
        // Why the window is split: a plain f32 UV at 2^22 texels is off by far more.
        let side = 4096.0 * 1016.0;
        let (o, step) = (side * 0.7316514, 0.371);
        let mut worst: f64 = 0.0;
        for x in 0..256 {
            let u = (o / side) as f32 + (x as f32 + 0.5) * (step / side) as f32;
            let texel = u as f64 * side;
            worst = worst.max((texel - (o + (x as f64 + 0.5) * step)).abs());
        }
        assert!(worst > 1.0 / 16.0, "f32 UVs were precise ({worst})");
    }

    #[test]
    fn windows_clamp_to_the_image_edges() {
        let w = WindowOrigin::new([-50.0, 10.0], [1.0, 1.0]);
        assert_eq!(w.at(0.5, 0.5, 0, [400, 400], 100), At { page: [0, 0], within: [0.0, 10.5] });
        let far = WindowOrigin::new([1e9, 399.0], [1.0, 1.0]);
        assert_eq!(far.at(0.5, 0.5, 0, [400, 400], 100), At { page: [3, 3], within: [99.0 + BELOW_ONE, 99.5] });
        // A 250 x 90 image in 100-texel pages: the third page column is half padding, never
        // reached; at LOD 2 the image ends a half texel into texel 22 (250 / 4 = 62.5).
        let far = WindowOrigin::new([1e6, 1e6], [1.0, 1.0]);
        let at = far.at(0.5, 0.5, 0, [250, 90], 100);
        assert_eq!((at.page, at.within[0]), ([2, 0], 49.0 + BELOW_ONE));
        let at = far.at(0.5, 0.5, 2, [250, 90], 100);
        assert_eq!((at.page, at.within), ([0, 0], [62.0 + 0.5 * BELOW_ONE, 22.0 + 0.5 * BELOW_ONE]));
        // Inside the image nothing is clamped, even in its last, partial texel.
        let edge = WindowOrigin::new([249.0, 0.0], [1.0, 1.0]);
        assert_eq!(edge.at(0.25, 0.5, 2, [250, 90], 100).within[0], 62.3125);
    }

    #[test]
    fn positions_beyond_the_image_are_off_it() {
        // A 200 x 100 image in a 200 x 200 frame at one texel per pixel, centred: 50 rows of
        // background above and below, and the image's first and last rows on it.
        let w = WindowOrigin::new([0.0, -50.0], [1.0, 1.0]);
        let rows: Vec<u32> = (0..200).filter(|y| w.on_image(100.5, *y as f32 + 0.5, [200, 100])).collect();
        assert_eq!(rows, (50..150).collect::<Vec<_>>());
        assert!(!w.on_image(-0.5, 60.5, [200, 100]) && !w.on_image(200.5, 60.5, [200, 100]));
        assert!(w.on_image(0.5, 60.5, [200, 100]) && w.on_image(199.5, 60.5, [200, 100]));
        // Far beyond the right edge, where the integer part carries the position.
        let far = WindowOrigin::new([1e9, 0.0], [1.0, 1.0]);
        assert!(!far.on_image(0.5, 0.5, [1 << 20, 1]));
    }

    #[test]
    fn uv_translation_matches_f64() {
        for &(u, lod, size) in
            &[(0.0f32, 0u8, 1920u32), (0.3, 0, 1920), (0.999, 2, 1920), (1.0, 0, 1000), (0.5, 3, 777)]
        {
            let at = uv_at(u, u, lod, [size, 480], 120);
            let want = (u.min(BELOW_ONE) as f64) * size as f64 / (1u32 << lod) as f64;
            assert!((texel_of(at, 120, 0) - want).abs() < 1e-4, "{u} at LOD {lod}: {at:?}");
            assert!(at.within[0] >= 0.0 && at.within[0] < 120.0);
        }
        // u = 1 is inside the image's last texel, not in the padding after it.
        let at = uv_at(1.0, 1.0, 0, [250, 90], 100);
        assert_eq!(at.page, [2, 0]);
        assert!(at.within[0] < 50.0 && at.within[1] < 90.0);
        assert_eq!(uv_at(f32::NAN, -1.0, 0, [250, 90], 100), At { page: [0, 0], within: [0.0, 0.0] });
    }

    #[test]
    fn mesh_translation_is_within_two_ulps_at_2_20_texels() {
        // 2^20 x 2^10 texels in 120-texel pages, f64 UVs rounded to the f32 a vertex carries:
        // within 2^-23 of the side (1/8 texel) of the exact position, at every LOD.
        let size = [1u32 << 20, 1u32 << 10];
        let mut worst: f64 = 0.0;
        for lod in [0u8, 1, 3, 7] {
            for i in 0..4000u32 {
                let u = 1.0 - (i as f64 * 0.000_731_7 + 1e-7).fract() * 0.3;
                let at = uv_at(u as f32, 0.5, lod, size, 120);
                let exact = u.min(BELOW_ONE as f64) * size[0] as f64 / (1u32 << lod) as f64;
                assert!(at.within[0] >= 0.0 && at.within[0] < 120.0, "{at:?}");
                worst = worst.max((texel_of(at, 120, 0) - exact).abs() * (1u32 << lod) as f64);
            }
        }
        assert!(worst <= size[0] as f64 / (1u32 << 23) as f64, "worst {worst} LOD-0 texels");
        // Every page boundary: the quotient rounds either way, the split does not.
        for page in 0..8739u32 {
            let at = uv_at(((page * 120) as f64 / size[0] as f64) as f32, 0.0, 0, size, 120);
            assert!(at.within[0] >= 0.0 && at.within[0] < 120.0, "{at:?}");
            let got = texel_of(at, 120, 0);
            assert!((got - (page * 120) as f64).abs() <= 1.0 / 16.0, "page {page}: {got}");
        }
    }

    proptest! {
        #[test]
        fn ancestors_address_the_same_point(
            page in (0u32..4096, 0u32..4096),
            within in (0.0f32..119.99, 0.0f32..119.99),
            levels in 0u8..12,
        ) {
            let at = At { page: [page.0, page.1], within: [within.0, within.1] };
            let up = at.ancestor(levels, 120);
            let scale = (1u32 << levels) as f64;
            for i in 0..2 {
                let fine = at.page[i] as f64 * 120.0 + at.within[i] as f64;
                let coarse = up.page[i] as f64 * 120.0 + up.within[i] as f64;
                prop_assert!((fine / scale - coarse).abs() < 1e-3);
                prop_assert!(up.within[i] < 120.0);
            }
        }

        #[test]
        fn window_and_mesh_paths_agree_where_uvs_are_exact(
            px in 0u32..64, lod in 0u8..4, x in 0u32..32,
        ) {
            // A window on whole texels with a dyadic step over a 2048 x 512 image: both paths
            // are exact.
            let (size, payload) = ([2048u32, 512], 120u32);
            let side = size[0] as f64;
            let w = WindowOrigin::new([px as f64 * 16.0, 0.0], [0.25, 0.25]);
            let at = w.at(x as f32 + 0.5, 0.5, lod, size, payload);
            let u = ((px as f64 * 16.0 + (x as f64 + 0.5) * 0.25) / side) as f32;
            let by_uv = uv_at(u, 0.5 * 0.25 / size[1] as f32, lod, size, payload);
            prop_assert_eq!(at.page[0], by_uv.page[0]);
            prop_assert!((at.within[0] - by_uv.within[0]).abs() < 1e-4);
        }

        #[test]
        fn the_page_holds_the_sample(u in 0f32..1.0, w in 1u32..100_000, payload in 1u32..1024, lod in 0u8..10) {
            let at = uv_at(u, u, lod, [w, 7], payload);
            let exact = u as f64 * w as f64 / (1u32 << lod) as f64;
            let page = (exact / payload as f64).floor();
            // The f32 product may cross a boundary the exact position is next to, by an ulp.
            let texel = texel_of(at, payload, 0);
            prop_assert!((texel - exact).abs() <= exact * 2f64.powi(-23) + 1e-9);
            prop_assert!(at.page[0] as f64 == page || (texel - page * payload as f64).abs() < 1e-3 || (texel - (page + 1.0) * payload as f64).abs() < 1e-3);
            prop_assert!(at.within[0] >= 0.0 && at.within[0] < payload as f32);
        }
    }
}
