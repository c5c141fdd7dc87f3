//! Every decoder path gives the same pyramid as every other for the same pixels.

mod common;

use std::path::{Path, PathBuf};

use common::{MemSink, png_options};
use vortex_tiler::background::Background;
use vortex_tiler::source;
use vortex_tiler::split::split;

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures").join(name)
}

fn tiles(path: &Path, max_memory: u64) -> Vec<((u32, u32, u32), Vec<u8>)> {
    let src = source::open(path, max_memory).unwrap();
    let sink = MemSink::default();
    split(src, &sink, &png_options(16, 1, Background::Edge), &()).unwrap();
    sink.tiles.into_inner().unwrap().into_iter().collect()
}

#[test]
fn interlaced_png_matches_the_same_pixels_streamed() {
    let interlaced = tiles(&fixture("interlaced-61x47.png"), 1 << 20);
    let ppm = tiles(&fixture("interlaced-61x47.ppm"), 1 << 20);
    assert_eq!(interlaced.len(), 85);
    assert!(interlaced == ppm);
}

#[test]
fn interlaced_png_over_max_memory_is_refused_with_advice() {
    let err = source::open(&fixture("interlaced-61x47.png"), 1000).err().expect("refused").to_string();
    for needle in ["interlaced-61x47.png", "Adam7", "8.4 KiB", "--max-memory", "non-interlaced"] {
        assert!(err.contains(needle), "{needle:?} missing from: {err}");
    }
}
