//! Several outputs from one run (`split -o web --layout dzi --pack slide.vtpk ...`): each
//! output's files are those of a run of its own, byte for byte, whether the outputs share a
//! pyramid and its encodings or are cut side by side; a run whose last output fails leaves
//! none; each --layout belongs to the -o before it.

use std::collections::BTreeMap;
use std::path::Path;

use vortex_tiler::pixel::{Channels, Depth, PixelLayout};

use crate::common::Image;
use crate::common::cli::{fails_with, ok, run, s};

/// Every file under `path` (or the file itself), by its path relative to it, with its bytes.
pub(crate) fn files(path: &Path) -> BTreeMap<String, Vec<u8>> {
    fn walk(root: &Path, at: &Path, out: &mut BTreeMap<String, Vec<u8>>) {
        if at.is_file() {
            let name = at.strip_prefix(root).unwrap().to_string_lossy().into_owned();
            out.insert(name, std::fs::read(at).unwrap());
            return;
        }
        for entry in std::fs::read_dir(at).unwrap_or_else(|e| panic!("{}: {e}", at.display())) {
            walk(root, &entry.unwrap().path(), out);
        }
    }
    let mut out = BTreeMap::new();
    walk(path, path, &mut out);
    out
}

/// An RGB PNG of an odd size, so that edge tiles are cropped (Deep Zoom, IIIF) or padded
/// (packs, XYZ) and the levels end on partial pages.
fn odd_png(dir: &Path, width: u32, height: u32) -> std::path::PathBuf {
    let image = Image::random(width, height, PixelLayout::new(Channels::Rgb, Depth::U8), 42);
    let path = dir.join("in.png");
    let mut enc = png::Encoder::new(std::fs::File::create(&path).unwrap(), width, height);
    enc.set_color(png::ColorType::Rgb);
    let bytes: Vec<u8> = image.samples.iter().map(|v| *v as u8).collect();
    enc.write_header().unwrap().write_image_data(&bytes).unwrap();
    path
}

/// Runs each output alone (`alone[k]`: its own flags) into `dir/one/`, then all of them in one
/// run (`together`) into `dir/all/`, and asserts that every output's files are the same. The
/// flags name outputs by `{}`, replaced by the run's folder. Returns the one run's `--json`.
fn same_as_separate_runs(
    input: &Path,
    dir: &Path,
    alone: &[&[&str]],
    together: &[&str],
    names: &[&str],
) -> serde_json::Value {
    let args = |flags: &[&str], folder: &Path| -> Vec<String> {
        let mut a = vec!["split".to_string(), s(input).to_string()];
        a.extend(flags.iter().map(|f| f.replace("{}", s(folder))));
        a
    };
    let (one, all) = (dir.join("one"), dir.join("all"));
    for folder in [&one, &all] {
        std::fs::create_dir_all(folder).unwrap();
    }
    for flags in alone {
        let a = args(flags, &one);
        ok(&a.iter().map(String::as_str).chain(["-q"]).collect::<Vec<_>>());
    }
    let a = args(together, &all);
    let json = ok(&a.iter().map(String::as_str).chain(["--json"]).collect::<Vec<_>>());
    for name in names {
        let (a, b) = (files(&one.join(name)), files(&all.join(name)));
        assert!(!a.is_empty(), "{name}: no files");
        assert_eq!(a.keys().collect::<Vec<_>>(), b.keys().collect::<Vec<_>>(), "{name}: the file sets differ");
        for (file, bytes) in &a {
            assert!(bytes == &b[file], "{name}/{file}: the one run's bytes differ from the run of its own");
        }
    }
    // Nothing but the outputs is left beside them.
    let left: Vec<String> =
        std::fs::read_dir(&all).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    assert_eq!(left.len(), names.len(), "{left:?}");
    serde_json::from_str(&json).unwrap()
}

/// The pyramid (`pyramid` in --json) and tiles encoded of each output, by its layout.
fn pyramids(json: &serde_json::Value) -> BTreeMap<String, (u64, u64)> {
    let outputs = json["outputs"].as_array().expect("an outputs array");
    outputs
        .iter()
        .map(|o| {
            (
                o["layout"].as_str().unwrap().to_string(),
                (o["pyramid"].as_u64().unwrap(), o["encoded"].as_u64().unwrap()),
            )
        })
        .collect()
}

