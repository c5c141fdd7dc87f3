//! An OME-TIFF of more channels than a pixel holds (`-o FILE.ome.tif` of a TIFF of more than
//! four samples, an OME-TIFF's grey planes, `--channel` files, `--channels` picks;
//! docs/tiff.md): a grey plane a channel, each the `c`th main IFD with its reduced levels as
//! SubIFDs, cut one pass each as OME-Zarr's channels are. Read back by our own reader (always)
//! and by tifffile and ome-types (the OME schema) from the Python named by VORTEX_PYVIPS,
//! skipped with a note where it is missing outside CI.
//!
//! The comparisons are exact: both sides are the same grey pipeline's levels (box filter, the
//! same tile size) stored losslessly (Deflate with the predictor in the TIFF, PNG tiles or
//! zstd chunks on the other side), so every sample must be the same number.

use std::path::{Path, PathBuf};
use std::process::Command;

use vortex_tiler::pixel::{Channels, Depth, PixelLayout};

use crate::common::Image;
use crate::common::cli::{fails_with, ok, run, s};
use crate::ome_zarr::write_png;
use crate::tiff_out::png_tiles;

/// `n` grey images of `layout` at `dir/chK.png`, each its own content, so that a swapped or
/// repeated channel shows.
fn channel_files(dir: &Path, n: u32, layout: PixelLayout) -> Vec<PathBuf> {
    (0..n)
        .map(|k| {
            let mut image = Image::random(150, 97, layout, 31 + u64::from(k));
            for (i, v) in image.samples.iter_mut().enumerate() {
                *v = v.wrapping_add((i as u16 % 150).wrapping_mul(k as u16 + 1));
                if layout.depth == Depth::U8 {
                    *v &= 0xFF;
                }
            }
            let path = dir.join(format!("ch{k}.png"));
            write_png(&path, &image);
            path
        })
        .collect()
}

/// `--channel` files into an OME-TIFF of planes, read back by our own reader as a channel set
/// (the OME-XML's `TiffData` mapping IFD `c` to channel `c`): each plane cuts the same tiles as
/// its file, 8 and 16 bits, all channels or picked ones in the order picked; `--json` says
/// the planes and counts every plane's tiles; the file is the same on every run.
#[test]
fn channel_files_become_planes_our_reader_reads_back() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (depth, n, picks) in [(Depth::U16, 5u32, None), (Depth::U8, 4, Some("3,1"))] {
        let sub = d.join(format!("{depth:?}"));
        std::fs::create_dir(&sub).unwrap();
        let files = channel_files(&sub, n, PixelLayout::new(Channels::Grey, depth));
        let tiff = sub.join("cells.ome.tif");
        let mut args = vec!["split", "-o", s(&tiff), "--codec", "deflate", "--tile-size", "64", "--json"];
        args.extend(files.iter().flat_map(|f| ["--channel", s(f)]));
        if let Some(picks) = picks {
            args.extend(["--channels", picks]);
        }
        let doc: serde_json::Value = serde_json::from_str(ok(&args).trim()).unwrap();
        let order: Vec<usize> = match picks {
            Some(p) => p.split(',').map(|k| k.parse().unwrap()).collect(),
            None => (0..n as usize).collect(),
        };
        assert_eq!(doc["layout"], "ome-tiff", "{doc}");
        assert_eq!(doc["tiff"]["planes"], order.len(), "{doc}");
        assert_eq!(doc["tiff"]["tiles"], doc["tiles"], "{doc}");
        let per_plane: u64 =
            (0..doc["lodCount"].as_u64().unwrap()).map(|k| 150u64.div_ceil(64 << k) * 97u64.div_ceil(64 << k)).sum();
        assert_eq!(doc["tiles"].as_u64().unwrap(), per_plane * order.len() as u64, "{doc}");
        // The same bytes on every run, whatever the thread count: each plane's tiles reach the
        // writer in the producer's order.
        for threads in ["1", "3"] {
            let again = sub.join(format!("again{threads}.ome.tif"));
            let args: Vec<&str> = (args.iter().map(|a| if *a == s(&tiff) { s(&again) } else { a }))
                .filter(|a| *a != "--json")
                .chain(["--threads", threads, "-q"])
                .collect();
            ok(&args);
            assert!(std::fs::read(&again).unwrap() == std::fs::read(&tiff).unwrap(), "{threads} threads: another file");
        }
        for (c, &k) in order.iter().enumerate() {
            let c = c.to_string();
            let got = png_tiles(&tiff, &sub.join(format!("got{c}")), &["--tile-size", "32", "--channels", &c]);
            let want = png_tiles(&files[k], &sub.join(format!("want{c}")), &["--tile-size", "32"]);
            assert!(!want.is_empty());
            assert!(got == want, "{depth:?}: plane {c} is not channel {k}'s pyramid");
        }
    }
}

