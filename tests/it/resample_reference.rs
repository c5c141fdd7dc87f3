//! `lanczos3` and `mitchell` against an outside reference: a naive separable resampler written
//! here from the textbook kernels, in `f64`, sharing no code with the library (which calls
//! fast_image_resize). The oracle's `naive_levels` takes these levels from the library's own
//! `resample_level` to check the banded pipeline against it; this module checks that
//! `resample_level` itself is the filter docs/info-json.md describes:
//!
//! - Lanczos, a = 3: `k(x) = sinc(x) sinc(x / 3)` for `|x| < 3`, `sinc(x) = sin(pi x) / (pi x)`.
//! - Mitchell-Netravali with B = C = 1/3 (Mitchell and Netravali 1988, eq. 8):
//!   `k(x) = ((12 - 9B - 6C)|x|^3 + (-18 + 12B + 6C)|x|^2 + (6 - 2B)) / 6` for `|x| < 1`,
//!   `((-B - 6C)|x|^3 + (6B + 30C)|x|^2 + (-12B - 48C)|x| + (8B + 24C)) / 6` for `1 <= |x| < 2`.
//! - Each level halves: the level is first extended to an even size by repeating its last
//!   column and row; output texel `i` is centred on input coordinate `2i + 1` (texel centres
//!   at `j + 0.5`) and the kernel is stretched by 2, so input texel `j` weighs
//!   `k((j + 0.5 - (2i + 1)) / 2)`. At the level's edges the kernel is cut to the texels that
//!   exist and its weights divided by their sum (no mirrored or repeated texels beyond the
//!   even extension). Columns first, then rows.
//! - With alpha, colour is multiplied by `alpha / MAX` before and divided by the resampled
//!   alpha after (before alpha is clamped); a texel whose alpha rounds to 0 is black.
//! - Results are clamped to the sample range and rounded to the nearest code; 8-bit images
//!   without alpha also after the first pass (stored as 8 bits between the passes).

use crate::common::Image;
use crate::common::compare::{Picture, Tolerance, assert_close};
use vortex_tiler::pixel::{Channels, Depth, PixelLayout};
use vortex_tiler::pyramid::Filter;
use vortex_tiler::testing::resample_level;

fn sinc(x: f64) -> f64 {
    if x == 0.0 { 1.0 } else { (std::f64::consts::PI * x).sin() / (std::f64::consts::PI * x) }
}

fn lanczos3(x: f64) -> f64 {
    if x.abs() < 3.0 { sinc(x) * sinc(x / 3.0) } else { 0.0 }
}

fn mitchell(x: f64) -> f64 {
    let (b, c) = (1.0 / 3.0, 1.0 / 3.0);
    let x = x.abs();
    let k = if x < 1.0 {
        (12.0 - 9.0 * b - 6.0 * c) * x.powi(3) + (-18.0 + 12.0 * b + 6.0 * c) * x * x + (6.0 - 2.0 * b)
    } else if x < 2.0 {
        (-b - 6.0 * c) * x.powi(3) + (6.0 * b + 30.0 * c) * x * x + (-12.0 * b - 48.0 * c) * x + (8.0 * b + 24.0 * c)
    } else {
        0.0
    };
    k / 6.0
}

/// What the kernel does past the ends of the (evenly extended) level.
#[derive(Clone, Copy, PartialEq)]
enum Edge {
    /// Cut to the texels that exist, weights divided by their sum: the library's rule.
    Cut,
    /// The end texels repeated as far as the kernel reaches (another common rule, only to
    /// show that the comparison tells the two apart).
    Repeat,
}

/// For each of `out` outputs along an axis `2 * out` texels long: its (input texel, weight)s.
fn weights(kernel: fn(f64) -> f64, support: f64, out: usize, edge: Edge) -> Vec<Vec<(usize, f64)>> {
    let len = 2 * out as i64;
    (0..out)
        .map(|i| {
            let centre = 2.0 * i as f64 + 1.0;
            let reach = (centre - 2.0 * support).floor() as i64..(centre + 2.0 * support).ceil() as i64;
            let taps: Vec<(usize, f64)> = reach
                .filter(|j| edge == Edge::Repeat || (0..len).contains(j))
                .map(|j| (j.clamp(0, len - 1) as usize, kernel((j as f64 + 0.5 - centre) / 2.0)))
                .collect();
            let sum: f64 = taps.iter().map(|t| t.1).sum();
            taps.into_iter().map(|(j, w)| (j, w / sum)).collect()
        })
        .collect()
}