/// Deep Zoom, a pack, PMTiles and a TIFF of one tile size and no border share one pyramid and
/// each page's encoding (Deep Zoom's cropped edge pages apart); OME-Zarr (zstd chunks, the box
/// filter) is cut beside them from the same rows. Each is what its own run writes: the TIFF
/// too, whose tiles are stored in the producer's order.
#[test]
fn shared_and_side_by_side_outputs_are_their_own_runs_files() {
    let dir = tempfile::tempdir().unwrap();
    let input = odd_png(dir.path(), 1003, 701);
    let json = same_as_separate_runs(
        &input,
        dir.path(),
        &[
            &["-o", "{}/web", "--layout", "dzi", "--tile-size", "256", "--overlap", "0"],
            &["--pack", "{}/in.vtpk", "--tile-size", "256", "--border", "0"],
            &["--pmtiles", "{}/in.pmtiles", "--tile-size", "256"],
            &["-o", "{}/in.tif", "--tile-size", "256"],
            // 0.4: one file per chunk, whose bytes do not depend on the order chunks arrive in.
            &["-o", "{}/in.ome.zarr", "--tile-size", "256", "--ome-zarr-version", "0.4"],
        ],
        &[
            "-o",
            "{}/web",
            "--layout",
            "dzi",
            "--overlap",
            "0",
            "--pack",
            "{}/in.vtpk",
            "--border",
            "0",
            "--pmtiles",
            "{}/in.pmtiles",
            "-o",
            "{}/in.tif",
            "-o",
            "{}/in.ome.zarr",
            "--ome-zarr-version",
            "0.4",
            "--tile-size",
            "256",
        ],
        &["web", "in.vtpk", "in.pmtiles", "in.tif", "in.ome.zarr"],
    );
    let p = pyramids(&json);
    assert_eq!(p["dzi"].0, p["pack"].0, "Deep Zoom and the pack share a pyramid: {p:?}");
    assert_eq!(p["tiff"].0, p["pack"].0, "the TIFF shares it too: {p:?}");
    assert_ne!(p["dzi"].0, p["ome-zarr"].0, "{p:?}");
    assert_eq!(json["pyramids"], p.values().map(|v| v.0).max().unwrap() + 1);
}

/// Outputs that differ only in how they encode the pages share one pyramid: with OME-Zarr's
/// filter (`--filter box`), a 16-bit image's Deep Zoom (8-bit JPEG tiles) and OME-Zarr (16-bit
/// raw chunks, zstd-compressed) are cut once, each page encoded once for each, and each holds
/// what its own run writes.
#[test]
fn outputs_of_one_filter_share_the_pyramid_whatever_their_encodings() {
    let dir = tempfile::tempdir().unwrap();
    let image = Image::random(517, 301, PixelLayout::new(Channels::Rgb, Depth::U16), 7);
    let input = dir.path().join("in.png");
    let mut enc = png::Encoder::new(std::fs::File::create(&input).unwrap(), image.width, image.height);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Sixteen);
    let bytes: Vec<u8> = image.samples.iter().flat_map(|v| v.to_be_bytes()).collect();
    enc.write_header().unwrap().write_image_data(&bytes).unwrap();
    let json = same_as_separate_runs(
        &input,
        dir.path(),
        &[
            &[
                "-o",
                "{}/web",
                "--layout",
                "dzi",
                "--tile-size",
                "128",
                "--overlap",
                "0",
                "--filter",
                "box",
                "--codec",
                "jpeg",
            ],
            &["-o", "{}/in.ome.zarr", "--tile-size", "128", "--ome-zarr-version", "0.4"],
        ],
        &[
            "-o",
            "{}/web",
            "--layout",
            "dzi",
            "--overlap",
            "0",
            "-o",
            "{}/in.ome.zarr",
            "--ome-zarr-version",
            "0.4",
            "--tile-size",
            "128",
            "--filter",
            "box",
            "--codec",
            "jpeg",
        ],
        &["web", "in.ome.zarr"],
    );
    let p = pyramids(&json);
    assert_eq!((json["pyramids"].as_u64(), p["dzi"].0, p["ome-zarr"].0), (Some(1), 0, 0), "{json}");
    let stored = |layout: &str| {
        let o = json["outputs"].as_array().unwrap().iter().find(|o| o["layout"] == layout).unwrap();
        o["stored"].clone()
    };
    assert_eq!(
        (stored("dzi").as_str(), stored("ome-zarr").as_str()),
        (Some("rgb 8-bit"), Some("rgb 16-bit")),
        "{json}"
    );
}

