//! Golden files: every tile of each small fixture as `lod x y width height crc32` (the tile
//! file's decoded width and height, and the CRC-32 of its decoded samples, big-endian), so any
//! change to the pyramid shows up as a reviewable diff.
//! Bless new results with `BLESS=1 cargo test --test it golden::` after checking them.

use std::path::Path;

use crate::common::{MemSink, decode_png_sized, png_options};
use vortex_tiler::background::Background;
use vortex_tiler::source;
use vortex_tiler::split::split;

fn golden(fixture: &str, tile: u32, border: u32, background: Background) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures");
    let src = source::open(&root.join(fixture), vortex_tiler::limits::Budget::new(1 << 30)).unwrap();
    let sink = MemSink::default();
    let summary = split(src, &sink, &png_options(tile, border, background), &()).unwrap();
    let mut text =
        format!("# {fixture}: tile {tile}, border {border}, background {background}, {} tiles\n", summary.tiles);
    text.push_str("# lod x y width height crc32\n");
    for ((lod, x, y), png) in sink.tiles.into_inner().unwrap() {
        let (width, height, samples) = decode_png_sized(&png);
        let samples: Vec<u8> = samples
            .iter()
            .flat_map(|s| {
                if summary.stored.depth == vortex_tiler::pixel::Depth::U8 {
                    vec![*s as u8]
                } else {
                    s.to_be_bytes().to_vec()
                }
            })
            .collect();
        text.push_str(&format!("{lod} {x} {y} {width} {height} {:08x}\n", crc32fast::hash(&samples)));
    }
    let path = root.join("golden").join(format!("{fixture}.txt"));
    if std::env::var_os("BLESS").is_some() {
        std::fs::write(&path, &text).unwrap();
    }
    let want = std::fs::read_to_string(&path).unwrap_or_default();
    if want != text {
        let actual = path.with_extension("actual.txt");
        std::fs::write(&actual, &text).unwrap();
        panic!(
            "{} differs from this run (written to {}); diff them, and bless with BLESS=1 if the change is intended",
            path.display(),
            actual.display()
        );
    }
}

#[test]
fn sample_rgb8() {
    golden("sample.png", 128, 4, Background::Edge);
}

#[test]
fn rgba8_odd_with_background() {
    golden("rgba8-130x67.png", 32, 2, Background::Colour([255, 0, 128, 64]));
}

#[test]
fn grey_alpha16_odd() {
    golden("grey-alpha16-97x61.png", 16, 1, Background::Edge);
}

#[test]
fn grey8_tall() {
    golden("grey8-33x200.png", 24, 3, Background::Colour([40, 40, 40, 255]));
}
