//! Numerical stability of the pyramid over deep cascades, with exact bounds.

mod common;

use vortex_tiler::pixel::Sample;
use vortex_tiler::pyramid::Reducer;

/// Cascades a grey image through `levels` reductions; returns each level's rounded texels
/// (level 1 first) and their widths.
fn cascade<T: Sample>(src: &[T], w: usize, h: usize, levels: u32) -> Vec<(usize, Vec<T>)> {
    let mut out = Vec::new();
    let mut rows: Vec<Vec<u64>> = src.chunks(w).map(|r| r.iter().map(|v| (*v).into()).collect()).collect();
    let mut width = w;
    for lod in 0..levels {
        let mut red = Reducer::new(w as u64, h as u64, lod, width, 1);
        let (mut next, mut rounded) = (Vec::new(), Vec::new());
        let mut take = |e: vortex_tiler::pyramid::ExactRow, next: &mut Vec<Vec<u64>>| {
            let mut o = vec![T::default(); e.sums.len()];
            e.round_into(&mut o);
            rounded.extend_from_slice(&o);
            next.push(e.sums.to_vec());
        };
        for r in &rows {
            if let Some(e) = red.push(r) {
                take(e, &mut next);
            }
        }
        if let Some(e) = red.finish() {
            take(e, &mut next);
        }
        width = red.out_width();
        out.push((width, rounded));
        rows = next;
    }
    out
}

fn mean<T: Sample>(v: &[T]) -> f64 {
    v.iter().map(|s| (*s).into() as f64).sum::<f64>() / v.len() as f64
}

#[test]
fn sixteen_levels_keep_the_mean_within_half_a_code_value() {
    // 2^16 x 4 so that every texel of every level has the same number of real pixels under it
    // (the plain mean of a level is then the image mean plus rounding), down to one texel.
    let (w, h) = (1usize << 16, 4usize);
    let img8 = common::Image::random(w as u32, h as u32, common::layouts()[0], 1);
    let src8: Vec<u8> = img8.samples.iter().map(|s| *s as u8).collect();
    let src_mean = mean(&src8);
    let levels = cascade(&src8, w, h, 16);
    assert_eq!(levels.last().unwrap().1.len(), 1);
    for (lod, (_, texels)) in levels.iter().enumerate() {
        let m = mean(texels);
        assert!((m - src_mean).abs() <= 0.5, "LOD {}: mean {m} vs source {src_mean}", lod + 1);
    }

    let img16 = common::Image::random(w as u32, h as u32, common::layouts()[1], 2);
    let src_mean = mean(&img16.samples);
    for (lod, (_, texels)) in cascade(&img16.samples, w, h, 16).iter().enumerate() {
        let m = mean(texels);
        assert!((m - src_mean).abs() <= 0.5, "16-bit LOD {}: mean {m} vs source {src_mean}", lod + 1);
    }
}

#[test]
fn constant_images_stay_exactly_constant_at_every_level() {
    for (w, h) in [(1usize, 1usize), (1000, 3), (3, 1000), (257, 129), (1 << 16, 2)] {
        let levels = (usize::BITS - w.max(h).leading_zeros()) + 1;
        for v in [0u8, 1, 127, 128, 254, 255] {
            for (lod, (_, t)) in cascade(&vec![v; w * h], w, h, levels).iter().enumerate() {
                assert!(t.iter().all(|x| *x == v), "{w}x{h} value {v} LOD {}", lod + 1);
            }
        }
        for v in [1u16, 32768, 65534, 65535] {
            for (lod, (_, t)) in cascade(&vec![v; w * h], w, h, levels).iter().enumerate() {
                assert!(t.iter().all(|x| *x == v), "16-bit {w}x{h} value {v} LOD {}", lod + 1);
            }
        }
    }
}

#[test]
fn one_texel_checkerboard_is_exact_mid_grey_at_lod_one() {
    for (w, h) in [(64usize, 64usize), (10, 6)] {
        let src: Vec<u8> = (0..w * h).map(|i| if (i % w + i / w) % 2 == 0 { 0 } else { 255 }).collect();
        let l1 = &cascade(&src, w, h, 1)[0].1;
        // (0 + 255 + 255 + 0) / 4 = 127.5, rounded half up, once.
        assert!(l1.iter().all(|v| *v == 128), "{l1:?}");
        let src16: Vec<u16> = src.iter().map(|v| *v as u16 * 257).collect();
        let l1 = &cascade(&src16, w, h, 1)[0].1;
        assert!(l1.iter().all(|v| *v == 32768), "{l1:?}");
    }
}

#[test]
fn sixteen_bit_extremes_do_not_overflow() {
    // Sums of 4^16 samples of 65535 need 48 bits; a u32 accumulator would wrap at level 8.
    let (w, h) = (1usize << 16, 2usize);
    let mut src = vec![65535u16; w * h];
    src[0] = 0;
    let levels = cascade(&src, w, h, 16);
    let (_, top) = levels.last().unwrap();
    // One zero among 131072 samples of 65535: the mean is 65534.5 -> 65535 (halves round up).
    assert_eq!(top, &vec![65535]);
}
