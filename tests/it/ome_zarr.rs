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
pub(crate) fn write_png(path: &Path, image: &Image) {
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
pub(crate) fn input(dir: &Path, name: &str, w: u32, h: u32, layout: PixelLayout) -> PathBuf {
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
    // Without --layout ome-zarr or a name that says it, -o is our tile directory.
    let plain = dir.path().join("plain");
    fails_with(&run(&["split", s(&source), "-o", s(&plain), "--pixel-size", "1um"]), &["--pixel-size", "ome-zarr"]);
    assert!(!out.exists() && !ozx.exists() && !plain.exists());
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
    crate::common::python_with(
        "zarr, ome_zarr, ome_zarr_models, numpy, pyvips",
        "the OME-Zarr readers",
        "zarr 3, ome-zarr, ome-zarr-models, numpy and pyvips",
    )
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

/// The zstd-decoded chunks of a level of channel `c` of an OME-Zarr directory (`c`: `None`
/// for a grey image without a channel axis), by (x, y), from its chunk files or shards.
fn level_chunks(out: &Path, lod: u32, c: Option<u32>, v05: Option<u32>) -> Vec<((u32, u32), Vec<u8>)> {
    let c = c.map_or(String::new(), |c| format!("{c}/"));
    let mut chunks = Vec::new();
    let root = match v05 {
        None => out.join(format!("{lod}/{c}")),
        Some(_) => out.join(format!("{lod}/c/{c}")),
    };
    for row in std::fs::read_dir(&root).unwrap() {
        let row = row.unwrap().path();
        // The level's own metadata (`.zarray`, `zarr.json`) beside its rows.
        let Ok(r) = row.file_name().unwrap().to_str().unwrap().parse::<u32>() else { continue };
        for file in std::fs::read_dir(&row).unwrap() {
            let file = file.unwrap().path();
            let q: u32 = file.file_name().unwrap().to_str().unwrap().parse().unwrap();
            let bytes = std::fs::read(&file).unwrap();
            match v05 {
                None => chunks.push(((q, r), zstd::decode_all(&bytes[..]).unwrap())),
                Some(n) => {
                    for (i, chunk) in shard_chunks(&bytes, n as usize).into_iter().enumerate() {
                        let (x, y) = (q * n + i as u32 % n, r * n + i as u32 / n);
                        chunks.extend(chunk.map(|c| ((x, y), c)));
                    }
                }
            }
        }
    }
    chunks.sort();
    chunks
}

#[test]
fn channel_files_make_one_array_each_channel_its_grey_pyramid() {
    let dir = tempfile::tempdir().unwrap();
    let grey16 = PixelLayout::new(Channels::Grey, Depth::U16);
    let (w, h, channels) = (150u32, 97u32, 5u32);
    let mut files = Vec::new();
    let mut ranges = Vec::new();
    for k in 0..channels {
        // Each channel its own content and range, so that a swapped channel shows.
        let mut image = Image::random(w, h, grey16, 11 + k as u64);
        for v in image.samples.iter_mut() {
            *v = *v / (k as u16 + 2) + 1000 * k as u16;
        }
        ranges.push((*image.samples.iter().min().unwrap(), *image.samples.iter().max().unwrap()));
        let path = dir.path().join(format!("ch{k}.png"));
        write_png(&path, &image);
        files.push(path);
    }
    let channel_args: Vec<&str> = files.iter().flat_map(|f| ["--channel", s(f)]).collect();
    for (name, v05, extra) in [
        ("v04.ome.zarr", None, &["--ome-zarr-version", "0.4"][..]),
        ("v05.ome.zarr", Some(2), &["--shard-chunks", "2"]),
    ] {
        let out = dir.path().join(name);
        let mut args = vec!["split", "--layout", "ome-zarr", "-o", s(&out), "--tile-size", "32", "-q"];
        args.extend_from_slice(&channel_args);
        args.extend_from_slice(extra);
        ok(&args);
        let (meta, attrs) = match v05 {
            None => (read_json(&out.join("0/.zarray")), read_json(&out.join(".zattrs"))),
            Some(_) => {
                let root = read_json(&out.join("zarr.json"));
                (read_json(&out.join("0/zarr.json")), root["attributes"]["ome"].clone())
            }
        };
        assert_eq!(meta["shape"], serde_json::json!([channels, h, w]));
        let chunk = match v05 {
            None => &meta["chunks"],
            Some(_) => &meta["codecs"][0]["configuration"]["chunk_shape"],
        };
        assert_eq!(*chunk, serde_json::json!([1, 32, 32]));
        assert_eq!(attrs["multiscales"][0]["axes"][0]["name"], "c");
        let omero = attrs["omero"]["channels"].as_array().unwrap();
        assert_eq!(omero.len(), channels as usize);
        for (k, entry) in omero.iter().enumerate() {
            // Named by their files, windowed by their data.
            assert_eq!(entry["label"], format!("ch{k}"));
            assert_eq!(entry["window"]["start"], ranges[k].0);
            assert_eq!(entry["window"]["end"], ranges[k].1);
        }
        let levels = attrs["multiscales"][0]["datasets"].as_array().unwrap().len() as u32;
        for (k, file) in files.iter().enumerate() {
            let grey = dir.path().join(format!("{k}-{name}"));
            let mut args = vec!["split", s(file), "--layout", "ome-zarr", "-o", s(&grey), "--tile-size", "32", "-q"];
            args.extend_from_slice(extra);
            ok(&args);
            for lod in 0..levels {
                let ours = level_chunks(&out, lod, Some(k as u32), v05);
                assert!(!ours.is_empty());
                assert!(ours == level_chunks(&grey, lod, None, v05), "{name}: channel {k}, level {lod}");
            }
        }
    }
}

#[test]
fn many_channels_are_refused_where_a_texel_holds_four() {
    let dir = tempfile::tempdir().unwrap();
    let grey = PixelLayout::new(Channels::Grey, Depth::U8);
    let files: Vec<PathBuf> = (0..5).map(|k| input(dir.path(), &format!("c{k}"), 40, 30, grey)).collect();
    let channel_args: Vec<&str> = files.iter().flat_map(|f| ["--channel", s(f)]).collect();
    let split = |extra: &[&str]| {
        let mut args = vec!["split"];
        args.extend_from_slice(&channel_args);
        args.extend_from_slice(extra);
        run(&args)
    };
    let out = dir.path().join("out");
    let o = s(&out);
    fails_with(&split(&["-o", o]), &["5 channels", "a vortex output", "--channels 0,1,2", "--layout ome-zarr"]);
    fails_with(&split(&["-o", o, "--layout", "dzi"]), &["a dzi output", "--channels 0,1,2"]);
    fails_with(&split(&["-o", o, "--layout", "dzi", "--channels", "0,1"]), &["2 channels", "--channels 0,1,2"]);
    fails_with(&split(&["--pack", o]), &["5 channels", "a pack", "--channels 0,1,2"]);
    assert!(!out.exists());
    // One or three picked are a grey or an RGB image.
    ok(&["split", "--channel", s(&files[0]), "--channel", s(&files[1]), "-o", o, "--channels", "1", "-q"]);
    assert_eq!(read_json(&out.join("info.json"))["tileFormat"], "luminance");
    let rgb = dir.path().join("rgb");
    let three = ["--channel", s(&files[0]), "--channel", s(&files[1]), "--channel", s(&files[2])];
    ok(&[&["split", "-o", s(&rgb), "--channels", "2,0,1", "-q"][..], &three].concat());
    assert_eq!(read_json(&rgb.join("info.json"))["tileFormat"], "rgb");
    // A channel past the last, or named twice, is refused.
    let five = dir.path().join("five.ome.zarr");
    let f = s(&five);
    fails_with(&split(&["--layout", "ome-zarr", "-o", f, "--channels", "0,5"]), &["--channels 5", "0 to 4"]);
    fails_with(&split(&["--layout", "ome-zarr", "-o", f, "--channels", "1,1"]), &["channel 1 twice"]);
    // Channels of different sizes, an INPUT beside --channel.
    let small = input(dir.path(), "small", 20, 30, grey);
    fails_with(
        &run(&["split", "--channel", s(&files[0]), "--channel", s(&small), "--layout", "ome-zarr", "-o", s(&five)]),
        &["small.png", "20x30", "40x30"],
    );
    fails_with(&run(&["split", s(&files[0]), "--channel", s(&files[1]), "-o", s(&five)]), &["--channel", "INPUT"]);
    assert!(!five.exists());
}

/// Writes 5-channel 16-bit TIFFs with tifffile: samples stored together (strips), separate
/// planes (strips; tiles with Deflate), an OME-TIFF of named grey planes; and each channel
/// alone as a grey TIFF.
const MANY_CHANNELS: &str = r#"
import sys
import numpy as np, tifffile
out = sys.argv[1]
h, w, c = 301, 410, 5
rng = np.random.default_rng(5)
y, x = np.mgrid[0:h, 0:w]
data = np.stack([((x * (k + 1) * 37 + y * 11 * (k + 2)) % 60000 + rng.integers(0, 50, (h, w))).astype(np.uint16) for k in range(c)])
# Optional second argument: the same values as uint32 (spread over the whole range) or float32
# (not whole numbers, so that means are not rounded).
kind = sys.argv[2] if len(sys.argv) > 2 else "uint16"
if kind == "uint32":
    data = data.astype(np.uint32) * 65537
elif kind == "float32":
    data = data.astype(np.float32) / 7.0 - 1000.0
elif kind == "float16":
    data = (data % 2048).astype(np.float16)
tifffile.imwrite(f"{out}/chunky.tif", np.moveaxis(data, 0, -1), photometric="minisblack", planarconfig="contig", rowsperstrip=16)
if kind == "float16":
    sys.exit(0)  # only the chunky file: it is refused
tifffile.imwrite(f"{out}/planar.tif", data, photometric="minisblack", planarconfig="separate", rowsperstrip=16)
tifffile.imwrite(f"{out}/tiled.tif", data, photometric="minisblack", planarconfig="separate", tile=(64, 64), compression="zlib")
names = ["DAPI", "GFP", "RFP", "Cy5", "BF"]
tifffile.imwrite(f"{out}/ome.ome.tif", data, metadata={"axes": "CYX", "Channel": {"Name": names}})
for k in range(c):
    tifffile.imwrite(f"{out}/c{k}.tif", data[k])
"#;

/// Every level of an OME-Zarr of channels, read by zarr: each channel equals the grey
/// OME-Zarr of its own file, and the omero names are the ones given.
const CHANNELS_COMPARE: &str = r#"
import sys
import numpy as np, zarr
path, names, greys = sys.argv[1], sys.argv[2].split(","), sys.argv[3:]
root = zarr.open_group(zarr.storage.ZipStore(path, mode="r") if path.endswith(".ozx") else path, mode="r")
attrs = root.attrs.asdict()
ome = attrs.get("ome", attrs)
assert [c["label"] for c in ome["omero"]["channels"]] == names, ome["omero"]
levels = 0
for d in ome["multiscales"][0]["datasets"]:
    a = root[d["path"]][...]
    assert a.shape[0] == len(greys), a.shape
    for k, grey in enumerate(greys):
        b = zarr.open_group(grey, mode="r")[d["path"]][...]
        assert a.dtype == b.dtype and np.array_equal(a[k], b), f"level {d['path']}, channel {k}"
    levels += 1
print(f"{levels} levels x {len(greys)} channels identical")
"#;

/// The readers' Python when it also has tifffile, which writes the multi-channel TIFFs.
fn readers_and_tifffile() -> Option<PathBuf> {
    let python = readers()?;
    let has_tifffile = Command::new(&python).args(["-c", "import tifffile"]).output().is_ok_and(|o| o.status.success());
    if !has_tifffile {
        crate::common::skip_unless_ci("the multi-channel TIFFs", "no tifffile in VORTEX_PYVIPS");
        return None;
    }
    Some(python)
}

#[test]
fn five_channel_tiffs_go_end_to_end() {
    let Some(python) = readers_and_tifffile() else { return };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    python_ok(&python, &["-c", MANY_CHANNELS, s(d)]);
    for (version, extra) in [("0.4", &["--ome-zarr-version", "0.4"][..]), ("0.5", &["--shard-chunks", "2"][..])] {
        let mut greys = Vec::new();
        for k in 0..5 {
            let grey = d.join(format!("g{k}-{version}.ome.zarr"));
            let mut args = vec!["split", "--layout", "ome-zarr", "--tile-size", "128", "-q", "-o", s(&grey)];
            args.extend_from_slice(extra);
            let file = d.join(format!("c{k}.tif"));
            args.push(s(&file));
            ok(&args);
            greys.push(grey);
        }
        let greys: Vec<&str> = greys.iter().map(|g| s(g)).collect();
        for (input, names) in [
            ("chunky.tif", "c0,c1,c2,c3,c4"),
            ("planar.tif", "c0,c1,c2,c3,c4"),
            ("tiled.tif", "c0,c1,c2,c3,c4"),
            ("ome.ome.tif", "DAPI,GFP,RFP,Cy5,BF"),
        ] {
            let out = d.join(format!("{input}-{version}.ome.zarr"));
            let source = d.join(input);
            let mut args = vec!["split", s(&source), "--layout", "ome-zarr", "--tile-size", "128", "-q", "-o", s(&out)];
            args.extend_from_slice(extra);
            ok(&args);
            let mut compare = vec!["-c", CHANNELS_COMPARE, s(&out), names];
            compare.extend_from_slice(&greys);
            let said = python_ok(&python, &compare);
            assert!(said.contains("3 levels x 5 channels identical"), "{input} {version}: {said}");
            let said = tool_ok(&python, "ome-zarr-models", &["validate", s(&out)]);
            assert!(said.contains("Valid OME-Zarr") && !said.contains("Invalid"), "{input} {version}: {said}");
        }
    }
    // Picked channels, in the order picked: the OME-TIFF's 4 and 0.
    let out = d.join("picked.ome.zarr");
    ok(&[
        "split",
        s(&d.join("ome.ome.tif")),
        "--layout",
        "ome-zarr",
        "--tile-size",
        "128",
        "--channels",
        "4,0",
        "-q",
        "-o",
        s(&out),
    ]);
    let greys = [d.join("g4-0.5.ome.zarr"), d.join("g0-0.5.ome.zarr")];
    let said = python_ok(&python, &["-c", CHANNELS_COMPARE, s(&out), "BF,DAPI", s(&greys[0]), s(&greys[1])]);
    assert!(said.contains("3 levels x 2 channels identical"), "{said}");
}

/// 32-bit unsigned and float channel sets: the same five channels as above as `uint32` and
/// `float32`, each channel of the array equal to the grey pyramid of its own file.
#[test]
fn five_channel_32_bit_tiffs_go_end_to_end() {
    let Some(python) = readers_and_tifffile() else { return };
    for kind in ["uint32", "float32"] {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        python_ok(&python, &["-c", MANY_CHANNELS, s(d), kind]);
        let split = |input: &Path, out: &Path| {
            ok(&[
                "split",
                s(input),
                "--layout",
                "ome-zarr",
                "--tile-size",
                "128",
                "--shard-chunks",
                "2",
                "-q",
                "-o",
                s(out),
            ])
        };
        let greys: Vec<PathBuf> = (0..5).map(|k| d.join(format!("g{k}.ome.zarr"))).collect();
        for (k, grey) in greys.iter().enumerate() {
            split(&d.join(format!("c{k}.tif")), grey);
        }
        let greys: Vec<&str> = greys.iter().map(|g| s(g)).collect();
        for input in ["chunky.tif", "planar.tif", "tiled.tif"] {
            let out = d.join(format!("{input}.ome.zarr"));
            split(&d.join(input), &out);
            let mut compare = vec!["-c", CHANNELS_COMPARE, s(&out), "c0,c1,c2,c3,c4"];
            compare.extend_from_slice(&greys);
            let said = python_ok(&python, &compare);
            assert!(said.contains("3 levels x 5 channels identical"), "{kind} {input}: {said}");
            let said = tool_ok(&python, "ome-zarr-models", &["validate", s(&out)]);
            assert!(said.contains("Valid OME-Zarr") && !said.contains("Invalid"), "{kind} {input}: {said}");
        }
    }
    // Half floats are widened to f32 as a single image's are: each channel's full resolution
    // is tifffile's samples as float32, exactly.
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    python_ok(&python, &["-c", MANY_CHANNELS, s(d), "float16"]);
    let out = d.join("half.ome.zarr");
    ok(&["split", s(&d.join("chunky.tif")), "--layout", "ome-zarr", "-q", "-o", s(&out)]);
    let said = python_ok(&python, &["-c", HALF_COMPARE, s(&out), s(&d.join("chunky.tif"))]);
    assert!(said.contains("5 channels exact"), "{said}");
}

/// Level 0 of an OME-Zarr of channels against the TIFF's samples (texels last) as float32.
const HALF_COMPARE: &str = r#"
import sys
import numpy as np, tifffile, zarr
root = zarr.open_group(sys.argv[1], mode="r")
attrs = root.attrs.asdict()
ome = attrs.get("ome", attrs)
a = root[ome["multiscales"][0]["datasets"][0]["path"]][...]
b = np.moveaxis(tifffile.imread(sys.argv[2]), -1, 0).astype(np.float32)
assert a.dtype == np.float32 and np.array_equal(a, b), (a.dtype, a.shape, b.shape)
print(f"{a.shape[0]} channels exact")
"#;

/// The Python with napari and its OME-Zarr reader (VORTEX_NAPARI, which `.ci/run` makes), and
/// `xvfb-run` to give its Qt window a display; else a skip with a note, and a failure under CI.
fn napari() -> Option<PathBuf> {
    let python = std::env::var_os("VORTEX_NAPARI").map(PathBuf::from);
    let works = python.as_ref().is_some_and(|p| {
        Command::new(p)
            .args(["-c", "import napari, napari_ome_zarr, imageio"])
            .output()
            .is_ok_and(|o| o.status.success())
    }) && Command::new("xvfb-run").arg("--help").output().is_ok();
    if !works {
        crate::common::skip_unless_ci(
            "napari",
            "no napari or xvfb-run: set VORTEX_NAPARI to a Python with napari and napari-ome-zarr, install xvfb",
        );
        return None;
    }
    python
}

/// Opens an OME-Zarr in napari (its own reader plugin, in a shown window under Xvfb: a
/// hidden one renders nothing), exports the figure at the data's resolution, saves it, and
/// compares it with what the `omero` metadata asks for, worked out from the source images
/// alone: each channel windowed to its own range, in blue, green, red, added up.
const NAPARI_SHOT: &str = r#"
import sys
import numpy as np
import imageio.v3 as iio
import napari
from qtpy.QtWidgets import QApplication

path, shot_path, sources = sys.argv[1], sys.argv[2], sys.argv[3:]
viewer = napari.Viewer(show=True)
viewer.open(path, plugin="napari-ome-zarr")
assert len(viewer.layers) == len(sources), [layer.name for layer in viewer.layers]
for _ in range(20):
    QApplication.processEvents()
shot = viewer.export_figure(flash=False)[..., :3]
iio.imwrite(shot_path, shot)
colours = [(0, 0, 1), (0, 1, 0), (1, 0, 0)]
expect = np.zeros(shot.shape)
for k, src in enumerate(sources):
    v = iio.imread(src).astype(np.float64)
    expect += np.clip((v - v.min()) / (v.max() - v.min()), 0, 1)[..., None] * np.array(colours[k])
expect = np.clip(expect, 0, 1) * 255
assert shot.shape == expect.shape, (shot.shape, expect.shape)
mse = np.mean((shot.astype(np.float64) - expect) ** 2)
psnr = 10 * np.log10(255**2 / mse) if mse > 0 else 99.0
print(f"PSNR {psnr:.2f}")
viewer.close()
"#;

#[test]
fn napari_shows_the_channels_as_the_metadata_says() {
    let Some(python) = napari() else { return };
    let dir = tempfile::tempdir().unwrap();
    let grey16 = PixelLayout::new(Channels::Grey, Depth::U16);
    // Three channels of different ranges, each a gradient of its own direction with noise.
    let (w, h) = (320u32, 200u32);
    let mut files = Vec::new();
    for k in 0..3u32 {
        let mut image = Image::random(w, h, grey16, 21 + k as u64);
        for (i, v) in image.samples.iter_mut().enumerate() {
            let (x, y) = (i as u32 % w, i as u32 / w);
            let ramp = [x * 40000 / w, y * 30000 / h, (x + y) * 20000 / (w + h)][k as usize];
            *v = (ramp + 5000 * k + (*v as u32 % 2000)) as u16;
        }
        let path = dir.path().join(format!("ch{k}.png"));
        write_png(&path, &image);
        files.push(path);
    }
    let out = dir.path().join("img.ome.zarr");
    let mut args = vec!["split", "--layout", "ome-zarr", "-o", s(&out), "--tile-size", "64", "-q"];
    args.extend(files.iter().flat_map(|f| ["--channel", s(f)]));
    ok(&args);
    let shot = dir.path().join("shot.png");
    let mut cmd = vec!["-a", "-s", "-screen 0 1280x1024x24", s(&python), "-c", NAPARI_SHOT, s(&out), s(&shot)];
    cmd.extend(files.iter().map(|f| s(f)));
    let run = Command::new("xvfb-run").args(&cmd).output().unwrap();
    let said = String::from_utf8_lossy(&run.stdout);
    assert!(run.status.success(), "napari: {said}{}", String::from_utf8_lossy(&run.stderr));
    let psnr: f64 = said.trim().rsplit(' ').next().and_then(|v| v.parse().ok()).unwrap_or_else(|| panic!("{said}"));
    // The 8-bit screenshot rounds what the metadata asks for (about 59 dB here); 40 dB leaves
    // room for the GPU's arithmetic and still fails a wrong window (a channel dark or burnt
    // out) or a wrong colour or order (each channel is a gradient of its own direction); a
    // blank canvas scores about 7 dB.
    assert!(psnr >= 40.0, "napari's screenshot is {psnr:.2} dB from the source");
}
