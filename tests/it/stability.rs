//! Numerical stability of the pyramid over deep cascades, with exact bounds, for every LOD
//! filter (`--filter`).
//!
//! What "exact" means per filter: `box` is the mean of the stored values of the real source
//! pixels under a texel, rounded once, halves up. `linear` is the same mean taken of the
//! fixed-point linear-light decodes (`SrgbTable`), rounded once to a fixed-point value and
//! encoded to the nearest code. `premultiplied` divides the alpha-weighted colour sum by the
//! alpha sum, rounded once, halves up (0 where the alpha sum is 0). `lanczos3` and `mitchell`
//! resample each level from the rounded previous one and are not exact means: their bounds
//! below are what the kernels give, measured and then fixed as limits.

use crate::common;
use vortex_tiler::layout::{Layout, MAX_SIDE};
use vortex_tiler::pixel::{Channels, Depth, PixelLayout, Sample};
use vortex_tiler::pyramid::Filter;
use vortex_tiler::testing::{
    Acc, ExactFilter, ExactRow, Reducer, Resampler, SrgbTable, linear_to_srgb, srgb_to_linear, sums_need_u128,
};

const EXACT: [Filter; 4] = [Filter::Box, Filter::Linear, Filter::Premultiplied, Filter::LinearPremultiplied];
const ALL: [Filter; 6] = Filter::ALL;

/// One level: width, height, samples (row-major, interleaved channels).
type Level<T> = (usize, usize, Vec<T>);

/// Levels 1..=`levels` of a `w x h` image in `layout` made with `filter`, as the pipeline
/// makes them (same reducers, filters and resamplers, without the tiling around them).
fn pyramid<T: Sample>(
    src: &[T],
    w: usize,
    h: usize,
    layout: PixelLayout,
    filter: Filter,
    levels: u32,
) -> Vec<Level<T>> {
    if !filter.is_exact() {
        return resampled(src, w, h, layout, filter, levels);
    }
    let deepest = Layout::new(w as u64, h as u64, 8, 0).unwrap().lod_count.max(levels + 1);
    match ExactFilter::new(filter, layout) {
        Some(f) if f.needs_u128(deepest) => exact::<T, T::Wide>(src, w, h, layout, Some(f), levels),
        f => exact::<T, T::Narrow>(src, w, h, layout, f, levels),
    }
}

fn exact<T: Sample + Into<A>, A: Acc>(
    src: &[T],
    w: usize,
    h: usize,
    layout: PixelLayout,
    filter: Option<ExactFilter>,
    levels: u32,
) -> Vec<Level<T>> {
    let c = layout.channels.count();
    let (mut width, mut out) = (w, Vec::new());
    let mut rows: Vec<Vec<A>> = Vec::new();
    for lod in 0..levels {
        let mut red = Reducer::<A>::new(w as u64, h as u64, lod, width, c);
        let (mut next, mut rounded) = (Vec::new(), Vec::new());
        let mut take = |e: ExactRow<A>| {
            let mut o = vec![T::default(); e.sums.len()];
            match &filter {
                Some(f) => f.finish(&e, &mut o),
                None => e.round_into(&mut o),
            }
            rounded.extend_from_slice(&o);
            next.push(e.sums.to_vec());
        };
        if lod == 0 {
            // The source rows go in as the pipeline gives them (`Pyramid::push_source_row`).
            let mut scratch = vec![0u64; w * c];
            for r in src.chunks(w * c) {
                let e = match &filter {
                    Some(f) => f.push_row(&mut red, r, &mut scratch),
                    None => red.push(r),
                };
                if let Some(e) = e {
                    take(e);
                }
            }
        } else {
            for r in &rows {
                if let Some(e) = red.push(r) {
                    take(e);
                }
            }
        }
        if let Some(e) = red.finish() {
            take(e);
        }
        width = red.out_width();
        out.push((width, next.len(), rounded));
        rows = next;
    }
    out
}

fn resampled<T: Sample>(
    src: &[T],
    w: usize,
    h: usize,
    layout: PixelLayout,
    filter: Filter,
    levels: u32,
) -> Vec<Level<T>> {
    let c = layout.channels.count();
    let (mut level, mut width, mut height, mut out) = (src.to_vec(), w, h, Vec::new());
    for _ in 0..levels {
        let mut r = Resampler::<T>::new(filter, layout, width, height as u64);
        let mut next = Vec::new();
        for row in level.chunks_exact(width * c) {
            if let Some(rows) = r.push(row).unwrap() {
                next.extend_from_slice(rows);
            }
        }
        (width, height) = (width.div_ceil(2), height.div_ceil(2));
        assert_eq!(next.len(), width * height * c);
        out.push((width, height, next.clone()));
        level = next;
    }
    out
}