/// `image` with its rows and columns exchanged.
fn transposed(image: &Image) -> Image {
    let (w, h, c) = (image.width as usize, image.height as usize, image.channels());
    let samples = (0..w).flat_map(|x| (0..h).flat_map(move |y| (0..c).map(move |ch| (x, y, ch))));
    let samples = samples.map(|(x, y, ch)| image.samples[(y * w + x) * c + ch]).collect();
    Image { width: image.height, height: image.width, layout: image.layout, samples }
}

/// The next level of `image` (samples of any depth) by the textbook kernel. fast_image_resize
/// takes the columns first, then the rows; only the 8-bit path, rounded between the passes,
/// can tell the order.
fn reference(image: &Image, filter: Filter, edge: Edge) -> Vec<u16> {
    let t = transposed(image);
    let out = rows_then_columns(&t, filter, edge);
    let next = Image { width: t.width.div_ceil(2), height: t.height.div_ceil(2), layout: t.layout, samples: out };
    transposed(&next).samples
}

fn rows_then_columns(image: &Image, filter: Filter, edge: Edge) -> Vec<u16> {
    let (kernel, support): (fn(f64) -> f64, f64) = match filter {
        Filter::Lanczos3 => (lanczos3, 3.0),
        Filter::Mitchell => (mitchell, 2.0),
        other => panic!("{other} is not a resampling filter"),
    };
    let (w, h, c) = (image.width as usize, image.height as usize, image.channels());
    let max = if image.layout.depth == Depth::U8 { 255.0 } else { 65535.0 };
    let alpha = image.layout.channels.has_alpha().then_some(c - 1);
    let (ow, oh) = (w.div_ceil(2), h.div_ceil(2));
    // The level extended to 2ow x 2oh by repeating its last column and row; colour premultiplied.
    let texel = |x: usize, y: usize| -> Vec<f64> {
        let at = (y.min(h - 1) * w + x.min(w - 1)) * c;
        let px: Vec<f64> = image.samples[at..at + c].iter().map(|&v| v as f64).collect();
        let weight = alpha.map_or(1.0, |a| px[a] / max);
        px.iter().enumerate().map(|(ch, v)| if Some(ch) == alpha { *v } else { v * weight }).collect()
    };
    let (across, down) = (weights(kernel, support, ow, edge), weights(kernel, support, oh, edge));
    // Rows first: every extended row resampled across.
    let rows: Vec<Vec<f64>> = (0..2 * oh)
        .map(|y| {
            across
                .iter()
                .flat_map(|taps| {
                    let mut acc = vec![0.0; c];
                    for &(j, wt) in taps {
                        for (a, v) in acc.iter_mut().zip(texel(j, y)) {
                            *a += wt * v;
                        }
                    }
                    // 8-bit without alpha: the first pass is stored as 8-bit samples, rounded
                    // and clamped (Lanczos' ringing past 0 and 255 is cut between the passes:
                    // without this, and in the other order, samples differ by up to 5).
                    if image.layout.depth == Depth::U8 && alpha.is_none() {
                        acc.iter_mut().for_each(|v| *v = v.clamp(0.0, 255.0).round());
                    }
                    acc
                })
                .collect()
        })
        .collect();
    let mut out = Vec::with_capacity(ow * oh * c);
    for taps in &down {
        for x in 0..ow {
            let mut acc = vec![0.0; c];
            for &(j, wt) in taps {
                for (ch, a) in acc.iter_mut().enumerate() {
                    *a += wt * rows[j][x * c + ch];
                }
            }
            let round = |v: f64| v.clamp(0.0, max).round() as u16;
            match alpha {
                None => out.extend(acc.iter().map(|v| round(*v))),
                Some(a) => {
                    let visible = round(acc[a]) != 0;
                    out.extend((0..c).map(|ch| match ch {
                        ch if ch == a => round(acc[a]),
                        _ if !visible => 0,
                        ch => round(acc[ch] * max / acc[a]),
                    }));
                }
            }
        }
    }
    out
}

/// The library's next level of `image`, widened to u16.
fn library(image: &Image, filter: Filter) -> Vec<u16> {
    let (w, h) = (image.width as usize, image.height as usize);
    match image.layout.depth {
        Depth::U8 => {
            let src: Vec<u8> = image.samples.iter().map(|&v| v as u8).collect();
            resample_level(filter, image.layout, &src, w, h).unwrap().into_iter().map(u16::from).collect()
        }
        _ => resample_level(filter, image.layout, &image.samples, w, h).unwrap(),
    }
}

