//! Image comparisons written once: two pictures' samples against a [`Tolerance`] that says why
//! it is what it is. On failure the pictures are kept as `NAME-actual.png`,
//! `NAME-expected.png` and `NAME-difference.png` under `target/image-diffs/` (the difference
//! scaled so that one level shows), and the panic names them, so a failure can be looked at.

use std::path::{Path, PathBuf};

use image::{DynamicImage, GenericImageView, ImageBuffer, Luma, LumaA, Rgb, Rgba};

/// How far two pictures may differ, per sample (in the pictures' own levels, 0-255 or
/// 0-65535), and why: the reason is required, so that no bound is a number nobody can explain.
#[derive(Clone, Copy, Debug)]
pub struct Tolerance {
    /// The largest difference of one sample.
    pub max: u32,
    /// The mean difference must stay below this, where the bound has one.
    pub mean_below: Option<f64>,
    /// Where the differences come from, and what a real fault would look like instead.
    pub why: &'static str,
}

impl Tolerance {
    /// No sample may differ by more than `max`.
    pub fn max(max: u32, why: &'static str) -> Tolerance {
        Tolerance { max, mean_below: None, why }
    }

    /// No sample by more than `max`, and the mean difference below `mean_below`.
    pub fn max_and_mean(max: u32, mean_below: f64, why: &'static str) -> Tolerance {
        Tolerance { max, mean_below: Some(mean_below), why }
    }

    /// Only the mean difference is bounded (below `mean_below`).
    pub fn mean(mean_below: f64, why: &'static str) -> Tolerance {
        Tolerance { max: u32::MAX, mean_below: Some(mean_below), why }
    }
}

/// A picture's samples, row by row, `channels` (1 to 4) to a texel.
pub struct Picture<'a, T> {
    pub width: u32,
    pub height: u32,
    pub channels: usize,
    pub samples: &'a [T],
}

impl<'a, T> Picture<'a, T> {
    pub fn new(width: u32, height: u32, channels: usize, samples: &'a [T]) -> Picture<'a, T> {
        Picture { width, height, channels, samples }
    }
}

/// The largest and the mean difference of two equally long runs of samples.
pub fn differences<T: Copy + Into<u32>>(a: &[T], b: &[T]) -> (u32, f64) {
    assert_eq!(a.len(), b.len(), "the pictures hold different numbers of samples");
    let each = a.iter().zip(b).map(|(x, y)| (*x).into().abs_diff((*y).into()));
    let (worst, sum) = each.fold((0u32, 0u64), |(w, s), d| (w.max(d), s + u64::from(d)));
    (worst, sum as f64 / a.len().max(1) as f64)
}

/// Panics, naming `name`, the numbers, the tolerance's reason and the pictures kept, unless
/// `actual` is within `tolerance` of `expected`.
pub fn assert_close<T: Copy + Into<u32>>(
    name: &str,
    actual: Picture<'_, T>,
    expected: Picture<'_, T>,
    tolerance: Tolerance,
) {
    assert_eq!(
        (actual.width, actual.height, actual.channels),
        (expected.width, expected.height, expected.channels),
        "{name}: the pictures differ in size or channels"
    );
    assert_eq!(
        actual.samples.len(),
        actual.width as usize * actual.height as usize * actual.channels,
        "{name}: the samples are not width x height x channels"
    );
    let (worst, mean) = differences(actual.samples, expected.samples);
    let over_mean = tolerance.mean_below.is_some_and(|below| mean >= below);
    if worst <= tolerance.max && !over_mean {
        return;
    }
    let bounds = match (tolerance.max, tolerance.mean_below) {
        (u32::MAX, Some(below)) => format!("a mean below {below}"),
        (max, Some(below)) => format!("at most {max} and a mean below {below}"),
        (max, None) => format!("at most {max}"),
    };
    let kept = keep(name, &actual, &expected);
    panic!(
        "{name}: differs by {worst} at worst, {mean:.3} on average; allowed {bounds} ({}). Pictures: {}",
        tolerance.why,
        kept.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", ")
    );
}