fn grey<T>() -> PixelLayout
where
    T: Sample,
{
    PixelLayout::new(Channels::Grey, T::DEPTH)
}

fn mean<T: Sample>(v: &[T]) -> f64 {
    v.iter().map(|s| s.to_u64() as f64).sum::<f64>() / v.len() as f64
}

/// Mean in linear light (exact decode) of codes of `max`.
fn linear_mean<T: Sample>(v: &[T]) -> f64 {
    let max = T::MAX as f64;
    v.iter().map(|s| srgb_to_linear(s.to_u64() as f64 / max)).sum::<f64>() / v.len() as f64
}

fn noise<T: Sample>(n: usize, seed: u64) -> Vec<T> {
    let img = common::Image::random(n as u32, 1, grey::<T>(), seed);
    img.samples.iter().map(|s| T::from_u16(*s)).collect()
}

// ---------------------------------------------------------------------------------------------
// Means over 16 levels

#[test]
fn sixteen_levels_keep_the_mean_within_half_a_code_value() {
    // 2^16 x 4 so that every texel of every level has the same number of real pixels under it
    // (the plain mean of a level is then the image mean plus rounding), down to one texel.
    let (w, h) = (1usize << 16, 4usize);
    let src8: Vec<u8> = noise(w * h, 1);
    let src16: Vec<u16> = noise(w * h, 2);
    // Box (and premultiplied, which is box without alpha): the mean of the stored values.
    for filter in [Filter::Box, Filter::Premultiplied] {
        let (m8, m16) = (mean(&src8), mean(&src16));
        let levels = pyramid(&src8, w, h, grey::<u8>(), filter, 16);
        assert_eq!(levels.last().unwrap().2.len(), 1);
        for (lod, (_, _, t)) in levels.iter().enumerate() {
            assert!((mean(t) - m8).abs() <= 0.5, "{filter} LOD {}: mean {} vs source {m8}", lod + 1, mean(t));
        }
        for (lod, (_, _, t)) in pyramid(&src16, w, h, grey::<u16>(), filter, 16).iter().enumerate() {
            assert!((mean(t) - m16).abs() <= 0.5, "{filter} 16-bit LOD {}: mean {} vs {m16}", lod + 1, mean(t));
        }
    }
    // Linear light: the mean light, expressed as the code it encodes to, within half a code.
    for filter in [Filter::Linear, Filter::LinearPremultiplied] {
        let want = linear_to_srgb(linear_mean(&src8)) * 255.0;
        for (lod, (_, _, t)) in pyramid(&src8, w, h, grey::<u8>(), filter, 16).iter().enumerate() {
            let got = linear_to_srgb(linear_mean(t)) * 255.0;
            assert!((got - want).abs() <= 0.5, "{filter} LOD {}: mean light {got} vs {want}", lod + 1);
        }
        let want = linear_to_srgb(linear_mean(&src16)) * 65535.0;
        for (lod, (_, _, t)) in pyramid(&src16, w, h, grey::<u16>(), filter, 16).iter().enumerate() {
            let got = linear_to_srgb(linear_mean(t)) * 65535.0;
            assert!((got - want).abs() <= 0.5, "{filter} 16-bit LOD {}: mean light {got} vs {want}", lod + 1);
        }
    }
}

#[test]
fn resampling_filters_keep_the_mean_within_their_bounds() {
    // Each level is resampled from the rounded one before, and near the ends of narrow levels
    // the cut, renormalised kernel weighs texels unevenly: measured 0.73 of a code value at 8
    // bits and 10.6 at 16 bits over 16 levels. The bounds are 1/255 and 16/65535 of full scale.
    let (w, h) = (1usize << 16, 4usize);
    let (src8, src16): (Vec<u8>, Vec<u16>) = (noise(w * h, 1), noise(w * h, 2));
    for filter in [Filter::Lanczos3, Filter::Mitchell] {
        let m = mean(&src8);
        for (lod, (_, _, t)) in pyramid(&src8, w, h, grey::<u8>(), filter, 16).iter().enumerate() {
            assert!((mean(t) - m).abs() <= 1.0, "{filter} LOD {}: mean {} vs {m}", lod + 1, mean(t));
        }
        let m = mean(&src16);
        for (lod, (_, _, t)) in pyramid(&src16, w, h, grey::<u16>(), filter, 16).iter().enumerate() {
            assert!((mean(t) - m).abs() <= 16.0, "{filter} 16-bit LOD {}: mean {} vs {m}", lod + 1, mean(t));
        }
    }
}

