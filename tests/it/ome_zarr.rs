//! `--layout ome-zarr`: OME-Zarr 0.4 (Zarr v2), 0.5 (Zarr v3, sharded) and `.ozx` (RFC-9
//! zipped) outputs hold our pyramid's levels exactly. Checked twice: here by decoding the
//! chunks and shard indexes ourselves against the PNG tiles of the same run, and by the readers
//! of that world (zarr 3, ome-zarr, ome-zarr-models from the Python named by VORTEX_PYVIPS,
//! which `.ci/run` makes), which are skipped with a note where they are missing outside CI.

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::Command;

use vortex_tiler::pixel::{Channels, Depth, PixelLayout};

use crate::common::Image;
use crate::common::cli::{fails_with, ok, run, s};

/// Writes `image` as a PNG (16-bit samples big-endian, as PNG stores them).
fn write_png(path: &Path, image: &Image) {
    let mut enc = png::Encoder::new(std::fs::File::create(path).unwrap(), image.width, image.height);
    enc.set_color(match image.layout.channels {
        Channels::Grey => png::ColorType::Grayscale,
        Channels::GreyAlpha => png::ColorType::GrayscaleAlpha,
        Channels::Rgb => png::ColorType::Rgb,
        Channels::Rgba => png::ColorType::Rgba,
    });
    let bytes: Vec<u8> = match image.layout.depth {
        Depth::U8 => image.samples.iter().map(|v| *v as u8).collect(),
        _ => {
            enc.set_depth(png::BitDepth::Sixteen);
            image.samples.iter().flat_map(|v| v.to_be_bytes()).collect()
        }
    };
    enc.write_header().unwrap().write_image_data(&bytes).unwrap();
}

/// A test image at `dir/name.png`: smooth gradients with noise, so that zstd has work and the
/// levels differ.
fn input(dir: &Path, name: &str, w: u32, h: u32, layout: PixelLayout) -> PathBuf {
    let mut image = Image::random(w, h, layout, 7);
    let max = if layout.depth == Depth::U8 { 255u32 } else { 65535 };
    let c = layout.channels.count();
    for (i, v) in image.samples.iter_mut().enumerate() {
        let (x, y) = ((i / c) as u32 % w, (i / c) as u32 / w);
        let gradient = (x * max / w + y * max / h) / 2;
        *v = ((gradient + (*v as u32 % 16)).min(max)) as u16;
    }
    let path = dir.join(format!("{name}.png"));
    write_png(&path, &image);
    path
}

/// Our PNG tiles of the same grid (border 0, box filter: the OME-Zarr defaults): the levels
/// every output is compared with.
fn reference_tiles(input: &Path, dir: &Path, tile: u32) -> PathBuf {
    let tiles = dir.join("tiles");
    ok(&[
        "split",
        s(input),
        "-o",
        s(&tiles),
        "--border",
        "0",
        "--tile-size",
        &tile.to_string(),
        "--codec",
        "png",
        "--filter",
        "box",
        "-q",
    ]);
    tiles
}

/// Page (x, y) of `lod` from the reference tiles, as the chunk holds it: channel planes of
/// little-endian samples.
fn reference_chunk(tiles: &Path, lod: u32, x: u32, y: u32, layout: PixelLayout) -> Vec<u8> {
    let bytes = std::fs::read(tiles.join(format!("lod{lod:02}-x{x:04}-y{y:04}.png"))).unwrap();
    let samples = crate::common::decode_png(&bytes);
    let c = layout.channels.count();
    let mut planar = Vec::new();
    for ch in 0..c {
        for v in samples.iter().skip(ch).step_by(c) {
            match layout.depth {
                Depth::U8 => planar.push(*v as u8),
                _ => planar.extend_from_slice(&v.to_le_bytes()),
            }
        }
    }
    planar
}