/// An OME-TIFF of planes and an OME-Zarr image from one run, each channel read once for both:
/// each output's files are those of a run of its own, byte for byte, and `--json` reports both
/// (one pyramid: the same tile size and filter), each with every plane's tiles.
#[test]
fn an_ome_tiff_of_planes_and_an_ome_zarr_in_one_run() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let files = channel_files(d, 5, PixelLayout::new(Channels::Grey, Depth::U16));
    let channels: Vec<&str> = files.iter().flat_map(|f| ["--channel", s(f)]).collect();
    // 16-bit planes: the OME-TIFF's tiles are Deflate by default, the OME-Zarr's chunks zstd.
    let common = ["--tile-size", "64", "--channels", "4,0,2"];
    let (one, alone) = (d.join("one"), d.join("alone"));
    for folder in [&one, &alone] {
        std::fs::create_dir(folder).unwrap();
    }
    let (tiff, zarr) = ("x.ome.tif", "x.ome.zarr");
    let split = |outputs: &[&str]| ok(&[&["split"][..], &channels, outputs, &common].concat());
    split(&["-o", s(&alone.join(tiff)), "-q"]);
    split(&["-o", s(&alone.join(zarr)), "--layout", "ome-zarr", "-q"]);
    let json = split(&["-o", s(&one.join(tiff)), "-o", s(&one.join(zarr)), "--layout", "ome-zarr", "--json"]);
    for name in [tiff, zarr] {
        let (a, b) = (crate::outputs::files(&alone.join(name)), crate::outputs::files(&one.join(name)));
        assert!(!a.is_empty(), "{name}: no files");
        assert_eq!(a.keys().collect::<Vec<_>>(), b.keys().collect::<Vec<_>>(), "{name}: the file sets differ");
        for (file, bytes) in &a {
            assert!(bytes == &b[file], "{name}/{file}: the one run's bytes differ from the run of its own");
        }
    }
    let doc: serde_json::Value = serde_json::from_str(json.trim()).unwrap();
    let outputs = doc["outputs"].as_array().unwrap();
    assert_eq!(outputs.len(), 2, "{doc}");
    assert_eq!(doc["pyramids"], 1, "{doc}");
    let per_plane: u64 =
        (0..outputs[0]["lodCount"].as_u64().unwrap()).map(|k| 150u64.div_ceil(64 << k) * 97u64.div_ceil(64 << k)).sum();
    for o in outputs {
        assert_eq!(o["tiles"].as_u64(), Some(per_plane * 3), "{o}");
    }
    assert_eq!(outputs[0]["tiff"]["planes"], 3, "{doc}");
}

/// A TIFF of more than four samples into a generic pyramid or a COG is refused, naming the
/// OME flavour and `--channels`; an OME-TIFF of planes writes no output that holds no planes
/// in its run (each pass is one channel's pyramid); nothing is left behind.
#[test]
fn planes_only_in_an_ome_tiff_or_ome_zarr() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let files = channel_files(d, 5, PixelLayout::new(Channels::Grey, Depth::U8));
    let channels: Vec<&str> = files.iter().flat_map(|f| ["--channel", s(f)]).collect();
    let split = |extra: &[&str]| run(&[&["split"][..], &channels, extra].concat());
    for name in ["x.tif", "x.cog.tif"] {
        let out = d.join(name);
        fails_with(&split(&["-o", s(&out)]), &["5 channels", name, "--channels 0,1,2", "-o FILE.ome.tif"]);
        assert!(!out.exists());
    }
    let (tiff, zarr, web) = (d.join("x.ome.tif"), d.join("x.ome.zarr"), d.join("web"));
    let beside = split(&["-o", s(&tiff), "-o", s(&zarr), "--layout", "ome-zarr", "-o", s(&web), "--layout", "dzi"]);
    fails_with(&beside, &["5 channels", "OME-TIFF planes one pass each", "web", "run of its own"]);
    assert!(!tiff.exists() && !zarr.exists() && !web.exists());
    let leftovers: Vec<_> = std::fs::read_dir(d)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| !n.ends_with(".png"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
    // One or three picked are still a grey or RGB generic pyramid.
    ok(&[&["split"][..], &channels, &["-o", s(&d.join("rgb.tif")), "--channels", "0,1,2", "-q"]].concat());
}