#[test]
fn premultiplied_with_uniform_alpha_is_box() {
    // colour = round(sum(c * a) / sum(a)) = round(sum(c) / n) when every a is the same.
    let (w, h) = (45, 30);
    let img = common::Image::random(w as u32, h as u32, PixelLayout::new(Channels::Rgba, Depth::U8), 5);
    for a in [1u8, 128, 255] {
        let src: Vec<u8> = img.samples.chunks(4).flat_map(|p| [p[0] as u8, p[1] as u8, p[2] as u8, a]).collect();
        let layout = PixelLayout::new(Channels::Rgba, Depth::U8);
        let want = pyramid(&src, w, h, layout, Filter::Box, 6);
        assert_eq!(pyramid(&src, w, h, layout, Filter::Premultiplied, 6), want, "alpha {a}");
    }
    let img = common::Image::random(w as u32, h as u32, PixelLayout::new(Channels::GreyAlpha, Depth::U16), 6);
    for a in [1u16, 65535] {
        let src: Vec<u16> = img.samples.chunks(2).flat_map(|p| [p[0], a]).collect();
        let layout = PixelLayout::new(Channels::GreyAlpha, Depth::U16);
        let want = pyramid(&src, w, h, layout, Filter::Box, 6);
        assert_eq!(pyramid(&src, w, h, layout, Filter::Premultiplied, 6), want, "16-bit alpha {a}");
    }
}

// ---------------------------------------------------------------------------------------------
// Constant images and the checkerboard

#[test]
fn constant_images_stay_exactly_constant_at_every_level() {
    for filter in ALL {
        for (w, h) in [(1usize, 1usize), (1000, 3), (3, 1000), (257, 129), (1 << 16, 2)] {
            let levels = (usize::BITS - w.max(h).leading_zeros()) + 1;
            for v in [0u8, 1, 127, 128, 254, 255] {
                for (lod, (_, _, t)) in pyramid(&vec![v; w * h], w, h, grey::<u8>(), filter, levels).iter().enumerate()
                {
                    assert!(t.iter().all(|x| *x == v), "{filter} {w}x{h} value {v} LOD {}", lod + 1);
                }
            }
            for v in [1u16, 32768, 65534, 65535] {
                for (lod, (_, _, t)) in pyramid(&vec![v; w * h], w, h, grey::<u16>(), filter, levels).iter().enumerate()
                {
                    assert!(t.iter().all(|x| *x == v), "{filter} 16-bit {w}x{h} value {v} LOD {}", lod + 1);
                }
            }
        }
        // With alpha: any colour, any visible alpha, stays exactly as it is.
        let (w, h) = (37, 21);
        for px in [[200u8, 100, 50, 255], [3, 250, 128, 1], [0, 0, 0, 77]] {
            let src: Vec<u8> = px.iter().copied().cycle().take(w * h * 4).collect();
            let layout = PixelLayout::new(Channels::Rgba, Depth::U8);
            for (lod, (_, _, t)) in pyramid(&src, w, h, layout, filter, 6).iter().enumerate() {
                assert!(t.chunks(4).all(|x| x == px), "{filter} {px:?} LOD {}: {:?}", lod + 1, &t[..4]);
            }
        }
    }
}

#[test]
fn one_texel_checkerboard_is_exact_mid_grey_at_lod_one() {
    // box: (0 + 255 + 255 + 0) / 4 = 127.5, rounded half up, once: 128 (16-bit: 32767.5 -> 32768).
    // linear: half the light, encoded: round(255 * srgb(0.5)) = round(187.516) = 188
    // (16-bit: round(48191.62) = 48192).
    let mid = |max: f64| (linear_to_srgb(0.5) * max).round() as u16;
    assert_eq!((mid(255.0), mid(65535.0)), (188, 48192));
    for (w, h) in [(64usize, 64usize), (10, 6), (2, 2), (3, 5)] {
        let src: Vec<u8> = (0..w * h).map(|i| if (i % w + i / w) % 2 == 0 { 0 } else { 255 }).collect();
        let src16: Vec<u16> = src.iter().map(|v| *v as u16 * 257).collect();
        for (filter, want8, want16) in [
            (Filter::Box, 128, 32768),
            (Filter::Premultiplied, 128, 32768),
            (Filter::Linear, mid(255.0), mid(65535.0)),
            (Filter::LinearPremultiplied, mid(255.0), mid(65535.0)),
        ] {
            if w % 2 == 1 || h % 2 == 1 {
                // Odd sizes: edge texels cover 1 or 2 pixels; only full 2x2 footprints are mid-grey.
                let (ow, _, l1) = &pyramid(&src, w, h, grey::<u8>(), filter, 1)[0];
                for (i, v) in l1.iter().enumerate() {
                    if 2 * (i % ow) + 1 < w && 2 * (i / ow) + 1 < h {
                        assert_eq!(*v as u16, want8, "{filter} {w}x{h} texel {i}");
                    }
                }
                continue;
            }
            let l1 = &pyramid(&src, w, h, grey::<u8>(), filter, 1)[0].2;
            assert!(l1.iter().all(|v| *v as u16 == want8), "{filter} {w}x{h}: {l1:?}");
            let l1 = &pyramid(&src16, w, h, grey::<u16>(), filter, 1)[0].2;
            assert!(l1.iter().all(|v| *v == want16), "{filter} 16-bit {w}x{h}: {l1:?}");
        }
    }
}

