//! Every decoder path gives the same pyramid as every other for the same pixels.

use std::path::{Path, PathBuf};

use crate::common;
use crate::common::compare::{Picture, Tolerance, assert_close};
use crate::common::{MemSink, png_options};
use vortex_tiler::background::Background;
use vortex_tiler::limits::Budget;
use vortex_tiler::source;
use vortex_tiler::split::split;

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures").join(name)
}

fn tiles(path: &Path, max_memory: u64) -> Vec<((u32, u32, u32), Vec<u8>)> {
    let src = source::open(path, Budget::new(max_memory)).unwrap();
    let sink = MemSink::default();
    split(src, &sink, &png_options(16, 1, Background::Edge), &()).unwrap();
    sink.tiles.into_inner().unwrap().into_iter().collect()
}

#[test]
fn interlaced_png_matches_the_same_pixels_streamed() {
    let interlaced = tiles(&fixture("interlaced-61x47.png"), 1 << 20);
    let ppm = tiles(&fixture("interlaced-61x47.ppm"), 1 << 20);
    // 61 x 47 in 14-texel payloads: 5 x 4, 3 x 2, 2 x 1 and 1 x 1 pages.
    assert_eq!(interlaced.len(), 29);
    assert!(interlaced == ppm);
}

#[test]
fn interlaced_png_over_max_memory_is_refused_with_advice() {
    let err = source::open(&fixture("interlaced-61x47.png"), Budget::new(1000)).err().expect("refused").to_string();
    for needle in ["interlaced-61x47.png", "Adam7", "8.4 KiB", "--max-memory", "non-interlaced"] {
        assert!(err.contains(needle), "{needle:?} missing from: {err}");
    }
}

/// The same pixels saved as PNG, TIFF and PPM (8 and 16 bits) give identical pyramids.
#[test]
fn png_tiff_and_ppm_agree() {
    let dir = tempfile::tempdir().unwrap();
    let rgb8 = image::RgbImage::from_fn(83, 57, |x, y| image::Rgb([(x * 3) as u8, (y * 4) as u8, ((x ^ y) * 5) as u8]));
    let rgb16 = image::ImageBuffer::<image::Rgb<u16>, _>::from_fn(83, 57, |x, y| {
        image::Rgb([(x * 700) as u16, (y * 1100) as u16, ((x * y) * 13) as u16])
    });
    for (name, wide) in [("rgb8", false), ("rgb16", true)] {
        let mut outputs = Vec::new();
        for ext in ["png", "tif", "ppm"] {
            let path = dir.path().join(format!("{name}.{ext}"));
            if wide {
                rgb16.save(&path).unwrap()
            } else {
                rgb8.save(&path).unwrap()
            }
            outputs.push((ext, tiles(&path, 1 << 20)));
        }
        for (ext, t) in &outputs[1..] {
            assert!(*t == outputs[0].1, "{name}.{ext} differs from {name}.png");
        }
    }
}

/// A baseline JPEG streams through the banded decoder and its pyramid is close to the one of
/// the `image` crate's decode of the same file (IDCTs differ by a code value or two).
#[test]
fn jpeg_input_streams() {
    let dir = tempfile::tempdir().unwrap();
    let img = image::RgbImage::from_fn(200, 120, |x, y| image::Rgb([(x + y) as u8, (x * 2) as u8, (y * 2) as u8]));
    let jpg = dir.path().join("in.jpg");
    img.save(&jpg).unwrap();
    let src = source::open(&jpg, Budget::new(1 << 20)).unwrap();
    assert!(src.describe().contains("jpeg"), "{}", src.describe());
    let reference = dir.path().join("ref.png");
    image::open(&jpg).unwrap().to_rgb8().save(&reference).unwrap();
    let (got, want) = (tiles(&jpg, 1 << 20), tiles(&reference, 1 << 20));
    for ((k, a), (_, b)) in got.iter().zip(&want) {
        let ((w, h, a), (_, _, b)) = (common::decode_png_sized(a), common::decode_png_sized(b));
        let c = a.len() / (w * h) as usize;
        let why = "the two decoders' IDCTs differ by a code value or two";
        assert_close(
            &format!("jpeg-tile-{k:?}"),
            Picture::new(w, h, c, &a),
            Picture::new(w, h, c, &b),
            Tolerance::max(4, why),
        );
    }
}