fn read_json(path: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

/// The chunks of one 0.5 shard, by their index (offset, length; `u64::MAX` = absent), after
/// checking the index's CRC-32C.
fn shard_chunks(shard: &[u8], n: usize) -> Vec<Option<Vec<u8>>> {
    let index_len = n * n * 16;
    assert!(shard.len() >= index_len + 4, "a shard shorter than its index");
    let (body, tail) = shard.split_at(shard.len() - index_len - 4);
    let (index, crc) = tail.split_at(index_len);
    assert_eq!(crc32c::crc32c(index).to_le_bytes(), crc, "shard index checksum");
    index
        .chunks_exact(16)
        .map(|e| {
            let offset = u64::from_le_bytes(e[..8].try_into().unwrap());
            let len = u64::from_le_bytes(e[8..].try_into().unwrap());
            (offset != u64::MAX).then(|| zstd::decode_all(&body[offset as usize..][..len as usize]).unwrap())
        })
        .collect()
}

/// Every chunk of a 0.4 directory or a 0.5 directory, decoded here, equals the reference page.
fn check_chunks(out: &Path, tiles: &Path, layout: PixelLayout, v05: Option<usize>) {
    let info = read_json(&tiles.join("info.json"));
    let lods = info["lodCount"].as_u64().unwrap() as u32;
    let (columns, rows) = (info["tileColumns"].as_u64().unwrap() as u32, info["tileRows"].as_u64().unwrap() as u32);
    let c = if layout.channels.count() > 1 { "0/" } else { "" };
    let (mut seen, mut shards) = (0, 0);
    for lod in 0..lods {
        let shrink = |v: u32| (v + (1 << lod) - 1) >> lod;
        let (cols, rws) = (shrink(columns), shrink(rows));
        if let Some(n) = v05 {
            shards += cols.div_ceil(n as u32) * rws.div_ceil(n as u32);
        }
        for y in 0..rws {
            for x in 0..cols {
                let expect = reference_chunk(tiles, lod, x, y, layout);
                let got = match v05 {
                    None => {
                        zstd::decode_all(&std::fs::read(out.join(format!("{lod}/{c}{y}/{x}"))).unwrap()[..]).unwrap()
                    }
                    Some(n) => {
                        let shard =
                            std::fs::read(out.join(format!("{lod}/c/{c}{}/{}", y as usize / n, x as usize / n)))
                                .unwrap();
                        let chunks = shard_chunks(&shard, n);
                        chunks[(y as usize % n) * n + x as usize % n].clone().expect("chunk in its shard")
                    }
                };
                assert!(got == expect, "level {lod} chunk ({x}, {y}) differs");
                seen += 1;
            }
        }
    }
    // Nothing else: one file per chunk (0.4) or per shard (0.5), beside the metadata.
    let files = data_files(out);
    assert_eq!(files, if v05.is_some() { shards } else { seen }, "data files in {}", out.display());
}

/// Files under `dir` other than Zarr metadata.
fn data_files(dir: &Path) -> u32 {
    let mut count = 0;
    for entry in std::fs::read_dir(dir).unwrap() {
        let entry = entry.unwrap();
        let name = entry.file_name().to_string_lossy().into_owned();
        if entry.file_type().unwrap().is_dir() {
            count += data_files(&entry.path());
        } else if ![".zarray", ".zattrs", ".zgroup", "zarr.json"].contains(&name.as_str()) {
            count += 1;
        }
    }
    count
}

#[test]
fn chunks_and_shards_hold_the_pyramid_exactly() {
    let dir = tempfile::tempdir().unwrap();
    for (layout, w, h, tile) in [
        (PixelLayout::new(Channels::Rgb, Depth::U8), 700, 500, 128),
        (PixelLayout::new(Channels::Grey, Depth::U16), 300, 201, 64),
        (PixelLayout::new(Channels::Rgba, Depth::U16), 129, 77, 32),
    ] {
        let case = dir.path().join(format!("{w}"));
        std::fs::create_dir(&case).unwrap();
        let source = input(&case, "img", w, h, layout);
        let tiles = reference_tiles(&source, &case, tile);
        let t = tile.to_string();
        let v04 = case.join("v04.ome.zarr");
        ok(&[
            "split",
            s(&source),
            "--layout",
            "ome-zarr",
            "--ome-zarr-version",
            "0.4",
            "-o",
            s(&v04),
            "--tile-size",
            &t,
            "-q",
        ]);
        check_chunks(&v04, &tiles, layout, None);
        let zarray = read_json(&v04.join("0/.zarray"));
        assert_eq!(zarray["compressor"]["id"], "zstd");
        let v05 = case.join("v05.ome.zarr");
        ok(&[
            "split",
            s(&source),
            "--layout",
            "ome-zarr",
            "-o",
            s(&v05),
            "--tile-size",
            &t,
            "--shard-chunks",
            "2",
            "-q",
        ]);
        check_chunks(&v05, &tiles, layout, Some(2));
        let root = read_json(&v05.join("zarr.json"));
        let axes = root["attributes"]["ome"]["multiscales"][0]["axes"].as_array().unwrap().len();
        assert_eq!(axes, if layout.channels == Channels::Grey { 2 } else { 3 });
    }
}

#[test]
fn ozx_is_one_zip_with_the_metadata_first_and_the_rfc_comment() {
    let dir = tempfile::tempdir().unwrap();
    let rgb = PixelLayout::new(Channels::Rgb, Depth::U8);
    let source = input(dir.path(), "img", 300, 200, rgb);
    let tiles = reference_tiles(&source, dir.path(), 64);
    let ozx = dir.path().join("img.ozx");
    ok(&["split", s(&source), "--layout", "ome-zarr", "-o", s(&ozx), "--tile-size", "64", "--shard-chunks", "2", "-q"]);
    let mut zip = zip::ZipArchive::new(std::fs::File::open(&ozx).unwrap()).unwrap();
    let comment: serde_json::Value = serde_json::from_slice(zip.comment()).unwrap();
    assert_eq!(comment["ome"]["version"], "0.5");
    assert_eq!(comment["ome"]["zipFile"]["centralDirectory"]["jsonFirst"], true);
    let names: Vec<String> = (0..zip.len()).map(|i| zip.by_index(i).unwrap().name().unwrap().into_owned()).collect();
    assert_eq!(names[0], "zarr.json");
    let last_json = names.iter().rposition(|n| n.ends_with("zarr.json")).unwrap();
    let first_chunk = names.iter().position(|n| !n.ends_with("zarr.json")).unwrap();
    assert!(last_json < first_chunk, "{names:?}");
    // Unzipped, it is the 0.5 directory, chunk for chunk.
    let unzipped = dir.path().join("unzipped");
    for name in &names {
        let mut entry = zip.by_name(name).unwrap();
        assert_eq!(entry.compression(), zip::CompressionMethod::Stored, "{name}");
        let mut bytes = Vec::new();
        entry.read_to_end(&mut bytes).unwrap();
        let path = unzipped.join(name);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(path, bytes).unwrap();
    }
    check_chunks(&unzipped, &tiles, rgb, Some(2));
    // No staging left beside it.
    let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().filter_map(|e| e.ok()).map(|e| e.file_name()).collect();
    assert!(left.iter().all(|n| !n.to_string_lossy().contains("partial")), "{left:?}");
}

#[test]
fn refusals_name_the_flag() {
    let dir = tempfile::tempdir().unwrap();
    let source = input(dir.path(), "img", 40, 30, PixelLayout::new(Channels::Rgb, Depth::U8));
    let out = dir.path().join("o.ome.zarr");
    let o = s(&out);
    let split = |extra: &[&str]| {
        let mut args = vec!["split", s(&source), "--layout", "ome-zarr", "-o", o];
        args.extend_from_slice(extra);
        run(&args)
    };
    fails_with(&split(&["--border", "1"]), &["--border 1", "no border"]);
    fails_with(&split(&["--codec", "jpeg"]), &["--codec jpeg", "zstd"]);
    fails_with(&split(&["--quality", "90"]), &["--quality"]);
    fails_with(&split(&["--ome-zarr-version", "0.4", "--shard-chunks", "4"]), &["--shard-chunks", "0.4"]);
    fails_with(&split(&["--shard-chunks", "0"]), &["--shard-chunks 0"]);
    // Refused by the flag parser (clap's exit status 2).
    let bad_size = split(&["--pixel-size", "3 parsec"]);
    assert_eq!(bad_size.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&bad_size.stderr).contains("'parsec' in '3 parsec' is not a length unit"));
    let ozx = dir.path().join("o.ozx");
    fails_with(
        &run(&["split", s(&source), "--layout", "ome-zarr", "--ome-zarr-version", "0.4", "-o", s(&ozx)]),
        &["o.ozx", "0.5"],
    );
    fails_with(&run(&["split", s(&source), "-o", o, "--pixel-size", "1um"]), &["--pixel-size", "ome-zarr"]);
    assert!(!out.exists() && !ozx.exists());
    // A directory that is not ours is left alone; our previous output is replaced.
    std::fs::create_dir(&out).unwrap();
    std::fs::write(out.join("notes.txt"), "mine").unwrap();
    fails_with(&split(&[]), &["notes.txt"]);
    std::fs::remove_file(out.join("notes.txt")).unwrap();
    ok(&["split", s(&source), "--layout", "ome-zarr", "-o", o, "-q"]);
    ok(&["split", s(&source), "--layout", "ome-zarr", "-o", o, "-q", "--ome-zarr-version", "0.4"]);
    assert!(out.join(".zattrs").is_file() && !out.join("zarr.json").exists());
}