/// Writes the inputs: a TIFF of 6 uint16 samples a pixel (stored together), an OME-TIFF of 5
/// uint8 grey planes with names and colours, a TIFF of 5 float32 samples in separate planes.
const INPUTS: &str = r#"
import sys
import numpy as np, tifffile
out = sys.argv[1]
h, w = 301, 410
rng = np.random.default_rng(5)
y, x = np.mgrid[0:h, 0:w]
def channels(c):
    return np.stack([((x * (k + 1) * 37 + y * 11 * (k + 2)) % 60000 + rng.integers(0, 50, (h, w))) for k in range(c)])
tifffile.imwrite(f"{out}/six.tif", np.moveaxis(channels(6).astype(np.uint16), 0, -1), photometric="minisblack", planarconfig="contig", rowsperstrip=16)
names = ["DAPI", "GFP", "RFP", "Cy5", "BF"]
colours = [-16776961, 16711935, 65535, -65281, -1]
tifffile.imwrite(f"{out}/named.ome.tif", (channels(5) % 256).astype(np.uint8), metadata={"axes": "CYX", "Channel": {"Name": names, "Color": colours}})
tifffile.imwrite(f"{out}/float.tif", channels(5).astype(np.float32) / 7.0 - 1000.0, photometric="minisblack", planarconfig="separate", rowsperstrip=16)
"#;

/// tifffile reads the OME-TIFF as one series (C, Y, X) with every level, each equal to the
/// OME-Zarr of the same channels, of the same sample type; ome-types validates the OME-XML
/// against the schema; the channels' names are the ones given and their colours those the
/// source gave (none written where it gave none), as the OME-Zarr's `omero` says too.
const COMPARE: &str = r#"
import re, sys
import numpy as np, tifffile, zarr, ome_types
tif, zarr_path, dtype, names, colours = sys.argv[1:6]
names = names.split(",")
colours = [None if c == "-" else int(c) for c in colours.split(",")]
with tifffile.TiffFile(tif) as t:
    assert t.is_ome and len(t.series) == 1, (t.is_ome, len(t.series))
    series = t.series[0]
    assert series.axes == "CYX", series.axes
    xml = t.ome_metadata
    levels = [level.asarray() for level in series.levels]
pixels = ome_types.from_xml(xml, validate=True).images[0].pixels
assert [c.name for c in pixels.channels] == names, [c.name for c in pixels.channels]
assert [c.samples_per_pixel for c in pixels.channels] == [1] * len(names)
assert [(d.ifd, d.first_c, d.plane_count) for d in pixels.tiff_data_blocks] == [(c, c, 1) for c in range(len(names))]
for c, want in enumerate(colours):
    tag = re.search(f'<Channel ID="Channel:0:{c}"[^>]*>', xml).group(0)
    got = pixels.channels[c].color.as_int32() if "Color=" in tag else None
    assert got == want, (c, tag, want)
root = zarr.open_group(zarr_path, mode="r")
attrs = root.attrs.asdict()
ome = attrs.get("ome", attrs)
omero = ome["omero"]["channels"]
assert [c["label"] for c in omero] == names, omero
for c, want in enumerate(colours):
    if want is not None:
        assert omero[c]["color"] == f"{want & 0xFFFFFFFF:08X}"[:6], (c, omero[c]["color"])
datasets = ome["multiscales"][0]["datasets"]
assert len(datasets) == len(levels) > 1, (len(datasets), len(levels))
for d, a in zip(datasets, levels):
    b = root[d["path"]][...]
    assert a.dtype == np.dtype(dtype) and a.dtype == b.dtype, (a.dtype, b.dtype)
    assert a.shape == b.shape and np.array_equal(a, b), f"level {d['path']}: {a.shape} {b.shape}"
print(f"{len(levels)} levels x {len(names)} channels identical, {levels[0].dtype}")
"#;

fn python_ok(python: &Path, args: &[&str]) -> String {
    let out = Command::new(python).args(args).output().unwrap();
    let said = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "{args:?}: {said}");
    said
}

/// The Python with tifffile, zarr and ome-types for `what`: VORTEX_PYVIPS, else a skip with
/// a note (a failure under CI).
fn readers(what: &str) -> Option<PathBuf> {
    crate::common::python_with("tifffile, zarr, numpy, ome_types", what, "tifffile, zarr and ome-types[lxml]")
}