/// Writes the three pictures; returns their paths (none where the samples cannot be one).
fn keep<T: Copy + Into<u32>>(name: &str, actual: &Picture<'_, T>, expected: &Picture<'_, T>) -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/image-diffs");
    let wide = actual.samples.iter().chain(expected.samples).any(|s| (*s).into() > 255);
    let levels = |p: &Picture<'_, T>| p.samples.iter().map(|s| (*s).into()).collect::<Vec<u32>>();
    let (a, e) = (levels(actual), levels(expected));
    // Scaled so that a difference of one level is visible: x8, saturating.
    let step = if wide { 256 } else { 1 };
    let diff: Vec<u32> = a.iter().zip(&e).map(|(x, y)| (x.abs_diff(*y) / step * 8).min(255) * step).collect();
    let file = |what: &str| dir.join(format!("{}-{what}.png", name.replace(['/', ' ', ':'], "_")));
    let mut kept = Vec::new();
    if std::fs::create_dir_all(&dir).is_err() {
        return kept;
    }
    for (what, samples) in [("actual", a), ("expected", e), ("difference", diff)] {
        let Some(picture) = picture(actual.width, actual.height, actual.channels, samples, wide) else { continue };
        let path = file(what);
        if picture.save(&path).is_ok() {
            kept.push(path);
        }
    }
    kept
}

fn picture(width: u32, height: u32, channels: usize, samples: Vec<u32>, wide: bool) -> Option<DynamicImage> {
    if wide {
        let s: Vec<u16> = samples.into_iter().map(|v| v.min(65535) as u16).collect();
        return Some(match channels {
            1 => DynamicImage::ImageLuma16(ImageBuffer::<Luma<u16>, _>::from_raw(width, height, s)?),
            2 => DynamicImage::ImageLumaA16(ImageBuffer::<LumaA<u16>, _>::from_raw(width, height, s)?),
            3 => DynamicImage::ImageRgb16(ImageBuffer::<Rgb<u16>, _>::from_raw(width, height, s)?),
            4 => DynamicImage::ImageRgba16(ImageBuffer::<Rgba<u16>, _>::from_raw(width, height, s)?),
            _ => return None,
        });
    }
    let s: Vec<u8> = samples.into_iter().map(|v| v.min(255) as u8).collect();
    Some(match channels {
        1 => DynamicImage::ImageLuma8(ImageBuffer::<Luma<u8>, _>::from_raw(width, height, s)?),
        2 => DynamicImage::ImageLumaA8(ImageBuffer::<LumaA<u8>, _>::from_raw(width, height, s)?),
        3 => DynamicImage::ImageRgb8(ImageBuffer::<Rgb<u8>, _>::from_raw(width, height, s)?),
        4 => DynamicImage::ImageRgba8(ImageBuffer::<Rgba<u8>, _>::from_raw(width, height, s)?),
        _ => return None,
    })
}

#[test]
fn a_picture_off_by_more_than_its_tolerance_fails_and_is_kept() {
    let expected = [10u8, 20, 30, 40];
    let near = [11u8, 20, 29, 40];
    assert_close("near", Picture::new(2, 2, 1, &near), Picture::new(2, 2, 1, &expected), Tolerance::max(1, "test"));
    let far = [10u8, 20, 30, 50];
    let failed = std::panic::catch_unwind(|| {
        assert_close(
            "compare-self-test",
            Picture::new(2, 2, 1, &far),
            Picture::new(2, 2, 1, &expected),
            Tolerance::max_and_mean(4, 1.0, "the reason"),
        )
    });
    let message = failed.err().and_then(|e| e.downcast::<String>().ok()).expect("a failure with a message");
    assert!(
        message.contains("differs by 10 at worst, 2.500 on average") && message.contains("(the reason)"),
        "{message}"
    );
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/image-diffs");
    for what in ["actual", "expected", "difference"] {
        let path = dir.join(format!("compare-self-test-{what}.png"));
        assert!(message.contains(&path.display().to_string()), "{message}");
        assert_eq!(image::open(&path).unwrap().dimensions(), (2, 2));
    }
    let difference = image::open(dir.join("compare-self-test-difference.png")).unwrap().into_luma8().into_raw();
    assert_eq!(difference, [0, 0, 0, 80], "differences x8");
}