/// Outputs of other tile sizes and codecs (our directory's 128-texel PNG tiles with a border,
/// IIIF's 512-texel tiles, Google's 256, OME-Zarr 0.5's zstd chunks in shards of 2 x 2) make
/// four pyramids from one read. A shard's chunks come from many encoder threads in any order;
/// its file holds them in chunk order, so it too is its own run's, byte for byte.
#[test]
fn outputs_of_other_tile_sizes_are_cut_side_by_side() {
    let dir = tempfile::tempdir().unwrap();
    let input = odd_png(dir.path(), 777, 555);
    // A flag is the run's: --codec png for every image output; OME-Zarr, which writes zstd
    // chunks, leaves it to them (alone, it would refuse it).
    let json = same_as_separate_runs(
        &input,
        dir.path(),
        &[
            &["-o", "{}/tiles", "--codec", "png"],
            &["-o", "{}/iiif", "--layout", "iiif", "--codec", "png"],
            &["-o", "{}/google", "--layout", "google", "--codec", "png"],
            &["-o", "{}/in.ome.zarr", "--shard-chunks", "2"],
        ],
        &[
            "-o",
            "{}/tiles",
            "-o",
            "{}/iiif",
            "--layout",
            "iiif",
            "-o",
            "{}/google",
            "--layout",
            "google",
            "--codec",
            "png",
            "-o",
            "{}/in.ome.zarr",
            "--shard-chunks",
            "2",
        ],
        &["tiles", "iiif", "google", "in.ome.zarr"],
    );
    assert_eq!((json["pyramids"].as_u64(), json["sourceReads"].as_u64()), (Some(4), Some(1)), "{json}");
}

/// With a budget that holds one band of the image for each pyramid alone but not the three
/// side by side (16 MiB for this 3000-texel-wide image; 48 MiB holds them side by side), the
/// pyramids are cut one after another, the source read once for each: the same files.
#[test]
fn a_budget_too_small_for_side_by_side_cuts_one_after_another() {
    let dir = tempfile::tempdir().unwrap();
    let input = odd_png(dir.path(), 3000, 400);
    let shared = ["--codec", "png", "--max-memory", "16M"];
    let flags: [&[&str]; 3] = [&["-o", "{}/a"], &["-o", "{}/b", "--layout", "xyz"], &["-o", "{}/c", "--layout", "dzi"]];
    let alone: Vec<Vec<&str>> = flags.iter().map(|f| [*f, &shared[..]].concat()).collect();
    let alone: Vec<&[&str]> = alone.iter().map(Vec::as_slice).collect();
    let together = [flags.concat(), shared.to_vec()].concat();
    let json = same_as_separate_runs(&input, dir.path(), &alone, &together, &["a", "b", "c"]);
    let passes: Vec<u64> = json["outputs"].as_array().unwrap().iter().map(|o| o["passes"].as_u64().unwrap()).collect();
    assert_eq!(passes, [1, 1, 1], "each pyramid in one pass of its own");
    assert_eq!(json["sourceReads"], 3, "{json}");
}

/// The last output cannot be written (its folder is missing): the run fails naming it, and
/// the outputs before it, whose sinks had started, leave nothing behind.
#[test]
fn a_failing_output_leaves_none_of_the_others() {
    let dir = tempfile::tempdir().unwrap();
    let input = odd_png(dir.path(), 300, 200);
    let (web, pack) = (dir.path().join("web"), dir.path().join("missing").join("in.vtpk"));
    let out = run(&[
        "split",
        s(&input),
        "-o",
        s(&web),
        "--layout",
        "dzi",
        "-o",
        s(&dir.path().join("t.ome.zarr")),
        "--pack",
        s(&pack),
    ]);
    fails_with(&out, &["in.vtpk"]);
    let left: Vec<String> =
        std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    assert_eq!(left, ["in.png"], "left behind: {left:?}");
}

