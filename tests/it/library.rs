//! The tiler used as a library: the README's example is the crate's doc test (which runs it),
//! and a run a `Progress` stops part-way leaves nothing behind.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

use vortex_tiler::error::TilerError;
use vortex_tiler::formats::pack::PackSink;
use vortex_tiler::pixel::{Channels, Depth, PixelLayout};
use vortex_tiler::split::{Progress, split};
use vortex_tiler::vortex_pack::WriteOptions;

use crate::common::{Image, png_options};

/// The lines of the code block that `begin` opens.
fn code_after<'a>(text: &'a str, begin: &str) -> Vec<&'a str> {
    let start = text.find(begin).unwrap_or_else(|| panic!("{begin:?} not found")) + begin.len();
    text[start..].lines().skip(1).take_while(|l| l.trim_start() != "```").collect()
}

#[test]
fn readme_example_is_the_doc_test() {
    let root = env!("CARGO_MANIFEST_DIR");
    let readme = std::fs::read_to_string(format!("{root}/README.md")).unwrap();
    let lib = std::fs::read_to_string(format!("{root}/src/lib.rs")).unwrap();
    let shown = code_after(&readme, "<!-- library-example:begin -->\n```rust");
    // rustdoc hides the lines that start with "# " (the test's set-up); the README leaves them out.
    let section = lib.find("//! # Tiling from Rust").expect("the doc section");
    let tested: Vec<&str> = lib[section..]
        .lines()
        .skip_while(|l| *l != "//! ```")
        .skip(1)
        .take_while(|l| *l != "//! ```")
        .map(|l| l.strip_prefix("//! ").unwrap_or(l.trim_start_matches("//!")))
        .filter(|l| !(l.starts_with("# ") || *l == "#"))
        .collect();
    assert!(shown.len() > 20, "the README's example is missing: {shown:?}");
    assert_eq!(shown, tested, "README.md's library example differs from src/lib.rs's doc test");
}

/// Stops the run as soon as it hears of the first finished tiles.
#[derive(Default)]
struct StopAtFirst {
    tiles: AtomicU64,
    stop: AtomicBool,
}

impl Progress for StopAtFirst {
    fn advance(&self, tiles: u64) {
        self.tiles.fetch_add(tiles, Ordering::SeqCst);
        self.stop.store(true, Ordering::SeqCst);
    }
    fn cancelled(&self) -> bool {
        self.stop.load(Ordering::SeqCst)
    }
}

#[test]
fn a_run_stopped_part_way_leaves_no_pack() {
    let image = Image::random(640, 640, PixelLayout::new(Channels::Rgb, Depth::U8), 29);
    let opts = png_options(32, 1, Default::default());
    let layout = opts.layout(image.width, image.height).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let dest = dir.path().join("stopped.vtpk");
    let sink = PackSink::create(&dest, &layout, image.layout, opts.codec, b"{}", WriteOptions::default()).unwrap();
    let watch = StopAtFirst::default();
    let result = split(image.source(), &sink, &opts, &watch);
    assert!(matches!(result, Err(TilerError::Interrupted)), "{result:?}");
    // 22 x 22 pages at LOD 0: the run stopped at the first batch's report, well before the end.
    let heard = watch.tiles.load(Ordering::SeqCst);
    assert!(heard > 0 && heard < layout.total_tiles(), "{heard} of {} tiles", layout.total_tiles());
    drop(sink);
    let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert!(left.is_empty(), "left behind: {left:?}");
}