/// The Python with the readers: VORTEX_PYVIPS, if it imports them; else a skip with a note,
/// and a failure under CI.
fn readers() -> Option<PathBuf> {
    let python = std::env::var_os("VORTEX_PYVIPS").map(PathBuf::from);
    let works = python.as_ref().is_some_and(|p| {
        Command::new(p)
            .args(["-c", "import zarr, ome_zarr, ome_zarr_models, numpy, pyvips"])
            .output()
            .is_ok_and(|o| o.status.success())
    });
    if !works {
        assert!(std::env::var("CI").map_or(true, |v| v != "true"), "CI=true and no zarr/ome-zarr/ome-zarr-models");
        eprintln!(
            "note: skipping the OME-Zarr readers: set VORTEX_PYVIPS to a Python with zarr 3, ome-zarr, ome-zarr-models"
        );
        return None;
    }
    python
}

/// Opens every level with zarr (a zip through its ZipStore) and compares it with the PNG
/// tiles, sample for sample; checks a .ozx's entry order and comment as a zip reader sees it.
const COMPARE: &str = r#"
import json, sys, zipfile
import numpy as np, pyvips, zarr

path, tiles, tile = sys.argv[1], sys.argv[2], int(sys.argv[3])

def level(lod, w, h):
    cols, rows = -(-w // tile), -(-h // tile)
    out = None
    for y in range(rows):
        for x in range(cols):
            im = pyvips.Image.new_from_file(f"{tiles}/lod{lod:02d}-x{x:04d}-y{y:04d}.png")
            dtype = {"uchar": np.uint8, "ushort": np.uint16}[im.format]
            a = np.ndarray(buffer=im.write_to_memory(), dtype=dtype, shape=[im.height, im.width, im.bands])
            if out is None:
                out = np.zeros((rows * tile, cols * tile, im.bands), dtype)
            out[y * tile:(y + 1) * tile, x * tile:(x + 1) * tile] = a
    return out[:h, :w]

if path.endswith(".ozx"):
    with zipfile.ZipFile(path) as z:
        names = z.namelist()
        assert names[0] == "zarr.json", names[:3]
        jsons = [i for i, n in enumerate(names) if n.endswith("zarr.json")]
        assert jsons == list(range(len(jsons))), "zarr.json entries first"
        assert json.loads(z.comment)["ome"]["version"] == "0.5"
    root = zarr.open_group(zarr.storage.ZipStore(path, mode="r"), mode="r")
else:
    root = zarr.open_group(path, mode="r")
attrs = root.attrs.asdict()
multiscales = attrs["ome"]["multiscales"] if "ome" in attrs else attrs["multiscales"]
count = 0
for lod, dataset in enumerate(multiscales[0]["datasets"]):
    data = root[dataset["path"]][...]
    data = data[:, :, None] if data.ndim == 2 else np.moveaxis(data, 0, -1)
    expect = level(lod, data.shape[1], data.shape[0])
    assert expect.shape == data.shape and expect.dtype == data.dtype, (lod, expect.shape, data.shape, data.dtype)
    assert np.array_equal(expect, data), f"level {lod}: {np.count_nonzero(expect != data)} samples differ"
    count += 1
print(f"{count} levels identical")
"#;

/// Extracts a .ozx for the validator, which reads directories.
const UNZIP: &str = "import sys, zipfile; zipfile.ZipFile(sys.argv[1]).extractall(sys.argv[2])";

fn python_ok(python: &Path, args: &[&str]) -> String {
    let out = Command::new(python).args(args).output().unwrap();
    assert!(
        out.status.success(),
        "{args:?}: {}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn tool_ok(python: &Path, tool: &str, args: &[&str]) -> String {
    let bin = python.parent().unwrap().join(tool);
    let out = Command::new(&bin).args(args).output().unwrap_or_else(|e| panic!("{}: {e}", bin.display()));
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "{tool} {args:?}: {text}");
    text
}

#[test]
fn readers_validate_and_open_every_level_exactly() {
    let Some(python) = readers() else { return };
    let dir = tempfile::tempdir().unwrap();
    for (layout, w, h, tile) in [
        (PixelLayout::new(Channels::Rgb, Depth::U8), 700, 500, 128),
        (PixelLayout::new(Channels::Grey, Depth::U16), 300, 201, 64),
    ] {
        let case = dir.path().join(format!("{w}"));
        std::fs::create_dir(&case).unwrap();
        let source = input(&case, "img", w, h, layout);
        let tiles = reference_tiles(&source, &case, tile);
        let t = tile.to_string();
        for (name, extra) in [
            ("v04.ome.zarr", &["--ome-zarr-version", "0.4"][..]),
            ("v05.ome.zarr", &["--shard-chunks", "2"][..]),
            ("img.ozx", &["--shard-chunks", "2", "--pixel-size", "0.25um"][..]),
        ] {
            let out = case.join(name);
            let mut args = vec!["split", s(&source), "--layout", "ome-zarr", "-o", s(&out), "--tile-size", &t, "-q"];
            args.extend_from_slice(extra);
            ok(&args);
            let said = python_ok(&python, &["-c", COMPARE, s(&out), s(&tiles), &t]);
            assert!(said.contains("levels identical"), "{said}");
            let validated = match name.ends_with(".ozx") {
                true => {
                    let unzipped = case.join("unzipped.ome.zarr");
                    python_ok(&python, &["-c", UNZIP, s(&out), s(&unzipped)]);
                    unzipped
                }
                false => out.clone(),
            };
            let said = tool_ok(&python, "ome-zarr-models", &["validate", s(&validated)]);
            assert!(said.contains("Valid OME-Zarr") && !said.contains("Invalid"), "{said}");
            let said = tool_ok(&python, "ome_zarr", &["info", s(&validated)]);
            assert!(said.contains("Multiscales"), "{said}");
        }
    }
    // A label image in an image's labels group (made from the grey case's source).
    let case = dir.path().join("300");
    for (image, extra) in [("v04.ome.zarr", "0.4"), ("v05.ome.zarr", "0.5")] {
        let image = case.join(image);
        let cells = image.join("labels/cells");
        ok(&["split", s(&case.join("img.png")), "--layout", "ome-zarr", "--filter", "mode", "-o", s(&cells), "-q"]);
        let said = tool_ok(&python, "ome-zarr-models", &["validate", s(&image)]);
        assert!(said.contains("Valid OME-Zarr") && !said.contains("Invalid"), "{extra}: {said}");
        let said = tool_ok(&python, "ome-zarr-models", &["validate", s(&cells)]);
        assert!(said.contains("Valid OME-Zarr") && !said.contains("Invalid"), "{extra}: {said}");
        let said = tool_ok(&python, "ome_zarr", &["info", s(&image)]);
        assert!(said.contains("Label") && said.contains("labels/cells"), "{extra}: {said}");
    }
}

/// A level of a run, from its tiles (border 0): `(width, height, samples)`, one channel.
fn level_of(tiles: &crate::common::Tiles, layout: &vortex_tiler::layout::Layout, lod: u32) -> (usize, usize, Vec<u16>) {
    let (w, h) = layout.level_extent(lod);
    let (w, h, t) = (w as usize, h as usize, layout.tile_size as usize);
    let mut level = vec![0u16; w * h];
    for y in 0..h {
        for x in 0..w {
            level[y * w + x] = tiles[&(lod, (x / t) as u32, (y / t) as u32)][(y % t) * t + x % t];
        }
    }
    (w, h, level)
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(24))]

    /// `--filter mode` and `nearest` through the whole pipeline: no level holds a value absent
    /// from the source; under mode each texel is a most frequent value of its 2x2 block of the
    /// level above (the first of them in block order), under nearest the block's top-left.
    #[test]
    fn label_filters_never_invent_a_label(
        w in 1u32..90,
        h in 1u32..90,
        sixteen in proptest::bool::ANY,
        mode in proptest::bool::ANY,
        seed in 0u64..1000,
    ) {
        let depth = if sixteen { Depth::U16 } else { Depth::U8 };
        let labels: &[u16] = if sixteen { &[0, 7, 300, 40000, 65535] } else { &[0, 3, 128, 255] };
        let mut image = Image::random(w, h, PixelLayout::new(Channels::Grey, depth), seed);
        // Few labels in patches, so that blocks hold repeated values and ties.
        for v in image.samples.iter_mut() {
            *v = labels[*v as usize % labels.len()];
        }
        for (i, v) in image.samples.clone().iter().enumerate() {
            if i % 3 == 0 && i + 1 < image.samples.len() {
                image.samples[i + 1] = *v;
            }
        }
        let filter = if mode { vortex_tiler::pyramid::Filter::Mode } else { vortex_tiler::pyramid::Filter::Nearest };
        let mut opts = crate::common::png_options(16, 0, vortex_tiler::background::Background::Edge);
        opts.filter = filter;
        let (summary, tiles) = crate::common::run_pipeline(&image, &opts, 2);
        let layout = summary.layout;
        let present: std::collections::BTreeSet<u16> = image.samples.iter().copied().collect();
        let mut above = (w as usize, h as usize, image.samples.clone());
        for lod in 0..layout.lod_count {
            let (lw, lh, level) = level_of(&tiles, &layout, lod);
            for v in &level {
                proptest::prop_assert!(present.contains(v), "level {} holds {}, absent from the source", lod, v);
            }
            if lod == 0 {
                proptest::prop_assert_eq!(&level, &image.samples);
            } else {
                let (aw, ah, prev) = &above;
                for y in 0..lh {
                    for x in 0..lw {
                        let block: Vec<u16> = [(0, 0), (1, 0), (0, 1), (1, 1)]
                            .iter()
                            .map(|(dx, dy)| (2 * x + dx, 2 * y + dy))
                            .filter(|(bx, by)| bx < aw && by < ah)
                            .map(|(bx, by)| prev[by * aw + bx])
                            .collect();
                        let count = |v: u16| block.iter().filter(|b| **b == v).count();
                        let most = block.iter().map(|v| count(*v)).max().unwrap();
                        let expect = match mode {
                            true => *block.iter().find(|v| count(**v) == most).unwrap(),
                            false => block[0],
                        };
                        proptest::prop_assert_eq!(level[y * lw + x], expect, "level {} ({}, {}) of block {:?}", lod, x, y, block);
                    }
                }
            }
            above = (lw, lh, level);
        }
    }
}