#[test]
fn resampled_checkerboard_is_mid_grey_away_from_the_edges() {
    // The kernels are symmetric about a texel's centre, which lies between a black and a
    // white column, so away from the edges (where the kernel is cut and renormalised) a texel
    // is 127.5 up to the resizer's fixed-point rounding: 127 or 128 (16-bit: within 2 of
    // 32767.5). At the edges lanczos3 measured 124..131.
    let (w, h) = (64usize, 64usize);
    let src: Vec<u8> = (0..w * h).map(|i| if (i % w + i / w) % 2 == 0 { 0 } else { 255 }).collect();
    let src16: Vec<u16> = src.iter().map(|v| *v as u16 * 257).collect();
    for filter in [Filter::Lanczos3, Filter::Mitchell] {
        let interior = |i: usize| (3..w / 2 - 3).contains(&(i % (w / 2))) && (3..h / 2 - 3).contains(&(i / (w / 2)));
        let l1 = &pyramid(&src, w, h, grey::<u8>(), filter, 1)[0].2;
        for (i, v) in l1.iter().enumerate() {
            assert!(!interior(i) || (127..=128).contains(v), "{filter} texel {i}: {v}");
            assert!((120..=135).contains(v), "{filter} edge texel {i}: {v}");
        }
        let l1 = &pyramid(&src16, w, h, grey::<u16>(), filter, 1)[0].2;
        for (i, v) in l1.iter().enumerate() {
            assert!(!interior(i) || (*v as f64 - 32767.5).abs() <= 2.0, "{filter} 16-bit texel {i}: {v}");
        }
    }
}

// ---------------------------------------------------------------------------------------------
// 16-bit sources

#[test]
fn sixteen_bit_extremes_do_not_overflow() {
    // Sums of 4^16 samples of 65535 need 48 bits; a u32 accumulator would wrap at level 8.
    let (w, h) = (1usize << 16, 2usize);
    let mut src = vec![65535u16; w * h];
    src[0] = 0;
    let levels = pyramid(&src, w, h, grey::<u16>(), Filter::Box, 16);
    // One zero among 131072 samples of 65535: the mean is 65534.5 -> 65535 (halves round up).
    assert_eq!(levels.last().unwrap().2, vec![65535]);
    // All-65535 RGBA at depth, every filter: every level stays 65535.
    let rgba = PixelLayout::new(Channels::Rgba, Depth::U16);
    for filter in ALL {
        let src = vec![65535u16; w * h * 4];
        for (lod, (_, _, t)) in pyramid(&src, w, h, rgba, filter, 16).iter().enumerate() {
            assert!(t.iter().all(|v| *v == 65535), "{filter} LOD {}", lod + 1);
        }
    }
}

#[test]
fn deepest_sums_fit_their_accumulator() {
    // The largest sums any pyramid can hold: the coarsest texel of a MAX_SIDE image in
    // 8-texel tiles with a 2-texel border covers 4^22 pixels. Feed a reducer the level above
    // it, every pixel at the largest value: a u64 sum would wrap for the filters that
    // ExactFilter puts in u128 (overflow panics in tests).
    let layout = Layout::new(MAX_SIDE, MAX_SIDE, 8, 2).unwrap();
    assert_eq!(layout.lod_count, 23);
    assert!(!sums_need_u128(65535, 23), "box sums always fit a u64");
    for depth in [Depth::U8, Depth::U16] {
        for filter in EXACT {
            let pixels = PixelLayout::new(Channels::Rgba, depth);
            let max = pixels.depth.bytes() as u32 * 8;
            let max = ((1u32 << max) - 1) as u16;
            let Some(f) = ExactFilter::new(filter, pixels) else { continue };
            let mut one = [0u64; 4];
            f.prepare(&[max; 4], &mut one);
            let wide = f.needs_u128(layout.lod_count);
            assert_eq!(
                wide,
                sums_need_u128(one[0], 23),
                "{filter} {depth:?}: u128 exactly when its value {} overflows",
                one[0]
            );
            if wide {
                deepest::<u128>(&one, max, filter, pixels);
            } else {
                deepest::<u64>(&one, max, filter, pixels);
            }
        }
    }
}