#[test]
fn tifffile_reads_every_plane_s_levels_as_the_ome_zarr_holds_them() {
    let Some(python) = readers("the OME-TIFF of planes against OME-Zarr") else { return };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    python_ok(&python, &["-c", INPUTS, s(d)]);
    let six = "c0,c1,c2,c3,c4,c5";
    let named_colours = "-16776961,16711935,65535,-65281,-1";
    for (input, dtype, names, colours) in [
        ("six.tif", "uint16", six, "-,-,-,-,-,-"),
        ("named.ome.tif", "uint8", "DAPI,GFP,RFP,Cy5,BF", named_colours),
        ("float.tif", "float32", "c0,c1,c2,c3,c4", "-,-,-,-,-"),
    ] {
        let source = d.join(input);
        let tiff = d.join(format!("{input}.out.ome.tif"));
        let zarr = d.join(format!("{input}.ome.zarr"));
        ok(&["split", s(&source), "-o", s(&tiff), "--codec", "deflate", "--tile-size", "128", "-q"]);
        ok(&["split", s(&source), "--layout", "ome-zarr", "-o", s(&zarr), "--tile-size", "128", "-q"]);
        let said = python_ok(&python, &["-c", COMPARE, s(&tiff), s(&zarr), dtype, names, colours]);
        let count = names.split(',').count();
        assert!(said.contains(&format!("3 levels x {count} channels identical, {dtype}")), "{input}: {said}");
    }
}

/// Writes the inputs of [`the_source_pixel_size_is_carried`]: an OME-TIFF of 5 grey planes at
/// 0.325 µm (OME-XML), a TIFF of 6 samples at 0.5 µm (resolution tags in pixels per
/// centimetre), and grey TIFFs for `--channel`: two at 0.4 µm, one at 0.8 µm.
const SIZED: &str = r#"
import sys
import numpy as np, tifffile
out = sys.argv[1]
h, w = 97, 150
rng = np.random.default_rng(7)
def channels(c):
    return rng.integers(0, 256, (c, h, w)).astype(np.uint8)
tifffile.imwrite(f"{out}/planes.ome.tif", channels(5), metadata={"axes": "CYX", "PhysicalSizeX": 0.325, "PhysicalSizeXUnit": "µm", "PhysicalSizeY": 0.325, "PhysicalSizeYUnit": "µm"})
tifffile.imwrite(f"{out}/six.tif", np.moveaxis(channels(6), 0, -1), photometric="minisblack", planarconfig="contig", resolution=(1e4 / 0.5, 1e4 / 0.5), resolutionunit="CENTIMETER")
for k, um in enumerate([0.4, 0.4, 0.8]):
    tifffile.imwrite(f"{out}/ch{k}.tif", channels(1)[0], photometric="minisblack", resolution=(1e4 / um, 1e4 / um), resolutionunit="CENTIMETER")
"#;

/// The pixel size an output records at level 0, as `x,y` (`-` for none): an OME-TIFF's
/// PhysicalSizeX/Y in micrometres (ome-types, the schema), an OME-Zarr's level-0 scale where its
/// axes have a unit.
const SIZE_OF: &str = r#"
import sys
import tifffile, zarr, ome_types
path = sys.argv[1]
if path.endswith(".ome.tif"):
    with tifffile.TiffFile(path) as t:
        pixels = ome_types.from_xml(t.ome_metadata, validate=True).images[0].pixels
    x, y = pixels.physical_size_x, pixels.physical_size_y
    if x is not None:
        assert pixels.physical_size_x_unit.value == "µm", pixels.physical_size_x_unit
else:
    attrs = zarr.open_group(path, mode="r").attrs.asdict()
    ms = attrs.get("ome", attrs)["multiscales"][0]
    scale = ms["datasets"][0]["coordinateTransformations"][0]["scale"]
    units = [a.get("unit") for a in ms["axes"][-2:]]
    x, y = (scale[-1], scale[-2]) if units == ["micrometer"] * 2 else (None, None)
print("-" if x is None else f"{x:.6g},{y:.6g}")
"#;