/// Each --layout belongs to the -o before it (one before any -o to the first); a name that
/// says its format needs none; mistakes are refused before anything is written.
#[test]
fn each_layout_belongs_to_the_output_before_it() {
    let dir = tempfile::tempdir().unwrap();
    let input = odd_png(dir.path(), 300, 200);
    let at = |name: &str| dir.path().join(name);
    ok(&["split", s(&input), "--layout", "dzi", "-o", s(&at("a")), "-o", s(&at("b")), "-o", s(&at("c.pmtiles")), "-q"]);
    assert!(at("a/in.dzi").is_file() && at("b/info.json").is_file() && at("c.pmtiles").is_file());
    ok(&["split", s(&input), "-o", s(&at("d")), "-o", s(&at("e")), "--layout", "iiif", "-o", s(&at("f.vtpk")), "-q"]);
    assert!(at("d/info.json").is_file() && at("e/info.json").is_file() && at("f.vtpk").is_file());
    let iiif: serde_json::Value = serde_json::from_slice(&std::fs::read(at("e/info.json")).unwrap()).unwrap();
    assert_eq!(iiif["type"], "ImageService3", "e is IIIF: {iiif}");

    let g = at("g");
    fails_with(
        &run(&["split", s(&input), "-o", s(&g), "--layout", "dzi", "--layout", "iiif"]),
        &["two layouts", "dzi", "iiif"],
    );
    fails_with(&run(&["split", s(&input), "-o", s(&g), "-o", s(&g)]), &["paths of their own"]);
    fails_with(&run(&["split", s(&input), "-o", s(&g), "--pack", s(&g.join("x.vtpk"))]), &["neither inside the other"]);
    fails_with(&run(&["split", s(&input)]), &["no output", "-o DIR", "--pack FILE", "--pmtiles FILE"]);
    // A setting no output reads is refused as a one-output run refuses it.
    fails_with(
        &run(&["split", s(&input), "-o", s(&g), "--pack", s(&at("h.vtpk")), "--overlap", "2"]),
        &["--overlap belongs to a viewer layout"],
    );
    assert!(!g.exists() && !at("h.vtpk").exists());
}

/// `split --help` groups its flags as ripgrep's help does, so that each is found under what it
/// is for; `-t` is --tile-size.
#[test]
fn help_groups_the_flags_by_what_they_are_for() {
    let help = ok(&["split", "--help"]);
    let headings: Vec<&str> = help.lines().filter(|l| !l.starts_with(' ') && l.ends_with(':')).collect();
    for want in ["Input:", "Outputs:", "Tiles:", "Pyramid and filter:", "Colour:", "Memory and speed:", "Scale-out:"] {
        assert!(headings.contains(&want), "no {want} section in {headings:?}");
    }
    // The flags (lines that start with one) under each heading.
    let mut under: Vec<(&str, &str)> = Vec::new();
    let mut heading = "";
    for line in help.lines() {
        if !line.starts_with(' ') && line.ends_with(':') {
            heading = line;
        } else if let Some(flag) = line.trim_start().split([',', ' ']).find(|w| w.starts_with("--")) {
            under.push((heading, flag));
        }
    }
    for flag in ["--output", "--layout", "--pack", "--pmtiles", "--ome-zarr-version", "--iiif-id"] {
        assert!(under.contains(&("Outputs:", flag)), "{flag} is not under Outputs: {under:?}");
    }
    assert!(
        under.contains(&("Tiles:", "--quality")) && under.contains(&("Memory and speed:", "--threads")),
        "{under:?}"
    );
    let dir = tempfile::tempdir().unwrap();
    let input = odd_png(dir.path(), 100, 80);
    ok(&["split", s(&input), "-o", s(&dir.path().join("t")), "-t", "64", "-q"]);
    let info: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("t/info.json")).unwrap()).unwrap();
    assert_eq!(info["tileSize"], 64);
}