fn deepest<A: Acc>(one: &[u64; 4], max: u16, filter: Filter, pixels: PixelLayout) {
    // LOD 21 of a MAX_SIDE image is 8 texels wide, each the sum of 4^21 pixels.
    let mut red = Reducer::<A>::new(MAX_SIDE, MAX_SIDE, 21, 8, 4);
    let times_4_21 = |v: u64| (0..42).fold(A::from(v), |s, _| s + s);
    let row: Vec<A> = (0..8).flat_map(|_| one.iter().map(|v| times_4_21(*v))).collect();
    assert!(red.push(&row).is_none());
    let e = red.push(&row).unwrap();
    let f = ExactFilter::new(filter, pixels).unwrap();
    let mut out = vec![0u16; 16];
    f.finish(&e, &mut out);
    assert!(out.iter().all(|v| *v == max), "{filter}: {out:?}");
}

#[test]
fn sixteen_bit_means_are_exact_to_the_stated_rounding() {
    // Every level of random 16-bit images, every layout, against the footprint definition.
    for (i, layout) in common::layouts().into_iter().filter(|l| l.depth == Depth::U16).enumerate() {
        let img = common::Image::random(45, 23, layout, 40 + i as u64);
        for filter in EXACT {
            let got = pyramid(&img.samples, 45, 23, layout, filter, 6);
            for (lod, (w, h, t)) in got.iter().enumerate() {
                let (nw, nh, want) = common::naive_level_filtered(&img, lod as u32 + 1, filter);
                assert_eq!((*w, *h), (nw as usize, nh as usize));
                assert_eq!(t, &want, "{filter} {layout} LOD {}", lod + 1);
            }
        }
    }
}

#[test]
fn sixteen_bit_to_eight_bit_rounds_to_nearest() {
    use vortex_tiler::background::Background;
    use vortex_tiler::split::SplitOptions;
    // Values around every rounding boundary of v / 257: 128 -> 0 (0.498), 129 -> 1 (0.502).
    let mut values: Vec<u16> = vec![0, 128, 129, 385, 386, 32767, 32768, 32896, 65407, 65408, 65535];
    values.extend(
        (0..=255u32)
            .flat_map(|c| [c * 257, (c * 257 + 128).min(65535), (c * 257).saturating_sub(129)])
            .map(|v| v as u16),
    );
    let (w, h) = (64u32, values.len().div_ceil(64) as u32);
    let n = (w * h) as usize;
    let samples: Vec<u16> = values.iter().copied().cycle().take(n).collect();
    let img = common::Image { width: w, height: h, layout: PixelLayout::new(Channels::Grey, Depth::U16), samples };
    let opts = SplitOptions { tile_depth: Some(Depth::U8), ..common::png_options(16, 0, Background::Edge) };
    let (_, tiles) = common::run_pipeline(&img, &opts, 2);
    // Texel (x, y) of a level, from its 16-texel tiles (no border).
    let at = |lod: u32, x: usize, y: usize| tiles[&(lod, x as u32 / 16, y as u32 / 16)][(y % 16) * 16 + x % 16] as f64;
    for (i, v) in img.samples.iter().enumerate() {
        let (x, y) = (i % w as usize, i / w as usize);
        assert_eq!(at(0, x, y), (*v as f64 / 257.0).round(), "{v} -> {}", at(0, x, y));
    }
    // Coarser levels are rounded to 16 bits first, then to 8: that is the 8-bit rounding of
    // the 16-bit texel, within 0.5 + 0.5/257 of the exact mean.
    for lod in 1..3 {
        let (lw, lh, texels) = common::naive_level(&img, lod);
        let (_, _, means) = mean_level(&img, lod);
        for y in 0..lh as usize {
            for x in 0..lw as usize {
                let (got, m) = (at(lod, x, y), means[y * lw as usize + x] / 257.0);
                assert!((got - m).abs() <= 0.5 + 0.5 / 257.0 + 1e-9, "LOD {lod} ({x}, {y}): {got} vs {m}");
                assert_eq!(got, (texels[y * lw as usize + x] as f64 / 257.0).round());
            }
        }
    }
}

/// Unrounded footprint means of a grey image.
fn mean_level(img: &common::Image, lod: u32) -> (u32, u32, Vec<f64>) {
    let f = 1usize << lod;
    let (w, h) = (img.width as usize, img.height as usize);
    let (lw, lh) = (w.div_ceil(f), h.div_ceil(f));
    let mut out = Vec::new();
    for y in 0..lh {
        for x in 0..lw {
            let px: Vec<f64> = (y * f..((y + 1) * f).min(h))
                .flat_map(|sy| (x * f..((x + 1) * f).min(w)).map(move |sx| img.samples[sy * w + sx] as f64))
                .collect();
            out.push(px.iter().sum::<f64>() / px.len() as f64);
        }
    }
    (lw as u32, lh as u32, out)
}