/// A 16-bit label image through `--layout ome-zarr --filter mode`: the levels hold only its
/// labels, and the multiscales name the filter.
#[test]
fn label_image_to_ome_zarr_with_mode() {
    let dir = tempfile::tempdir().unwrap();
    let grey16 = PixelLayout::new(Channels::Grey, Depth::U16);
    let mut image = Image::random(97, 61, grey16, 3);
    for (i, v) in image.samples.iter_mut().enumerate() {
        let (x, y) = (i % 97, i / 97);
        // Objects: squares of 12 texels, each a label from the random field.
        *v = [1, 500, 9000, 65000][(x / 12 + 3 * (y / 12) + (*v as usize % 2)) % 4];
    }
    let source = dir.path().join("labels.png");
    write_png(&source, &image);
    let out = dir.path().join("labels.ome.zarr");
    ok(&[
        "split",
        s(&source),
        "--layout",
        "ome-zarr",
        "--filter",
        "mode",
        "-o",
        s(&out),
        "--tile-size",
        "32",
        "--shard-chunks",
        "2",
        "-q",
    ]);
    let root = read_json(&out.join("zarr.json"));
    assert_eq!(root["attributes"]["ome"]["multiscales"][0]["type"], "mode");
    let n = 2;
    for lod in 0..3u32 {
        for entry in std::fs::read_dir(out.join(format!("{lod}/c"))).unwrap() {
            for shard in std::fs::read_dir(entry.unwrap().path()).unwrap() {
                for chunk in shard_chunks(&std::fs::read(shard.unwrap().path()).unwrap(), n).into_iter().flatten() {
                    for v in chunk.chunks_exact(2).map(|b| u16::from_le_bytes([b[0], b[1]])) {
                        assert!([1, 500, 9000, 65000].contains(&v), "level {lod} holds {v}");
                    }
                }
            }
        }
    }
    let refused = run(&["split", s(&source), "--filter", "mode", "--codec", "jpeg", "-o", s(&dir.path().join("j"))]);
    fails_with(&refused, &["--filter mode", "jpeg"]);
    // -o IMAGE/labels/NAME: the labels group of an image, in the image's version.
    for version in ["0.4", "0.5"] {
        let image = dir.path().join(format!("image{version}.ome.zarr"));
        let split = |extra: &[&str]| {
            let mut args = vec!["split", s(&source), "--layout", "ome-zarr", "-q"];
            args.extend_from_slice(extra);
            run(&args)
        };
        assert!(split(&["--ome-zarr-version", version, "-o", s(&image)]).status.success());
        let cells = image.join("labels/cells");
        fails_with(&split(&["-o", s(&cells)]), &["labels/cells", "--filter mode"]);
        let other = if version == "0.4" { "0.5" } else { "0.4" };
        fails_with(&split(&["--filter", "nearest", "--ome-zarr-version", other, "-o", s(&cells)]), &[version]);
        fails_with(&split(&["--filter", "mode", "--tile-size", "16", "-o", s(&cells)]), &["matches its image"]);
        assert!(split(&["--filter", "mode", "-o", s(&cells)]).status.success());
        assert!(split(&["--filter", "nearest", "-o", s(&image.join("labels/near"))]).status.success());
        let (group, label) = match version {
            "0.4" => (read_json(&image.join("labels/.zattrs")), read_json(&cells.join(".zattrs"))),
            _ => (
                read_json(&image.join("labels/zarr.json"))["attributes"]["ome"].clone(),
                read_json(&cells.join("zarr.json"))["attributes"]["ome"].clone(),
            ),
        };
        assert_eq!(group["labels"], serde_json::json!(["cells", "near"]));
        assert_eq!(label["image-label"]["source"]["image"], "../../");
        // The image with its labels is still ours to replace.
        assert!(split(&["--ome-zarr-version", version, "-o", s(&image)]).status.success());
    }
}

