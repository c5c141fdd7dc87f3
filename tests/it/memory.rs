//! Where a run's memory goes (issue 28): `split --json`'s `memory` names every part the stages
//! count, and the parts stay under `--max-memory` together, in one band and in stripes, from
//! rows in memory and from strip, tiled, LZW and Deflate TIFFs (whose decoders hold buffers of their own).
//! Byte counts only: nothing here depends on timing.

use std::path::Path;

use crate::common::cli::{self, s};
use crate::common::*;
use tiff::encoder::{TiffEncoder, colortype};
use vortex_tiler::layout::Layout;
use vortex_tiler::limits::Part;
use vortex_tiler::pixel::{Channels, Depth, PixelLayout};
use vortex_tiler::split::{MemoryReport, split};
use vortex_tiler::testing::one_band_bytes;

/// `--json`'s `memory` fields for the parts, in [`Part`]'s order.
const PARTS: [(&str, Part); 6] = [
    ("decoderBytes", Part::Decoder),
    ("readAheadBytes", Part::ReadAhead),
    ("sumRowsBytes", Part::SumRows),
    ("bandBytes", Part::Bands),
    ("tilesBytes", Part::Tiles),
    ("encodedBytes", Part::Encoded),
];

/// What the stages held at once stays under the budget, and is no more than the parts' peaks
/// together nor less than any one of them. (The parts' peaks themselves may come at different
/// moments, which the threads' scheduling decides: their sum is no bound, and a run on a busy
/// machine went over the budget with it while holding 93% of it at once.)
fn check(m: &MemoryReport, what: &str) {
    let parts: Vec<u64> = PARTS.iter().map(|&(_, p)| m.peaks.part(p)).collect();
    let sum: u64 = parts.iter().sum();
    assert!(m.peaks.total <= m.budget, "{what}: held {} at once, over --max-memory {}", m.peaks.total, m.budget);
    assert!(m.peaks.total <= sum && parts.iter().all(|&p| p <= m.peaks.total), "{what}: {m:?}");
    // Every run fills bands and cuts tiles.
    assert!(m.peaks.part(Part::Bands) > 0 && m.peaks.part(Part::Tiles) > 0, "{what}: {m:?}");
    if let Some(planned) = m.planned {
        assert!(planned <= m.budget, "{what}: planned {planned} over the budget: {m:?}");
    }
}

#[test]
fn the_parts_stay_under_max_memory_in_one_band_and_in_stripes() {
    let rgb = PixelLayout::new(Channels::Rgb, Depth::U8);
    for (width, height, tile, border) in [(700, 300, 64, 0), (1500, 200, 128, 1), (333, 777, 32, 2)] {
        let image = Image::random(width, height, rgb, width as u64);
        let mut opts = png_options(tile, border, vortex_tiler::background::Background::default());
        let layout = Layout::new(width as u64, height as u64, tile, border).unwrap();
        let one_band = one_band_bytes(&layout, 3);
        // Room for the read-ahead, one band without it, and stripes.
        for (budget, read_ahead) in [(1u64 << 30, true), (one_band, false), (one_band / 2, false)] {
            opts.max_memory = budget;
            let what = format!("{width}x{height}, {tile}-texel tiles, border {border}, --max-memory {budget}");
            let sink = MemSink::default();
            let summary = split(image.source(), &sink, &opts, &()).unwrap_or_else(|e| panic!("{what}: {e}"));
            check(&summary.memory, &what);
            assert_eq!(summary.memory.budget, budget, "{what}");
            assert_eq!(
                summary.memory.peaks.part(Part::ReadAhead) > 3 * width as u64,
                read_ahead,
                "{what}: {summary:?}"
            );
            // Rows go to the cutting thread only where the source is read ahead.
            assert_eq!(summary.memory.peaks.part(Part::SumRows) > 0, read_ahead, "{what}");
            if budget == one_band / 2 {
                assert!(summary.passes > 1, "{what}: a budget under one band is striped");
            }
        }
    }
}

/// A `width x height` RGB TIFF in strips of 16 rows, by the `tiff` crate.
fn strip_tiff(path: &Path, width: u32, height: u32) {
    let image = Image::random(width, height, PixelLayout::new(Channels::Rgb, Depth::U8), 7);
    let texels: Vec<u8> = image.samples.iter().map(|&v| v as u8).collect();
    let mut tif = TiffEncoder::new(std::fs::File::create(path).unwrap()).unwrap();
    let mut img = tif.new_image::<colortype::RGB8>(width, height).unwrap();
    img.rows_per_strip(16).unwrap();
    img.write_data(&texels).unwrap();
}

#[test]
fn json_says_where_the_memory_went_for_strip_and_tiled_tiffs() {
    let dir = tempfile::tempdir().unwrap();
    let strips = dir.path().join("strips.tif");
    strip_tiff(&strips, 1000, 600);
    let mut inputs = vec![(strips.clone(), false)];
    // (input, whether its decoder holds buffers of its own)
    if have_program("tiffcp", "-h", "libtiff-tools") {
        // Tiles, and Deflate strips (decoded into the source's band, some by workers ahead).
        for (name, args) in [("tiled.tif", "none -t"), ("lzw.tif", "lzw -t"), ("deflate.tif", "zip -r 16")] {
            let file = dir.path().join(name);
            let mut tiffcp = std::process::Command::new("tiffcp");
            tiffcp.arg("-c").args(args.split(' '));
            if args.ends_with("-t") {
                tiffcp.args(["-w", "128", "-l", "128"]);
            }
            let out = tiffcp.args([s(&strips), s(&file)]).output().unwrap();
            assert!(out.status.success(), "tiffcp: {}", String::from_utf8_lossy(&out.stderr));
            inputs.push((file, true));
        }
    }
    for (input, tiled) in &inputs {
        for budget in ["1G", "4M", "1M"] {
            let pack = dir.path().join("out.vtpk");
            let out = cli::ok(&[
                "split",
                s(input),
                "--pack",
                s(&pack),
                "--force",
                "--tile-size",
                "128",
                "--max-memory",
                budget,
                "--json",
            ]);
            let doc: serde_json::Value = serde_json::from_str(&out).unwrap();
            let m = &doc["memory"];
            let what = format!("{} under --max-memory {budget}: {m}", input.display());
            let field = |name: &str| m[name].as_u64().unwrap_or_else(|| panic!("{what}: no {name}"));
            let peaks =
                vortex_tiler::limits::Peaks { parts: PARTS.map(|(name, _)| field(name)), total: field("peakBytes") };
            let planned = (!m["plannedBytes"].is_null()).then(|| field("plannedBytes"));
            check(&MemoryReport { budget: field("maxMemoryBytes"), planned, peaks }, &what);
            // A pack's writer takes the encoded tiles in order: some wait for it.
            assert!(field("encodedBytes") > 0, "{what}");
            // Uncompressed strips are read straight into the rows; tiles and Deflate strips are
            // decoded first.
            assert_eq!(field("decoderBytes") > 0, *tiled, "{what}");
        }
    }
}

#[test]
fn docs_name_every_memory_member() {
    let doc = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/docs/cli.md")).unwrap();
    for name in PARTS.map(|(name, _)| name).into_iter().chain(["maxMemoryBytes", "plannedBytes", "peakBytes"]) {
        assert!(doc.contains(&format!("| `{name}` |")), "docs/cli.md's memory table lacks {name}");
    }
}
