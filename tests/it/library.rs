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

/// What a run tells its `Progress`: the tiles in all where writing finds them other than the
/// plan counted, and each tile as it is stored.
#[derive(Default)]
struct Counted {
    total: AtomicU64,
    tiles: AtomicU64,
}

impl Progress for Counted {
    fn advance(&self, tiles: u64) {
        self.tiles.fetch_add(tiles, Ordering::SeqCst);
    }
    fn total(&self, tiles: u64) {
        self.total.store(tiles, Ordering::SeqCst);
    }
}

/// A TIFF of a slide's own levels copies their tiles, not the pyramid the plan counted: the
/// run says how many it will store (here the slide's 512-texel tiles, where the plan counted
/// 256-texel ones) and stores that many, so a progress bar ends full.
#[test]
fn a_run_of_copied_levels_tells_its_progress_their_tiles() {
    use vortex_tiler::formats::tiff::Flavour;
    use vortex_tiler::layout::Levels;
    use vortex_tiler::outputs::{Budget, Format, Output, Plan, Settings};

    let dir = tempfile::tempdir().unwrap();
    let input = crate::ome_zarr::input(dir.path(), "image", 1500, 1100, PixelLayout::new(Channels::Rgb, Depth::U8));
    // The slide: our own JPEG pyramid of 512-texel tiles.
    let slide = dir.path().join("slide.tif");
    let budget = Budget::default();
    let mut settings = Settings::default();
    settings.tiles.tile_size = Some(512);
    settings.levels = Some(Levels::Pow2);
    let source = vortex_tiler::source::open(&input, budget).unwrap();
    let outputs = vec![Output::new(Format::Tiff(Flavour::Generic), &slide)];
    Plan::new(outputs, &settings, &source.header(), &[input.as_path()], budget).unwrap().write(source, &()).unwrap();

    let source = vortex_tiler::source::open(&slide, budget).unwrap();
    let copy = dir.path().join("copy.tif");
    let outputs = vec![Output::new(Format::Tiff(Flavour::Generic), &copy)];
    let plan = Plan::new(outputs, &Settings::default(), &source.header(), &[slide.as_path()], budget).unwrap();
    let planned = plan.total_tiles();
    let counted = Counted::default();
    let wrote = plan.write(source, &counted).unwrap();
    let copied = wrote[0].tiles;
    assert_eq!(wrote[0].summary.copied, copied, "every tile of the slide's levels copied");
    assert_eq!(counted.total.load(Ordering::SeqCst), copied, "planned {planned}");
    assert_eq!(counted.tiles.load(Ordering::SeqCst), copied);
    assert!(planned > copied, "the plan counted {planned} tiles of 256, the slide has {copied} of 512");
}