/// Ctrl-C during a run removes the staging directory: nothing is left at the destination.
#[cfg(unix)]
#[test]
fn an_interrupted_run_leaves_nothing() {
    use crate::common::cli::{BIN, wait_or_kill};
    let dir = tempfile::tempdir().unwrap();
    // Noise at zstd's slowest level: the run is stopped long before it ends.
    let source = dir.path().join("noise.png");
    write_png(&source, &Image::random(2000, 2000, PixelLayout::new(Channels::Rgb, Depth::U8), 11));
    for out in ["noise.ome.zarr", "noise.ozx"] {
        let dest = dir.path().join(out);
        let child = Command::new(BIN)
            .args(["split", s(&source), "--layout", "ome-zarr", "-o", s(&dest), "-q", "--zstd-level", "22"])
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let pid = child.id().to_string();
        let staging = || {
            std::fs::read_dir(dir.path())
                .unwrap()
                .any(|e| e.unwrap().file_name().to_string_lossy().starts_with(&format!(".{out}.partial-")))
        };
        // Until the run has its staging directory (a fail-safe deadline, not a timing).
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(120);
        while !staging() && std::time::Instant::now() < deadline {
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
        let kill = |signal: &str| assert!(Command::new("kill").args([signal, &pid]).status().unwrap().success());
        kill("-STOP");
        assert!(staging(), "the run made no staging directory, or finished before it was stopped");
        kill("-INT");
        kill("-CONT");
        let result = wait_or_kill(child.id(), "an interrupted ome-zarr split", || child.wait_with_output().unwrap());
        let e = String::from_utf8_lossy(&result.stderr);
        assert_eq!(result.status.code(), Some(130), "{e}");
        assert!(!staging() && !dest.exists(), "{out}: {e}");
    }
}