/// Random texels (the hardest case for a resampler: every texel differs from its neighbours,
/// so a kernel misplaced by half a texel, a wrong kernel or a wrong edge rule is off by tens of
/// levels) at odd and even sizes down to 1x1, every channel layout, 8 and 16 bits.
#[test]
fn lanczos3_and_mitchell_are_the_textbook_kernels() {
    // The library rounds its coefficients to fixed point (8-bit) or works in `f32` (16-bit,
    // alpha), this reference in `f64`: a value within that error of a half rounds the other
    // way, so one code apart at most, and rarely (measured: 78 of 36072 samples, 0.22%).
    let tolerance = Tolerance::max(1, "fixed-point or f32 arithmetic against f64: a half rounded the other way");
    // How often they differ, over every case together (one image of 2 samples says little).
    let (mut differing, mut samples) = (0usize, 0usize);
    let layouts = [
        PixelLayout::new(Channels::Grey, Depth::U8),
        PixelLayout::new(Channels::Rgb, Depth::U8),
        PixelLayout::new(Channels::GreyAlpha, Depth::U8),
        PixelLayout::new(Channels::Rgba, Depth::U8),
        PixelLayout::new(Channels::Grey, Depth::U16),
        PixelLayout::new(Channels::Rgb, Depth::U16),
        PixelLayout::new(Channels::Rgba, Depth::U16),
    ];
    let mut seed = 1;
    for filter in [Filter::Lanczos3, Filter::Mitchell] {
        for layout in layouts {
            for (w, h) in [(1, 1), (2, 3), (5, 2), (37, 23), (64, 48)] {
                seed += 1;
                let mut image = Image::random(w, h, layout, seed);
                if layout.channels.has_alpha() {
                    // Alpha of at least a quarter: colour divided by a small alpha magnifies
                    // the f32 error the tolerance allows (transparency itself is the exact
                    // filters' concern, tested in `oracle`).
                    let (c, max) = (layout.channels.count(), if layout.depth == Depth::U8 { 255 } else { 65535 });
                    for a in image.samples.iter_mut().skip(c - 1).step_by(c) {
                        *a = max / 4 + *a % (max - max / 4);
                    }
                }
                let (ow, oh) = (w.div_ceil(2), h.div_ceil(2));
                let name = format!("{filter}-{w}x{h}-{}-{}", layout.channels.count(), layout.depth.bytes() * 8);
                let ours = library(&image, filter);
                let theirs = reference(&image, filter, Edge::Cut);
                let c = layout.channels.count();
                assert_close(&name, Picture::new(ow, oh, c, &ours), Picture::new(ow, oh, c, &theirs), tolerance);
                differing += ours.iter().zip(&theirs).filter(|(a, b)| a != b).count();
                samples += ours.len();
            }
        }
    }
    let share = differing as f64 / samples as f64;
    eprintln!("{differing} of {samples} samples apart ({:.2}%)", share * 100.0);
    assert!(share < 0.01, "{differing} of {samples} samples differ: more than rounding explains");
}

/// The comparison tells the kernels and the edge rules apart, so agreeing within its
/// tolerance means something: on random texels Lanczos 3's levels are tens of levels from
/// Mitchell's, and repeating the end texels past the level instead of cutting the kernel
/// there moves the border texels by more than the tolerance.
#[test]
fn the_reference_tells_the_kernels_and_edges_apart() {
    let image = Image::random(37, 23, PixelLayout::new(Channels::Grey, Depth::U8), 99);
    let worst = |a: &[u16], b: &[u16]| a.iter().zip(b).map(|(x, y)| x.abs_diff(*y)).max().unwrap();
    for filter in [Filter::Lanczos3, Filter::Mitchell] {
        let ours = library(&image, filter);
        let other = if filter == Filter::Mitchell { Filter::Lanczos3 } else { Filter::Mitchell };
        let apart = worst(&ours, &reference(&image, other, Edge::Cut));
        assert!(apart > 10, "the library's {filter} level is within {apart} of {other}'s");
        let apart = worst(&ours, &reference(&image, filter, Edge::Repeat));
        assert!(apart > 2, "the library's {filter} level is within {apart} of one with repeated edges");
    }
}