// ---------------------------------------------------------------------------------------------
// Alpha

/// An RGBA8 image: opaque `colour` left of column `edge`, fully transparent garbage right of it.
fn half_transparent(w: usize, h: usize, edge: usize, colour: [u8; 3]) -> Vec<u8> {
    let garbage: Vec<u8> = noise(w * h * 3, 9);
    (0..w * h)
        .flat_map(|i| {
            let g = &garbage[i * 3..i * 3 + 3];
            if i % w < edge { [colour[0], colour[1], colour[2], 255] } else { [g[0], g[1], g[2], 0] }
        })
        .collect()
}

#[test]
fn transparent_garbage_leaves_no_fringe_when_premultiplied() {
    // The edge at an odd column so that texels of every level straddle it.
    let (w, h, edge, colour) = (75usize, 50usize, 37usize, [200u8, 100, 50]);
    let src = half_transparent(w, h, edge, colour);
    let layout = PixelLayout::new(Channels::Rgba, Depth::U8);
    for filter in [Filter::Premultiplied, Filter::LinearPremultiplied] {
        for (lod, (_, _, t)) in pyramid(&src, w, h, layout, filter, 7).iter().enumerate() {
            for px in t.chunks(4) {
                // Visible texels are exactly the opaque colour; fully transparent ones are black.
                let want = if px[3] > 0 { colour } else { [0, 0, 0] };
                assert_eq!(px[..3], want, "{filter} LOD {}: {px:?}", lod + 1);
            }
        }
    }
    // The resampling filters premultiply in f32 and divide before clamping alpha, so ringing
    // in alpha does not tint colour either.
    for filter in [Filter::Lanczos3, Filter::Mitchell] {
        for (lod, (_, _, t)) in pyramid(&src, w, h, layout, filter, 7).iter().enumerate() {
            for px in t.chunks(4) {
                let want = if px[3] > 0 { colour } else { [0, 0, 0] };
                assert_eq!(px[..3], want, "{filter} LOD {}: {px:?}", lod + 1);
            }
        }
    }
    // Box mixes the garbage in: the test can see a fringe.
    let fringe = pyramid(&src, w, h, layout, Filter::Box, 7)
        .iter()
        .any(|(_, _, t)| t.chunks(4).any(|px| px[3] > 0 && px[..3] != colour));
    assert!(fringe, "box shows a fringe");
}

mod alpha_range {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig { cases: 64, .. ProptestConfig::default() })]

        /// Straight-alpha results stay in range: a premultiplied texel's colour lies between the
        /// smallest and largest colour of the visible pixels under it; alpha is the rounded mean.
        #[test]
        fn premultiplied_colour_stays_within_the_visible_colours(
            w in 1usize..24,
            h in 1usize..24,
            wide in any::<bool>(),
            linear in any::<bool>(),
            transparent_share in 0u64..4,
            seed in any::<u64>(),
        ) {
            let layout = PixelLayout::new(Channels::Rgba, if wide { Depth::U16 } else { Depth::U8 });
            let mut img = common::Image::random(w as u32, h as u32, layout, seed);
            // Many alphas 0 and many tiny ones.
            for (i, px) in img.samples.chunks_mut(4).enumerate() {
                match (seed.wrapping_add(i as u64 * 7)) % 4 {
                    k if k < transparent_share => px[3] = 0,
                    1 => px[3] %= 3,
                    _ => {}
                }
            }
            let filter = if linear { Filter::LinearPremultiplied } else { Filter::Premultiplied };
            let levels = (usize::BITS - w.max(h).leading_zeros()) + 1;
            let (got, src) = if wide {
                (pyramid(&img.samples, w, h, layout, filter, levels), img.samples.clone())
            } else {
                let s: Vec<u8> = img.samples.iter().map(|v| *v as u8).collect();
                let g = pyramid(&s, w, h, layout, filter, levels);
                (g.into_iter().map(|(a, b, t)| (a, b, t.into_iter().map(u16::from).collect())).collect(), img.samples.clone())
            };
            for (lod, (lw, _, t)) in got.iter().enumerate() {
                let f = 2usize << lod;
                for (i, px) in t.chunks(4).enumerate() {
                    let (x, y) = (i % lw, i / lw);
                    let under: Vec<&[u16]> = (y * f..((y + 1) * f).min(h))
                        .flat_map(|sy| (x * f..((x + 1) * f).min(w)).map(move |sx| sy * w + sx))
                        .map(|j| &src[j * 4..j * 4 + 4])
                        .collect();
                    let alpha_sum: u64 = under.iter().map(|p| p[3] as u64).sum();
                    let n = under.len() as u64;
                    prop_assert_eq!(px[3] as u64, (2 * alpha_sum + n) / (2 * n));
                    for ch in 0..3 {
                        let visible = under.iter().filter(|p| p[3] > 0).map(|p| p[ch]);
                        match (visible.clone().min(), visible.max()) {
                            (Some(lo), Some(hi)) => prop_assert!(
                                (lo..=hi).contains(&px[ch]),
                                "LOD {} texel {i} channel {ch}: {} outside [{lo}, {hi}]", lod + 1, px[ch]
                            ),
                            _ => prop_assert_eq!(px[ch], 0),
                        }
                    }
                }
            }
        }

        /// Any 2x2 footprint through the linear filter is within one code of the float formula.
        #[test]
        fn linear_quads_agree_with_the_float_formula(q8 in any::<[u8; 4]>(), q16 in any::<[u16; 4]>()) {
            let got = pyramid(&q8, 2, 2, grey::<u8>(), Filter::Linear, 1)[0].2[0];
            let want = float_linear_mean(&q8.map(u16::from), 255.0);
            prop_assert!((got as f64 - want).abs() <= 1.0, "{:?}: {} vs {}", q8, got, want);
            let got = pyramid(&q16, 2, 2, grey::<u16>(), Filter::Linear, 1)[0].2[0];
            let want = float_linear_mean(&q16, 65535.0);
            prop_assert!((got as f64 - want).abs() <= 1.0, "{:?}: {} vs {}", q16, got, want);
        }
    }
}