/// A run of many channels records the source's pixel size as a run of the image read as it is
/// does: an OME-TIFF's PhysicalSizeX/Y and a TIFF's resolution tags become the OME-TIFF's
/// PhysicalSizeX/Y and the OME-Zarr's level-0 scale; `--pixel-size` overrides it; `--channel`
/// files give theirs where all agree, none where they differ or state none.
#[test]
fn the_source_pixel_size_is_carried() {
    let Some(python) = readers("the pixel size a run of many channels carries") else { return };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    python_ok(&python, &["-c", SIZED, s(d)]);
    let (planes, six) = (d.join("planes.ome.tif"), d.join("six.tif"));
    let chs: Vec<PathBuf> = (0..3).map(|k| d.join(format!("ch{k}.tif"))).collect();
    let pngs = channel_files(d, 2, PixelLayout::new(Channels::Grey, Depth::U8));
    let files = |paths: &[&PathBuf]| -> Vec<String> {
        paths.iter().flat_map(|p| ["--channel".to_string(), s(p).to_string()]).collect()
    };
    let cases: Vec<(&str, Vec<String>, &str)> = vec![
        ("planes", vec![s(&planes).into()], "0.325,0.325"),
        ("planes-picked", vec![s(&planes).into(), "--channels".into(), "4,0".into()], "0.325,0.325"),
        ("planes-given", vec![s(&planes).into(), "--pixel-size".into(), "0.5um".into()], "0.5,0.5"),
        ("six", vec![s(&six).into()], "0.5,0.5"),
        ("agree", files(&[&chs[0], &chs[1]]), "0.4,0.4"),
        ("differ", files(&[&chs[0], &chs[1], &chs[2]]), "-"),
        ("none", files(&[&pngs[0], &pngs[1]]), "-"),
    ];
    let outs = d.join("out");
    std::fs::create_dir(&outs).unwrap();
    for (name, args, want) in cases {
        for out in [outs.join(format!("{name}.ome.tif")), outs.join(format!("{name}.ome.zarr"))] {
            let mut all: Vec<&str> = vec!["split", "-o", s(&out), "--tile-size", "64", "-q"];
            if out.extension().is_some_and(|e| e == "zarr") {
                all.extend(["--layout", "ome-zarr"]);
            }
            all.extend(args.iter().map(String::as_str));
            ok(&all);
            let got = python_ok(&python, &["-c", SIZE_OF, s(&out)]);
            assert_eq!(got.trim(), want, "{name}: {}", out.display());
        }
    }
    // The summary says the size and where it was found.
    let said = ok(&["split", s(&planes), "-o", s(&outs.join("said.ome.tif")), "--tile-size", "64"]);
    assert!(said.contains("0.3250 µm/texel (the OME-XML's PhysicalSizeX/Y)"), "{said}");
}

/// A one-channel OME-TIFF (tifffile, `Channel Name="DAPI"` with a `Color`, 16-bit) and its
/// channel named in OME-XML; the one channel the second names, read back by ome-types.
const ONE_CHANNEL: &str = r#"
import sys
import numpy as np, tifffile
img = np.random.default_rng(5).integers(0, 4096, (97, 150)).astype(np.uint16)
tifffile.imwrite(sys.argv[1], img, metadata={"axes": "YX", "Channel": {"Name": "DAPI", "Color": -16776961}})
tifffile.imwrite(sys.argv[2], img, metadata={"axes": "YX"})
"#;

/// The OME-XML's channels (it validates), and the first one's `Name` and `Color` attributes
/// as written (ome-types gives a `Color` not written the schema's default).
const CHANNEL_OF: &str = r#"
import re, sys
import tifffile, ome_types
with tifffile.TiffFile(sys.argv[1]) as t:
    xml = t.ome_metadata
channels = ome_types.from_xml(xml, validate=True).images[0].pixels.channels
tag = re.search(r"<Channel\b[^>]*>", xml).group(0)
said = lambda name: (re.search(name + r'="([^"]*)"', tag) or [None, None])[1]
print(len(channels), said("Name"), said("Color"))
"#;

/// The one channel of an OME-TIFF source keeps its name and colour in an OME-TIFF output (read
/// as texels, it is not a run of planes); a source that names none gives a channel without
/// either, as before.
#[test]
fn a_one_channel_ome_tiff_keeps_its_channel_s_name() {
    let Some(python) = readers("the channel name of a one-channel OME-TIFF") else { return };
    let dir = tempfile::tempdir().unwrap();
    let (named, plain) = (dir.path().join("dapi.ome.tif"), dir.path().join("plain.ome.tif"));
    python_ok(&python, &["-c", ONE_CHANNEL, s(&named), s(&plain)]);
    for (source, want) in [(&named, "1 DAPI -16776961"), (&plain, "1 None None")] {
        let out = dir.path().join(format!("out-{}", source.file_name().unwrap().to_string_lossy()));
        ok(&["split", s(source), "-o", s(&out), "--tile-size", "64", "-q"]);
        let got = python_ok(&python, &["-c", CHANNEL_OF, s(&out)]);
        assert_eq!(got.trim(), want, "{}", source.display());
    }
}