/// The exact linear-light mean of `codes`, encoded and rounded, in f64.
fn float_linear_mean(codes: &[u16], max: f64) -> f64 {
    let l = codes.iter().map(|c| srgb_to_linear(*c as f64 / max)).sum::<f64>() / codes.len() as f64;
    (linear_to_srgb(l) * max).round()
}

// ---------------------------------------------------------------------------------------------
// The sRGB tables

#[test]
fn srgb_tables_round_trip_every_code() {
    let t8 = SrgbTable::get(Depth::U8);
    for c in 0..=255u16 {
        assert_eq!(t8.encode(t8.decode(c) as u64), c, "8-bit code {c}");
    }
    let t16 = SrgbTable::get(Depth::U16);
    for c in 0..=65535u16 {
        assert_eq!(t16.encode(t16.decode(c) as u64), c, "16-bit code {c}");
    }
    assert_eq!((t8.decode(0), t8.decode(255)), (0, t8.scale));
    assert_eq!((t16.decode(0), t16.decode(65535)), (0, t16.scale));
}

#[test]
fn srgb_tables_agree_with_the_exact_formula() {
    // Decoding: the nearest fixed-point value. Encoding: the nearest code to every fixed-point
    // value, exactly but for float ties (none found), so never more than one code off.
    for (depth, max) in [(Depth::U8, 255.0), (Depth::U16, 65535.0)] {
        let t = SrgbTable::get(depth);
        let scale = t.scale as f64;
        for c in 0..=max as u32 {
            let exact = srgb_to_linear(c as f64 / max) * scale;
            assert!((t.decode(c as u16) as f64 - exact).abs() <= 0.5, "{depth:?} decode {c}");
        }
        let mut off = 0;
        for v in 0..=t.scale {
            let exact = (linear_to_srgb(v as f64 / scale) * max).round();
            let got = t.encode(v as u64) as f64;
            assert!((got - exact).abs() <= 1.0, "{depth:?} encode {v}: {got} vs {exact}");
            off += (got != exact) as u32;
        }
        assert_eq!(off, 0, "{depth:?}: {off} values encode one code off");
    }
}

#[test]
fn linear_filter_agrees_with_the_float_formula_for_every_pair() {
    // Every 8-bit pair (a, b) as the 2x2 footprint [a b; a b] of one 512 x 512 image: texel
    // (x, y) of LOD 1 has a = y, b = x.
    let (w, h) = (512usize, 512usize);
    let src: Vec<u8> = (0..w * h).map(|i| if i % 2 == 0 { (i / w / 2) as u8 } else { (i % w / 2) as u8 }).collect();
    let l1 = &pyramid(&src, w, h, grey::<u8>(), Filter::Linear, 1)[0].2;
    let mut off = 0;
    for (i, got) in l1.iter().enumerate() {
        let (a, b) = ((i / 256) as u16, (i % 256) as u16);
        let want = float_linear_mean(&[a, b, a, b], 255.0);
        assert!((*got as f64 - want).abs() <= 1.0, "({a}, {b}): {got} vs {want}");
        off += (*got as f64 != want) as u32;
    }
    // One code off only where the exact result is within the 16-bit fixed point's reach of a
    // tie (measured: 131 of 65536 pairs, mostly near black).
    assert!(off <= 200, "{off} of 65536 pairs one code off");
}

// ---------------------------------------------------------------------------------------------
// Sizes and arithmetic at the limits

#[test]
fn widest_row_reduces_exactly() {
    // One row as wide as Layout accepts, less one (odd), through all 24 levels: the last
    // texel is the rounded mean of every pixel, the edge texels of every level average only
    // real pixels.
    let w = MAX_SIDE as usize - 1;
    let row: Vec<u8> = (0..w).map(|x| (x % 251) as u8).collect();
    let total: u64 = row.iter().map(|v| *v as u64).sum();
    let mut red = Reducer::<u64>::new(w as u64, 1, 0, w, 1);
    let e = red.finish_with(&row);
    let (mut sums, mut width) = (e, red.out_width());
    for lod in 1..24 {
        let mut red = Reducer::<u64>::new(w as u64, 1, lod, width, 1);
        sums = red.finish_with(&sums);
        width = red.out_width();
    }
    assert_eq!((width, sums.len()), (1, 1));
    assert_eq!(sums[0], total);
}

trait FinishWith {
    fn finish_with<S: Copy + Into<u64>>(&mut self, row: &[S]) -> Vec<u64>;
}

impl FinishWith for Reducer<u64> {
    /// Pushes the only row of a one-row level and returns the next level's exact sums.
    fn finish_with<S: Copy + Into<u64>>(&mut self, row: &[S]) -> Vec<u64> {
        assert!(self.push(row).is_none());
        let e = self.finish().unwrap();
        let mut out = vec![0u8; e.sums.len()];
        e.round_into(&mut out);
        // The right edge texel covers fewer real pixels: its mean is over those alone.
        let last = e.sums.len() - 1;
        assert_eq!(out[last] as u64, e.mean(last, e.sums[last]));
        e.sums.to_vec()
    }
}

#[test]
fn sizes_and_offsets_above_2_32_are_exact() {
    // The largest grid: 2^22 pages per side, 23 levels, 2^24 - 1 texels per side.
    let side = MAX_SIDE - 1;
    let l = Layout::new(side, side, 8, 2).unwrap();
    assert_eq!((l.columns, l.rows, l.lod_count, l.payload()), (1 << 22, 1 << 22, 23, 4));
    let tiles: u128 = (0..23u32).map(|k| (1u128 << (22 - k)).pow(2)).sum();
    assert_eq!(l.total_tiles() as u128, tiles);
    assert!(l.total_tiles() > u32::MAX as u64);
    for lod in 0..23 {
        let want = (side as u128).div_ceil(1 << lod) as u32;
        assert_eq!(l.level_extent(lod), (want, want), "LOD {lod}");
        assert_eq!(l.virtual_extent(lod).0 as u128, (1u128 << (22 - lod)) * 4);
    }
    // Rows of the last tile row at LOD 0, beyond 2^24 in virtual rows, clamp to the image.
    let last = l.rows - 1;
    assert_eq!(vortex_tiler::testing::last_row_needed(&l, last, side as u32), side - 1);
    assert_eq!(vortex_tiler::testing::first_row_read(&l, last), last as u64 * 4 - 2);
    // Texel weights above 2^32: the coarsest texels of a 2^24 - 1 image cover up to 4^22
    // pixels; the bottom-right one (2^22 - 1)^2, an odd count.
    let mut red = Reducer::<u64>::new(side, side, 21, 8, 1);
    let corner = ((1u64 << 22) - 1).pow(2);
    for y in 0..4 {
        let mut row = [0u64; 8];
        if y == 3 {
            // Sums just either side of 200.5 per pixel in the corner texel.
            row[6] = 200 * corner + (corner - 1) / 2;
            row[4] = 200 * corner + corner.div_ceil(2);
        }
        assert!(red.push(&row).is_none());
        let e = red.push(&[0u64; 8]).unwrap();
        assert_eq!(e.weight(0), if y < 3 { 1 << 44 } else { (1 << 22) * ((1 << 22) - 1) });
        if y == 3 {
            assert_eq!(e.weight(3), corner);
            assert!(e.weight(3) > u32::MAX as u64);
            assert_eq!((e.mean(3, e.sums[3]), e.mean(3, e.sums[2])), (200, 201), "{:?}", e.sums);
        }
    }
}
