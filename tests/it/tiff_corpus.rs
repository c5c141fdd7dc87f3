//! The differential corpus (issue 41): TIFFs as other programs write them, in every layout they
//! write, each read by us and compared with tifffile's decode of the same file exactly, every
//! sample of every channel, or refused with a message naming the file and what it is.
//!
//! The writers, each run once per test by `tiff_corpus.py` (beside this file), which also
//! checks that tifffile reads back the pixels written and says, file by file, what we must give:
//! - tifffile: grey (MinIsBlack) of 1, 2 (alpha or not) and 5 or 6 samples, RGB of 3, 4 (alpha or
//!   an unspecified extra), 5 and 6 samples; 8/16/32-bit unsigned, 32-bit and half floats, 16-bit
//!   signed, and (refused) 8/32-bit signed and 64-bit floats; contiguous and separate planes;
//!   strips of 7 rows and 16x16 tiles; uncompressed, LZW, Deflate and PackBits, LZW and Deflate
//!   with the horizontal (integers) or floating-point (floats) predictor; little- and big-endian,
//!   TIFF and BigTIFF; at 37x23 and 129x65 (edge strips and tiles cut short). Also WhiteIsZero
//!   grey and 8-bit palettes (of 8-bit maps, 16-bit maps of 8-bit values and wide ones).
//! - libtiff's `tiffcp`, re-writing tifffile's 8- and 16-bit files big-endian in one-row LZW
//!   strips with predictor, as Deflate tiles of 32x48, planes separated and joined.
//! - libvips (pyvips' 8.18): 1 to 6 bands (grey, grey+alpha, RGB, RGBA, RGB + extra samples) of
//!   8/16/32-bit unsigned, 32-bit float and 16-bit signed samples, strips and tiles, every
//!   lossless compression it writes, with its predictors.
//!
//! What we must give: texels of up to four samples as `source::open` reads them (grey, grey +
//! alpha, RGB, RGBA; extra samples past those dropped, as docs/sources.md says; WhiteIsZero
//! inverted, palettes through their map, half floats and signed 16-bit widened to f32), and
//! each sample of a texel of more as a channel (`ChannelSet`), whatever the photometric calls
//! them. Every disagreement is listed before the test fails.

use std::path::Path;

use crate::common::cli::s;
use crate::tiff_slides::{python, venv_python};
use vortex_tiler::limits::Budget;
use vortex_tiler::pixel::Depth;
use vortex_tiler::source::channels::ChannelSet;
use vortex_tiler::source::{self, Pick, RowSource};

const CORPUS: &str = include_str!("tiff_corpus.py");

/// One file of the corpus and what reading it must give.
struct Entry {
    name: String,
    kind: String,
    /// numpy's type string of the expected samples ("<u2", "<f4", ...), and their shape: (h, w,
    /// samples) for texels, (channels, h, w) for channels.
    dtype: Option<String>,
    shape: Vec<usize>,
    refuse: Vec<String>,
}

/// The corpus `which` writes ("tifffile", with tiffcp's where it is installed, or "vips"), in
/// `dir`.
fn corpus(python_path: &std::ffi::OsStr, dir: &Path, which: &str) -> Vec<Entry> {
    python(python_path, CORPUS, &[s(dir), which]);
    let manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("manifest.json")).unwrap()).unwrap();
    let text = |v: &serde_json::Value| v.as_str().unwrap().to_string();
    manifest
        .as_array()
        .unwrap()
        .iter()
        .map(|e| Entry {
            name: text(&e["name"]),
            kind: text(&e["kind"]),
            dtype: e["dtype"].as_str().map(str::to_string),
            shape: e["shape"].as_array().map_or(vec![], |a| a.iter().map(|v| v.as_u64().unwrap() as usize).collect()),
            refuse: e["refuse"].as_array().map_or(vec![], |a| a.iter().map(text).collect()),
        })
        .collect()
}

/// Every row of `source`.
fn rows(source: &mut dyn RowSource) -> Result<Vec<u8>, String> {
    let row = source.width() as usize * source.layout().bytes_per_pixel();
    let mut all = vec![0u8; row * source.height() as usize];
    for chunk in all.chunks_exact_mut(row.max(1)) {
        source.read_row(chunk).map_err(|e| e.to_string())?;
    }
    Ok(all)
}

/// The depth numpy's type string stands for.
fn depth_of(dtype: &str) -> Depth {
    match &dtype[1..] {
        "u1" => Depth::U8,
        "u2" => Depth::U16,
        "u4" => Depth::U32,
        "f4" => Depth::F32,
        other => panic!("no depth for numpy's {other}"),
    }
}

/// Little-endian samples of `size` bytes into native order.
fn native(mut bytes: Vec<u8>, size: usize) -> Vec<u8> {
    if cfg!(target_endian = "big") {
        bytes.chunks_exact_mut(size).for_each(|s| s.reverse());
    }
    bytes
}

/// Where the first of `ours` and `theirs` differ, as (sample index, ours, theirs).
fn first_difference(ours: &[u8], theirs: &[u8], size: usize) -> String {
    let at = ours.chunks_exact(size).zip(theirs.chunks_exact(size)).position(|(a, b)| a != b);
    match at {
        Some(i) => format!(
            "sample {i} of {}: ours {:?}, tifffile's {:?}",
            theirs.len() / size,
            &ours[i * size..][..size],
            &theirs[i * size..][..size]
        ),
        None => format!("{} bytes where tifffile gives {}", ours.len(), theirs.len()),
    }
}

/// What is wrong with our reading of `entry`, if anything.
fn check(dir: &Path, entry: &Entry) -> Result<(), String> {
    let path = dir.join(format!("{}.tif", entry.name));
    let max_memory = 1 << 30;
    if entry.kind == "refused" {
        let error = match ChannelSet::open(&path, Pick::default(), Budget::new(max_memory)) {
            Ok(set) => match (0..set.count())
                .map(|k| {
                    set.channel(k).and_then(|mut c| rows(c.as_mut()).map_err(vortex_tiler::error::TilerError::Options))
                })
                .find_map(Result::err)
            {
                Some(e) => e.to_string(),
                None => return Err(format!("read where it must be refused naming {:?}", entry.refuse)),
            },
            Err(e) => e.to_string(),
        };
        let file = path.file_name().unwrap().to_str().unwrap();
        // Each needle must be there ("a|b": one of them).
        let says = |needle: &String| needle.split('|').any(|n| error.contains(n));
        if !error.contains(file) || !entry.refuse.iter().all(says) || error.contains("panicked") {
            return Err(format!("refused, but the message lacks the file or {:?}: {error}", entry.refuse));
        }
        return Ok(());
    }
    let dtype = entry.dtype.as_deref().unwrap();
    let depth = depth_of(dtype);
    let size = depth.bytes();
    let expect = native(std::fs::read(dir.join(format!("{}.expect", entry.name))).unwrap(), size);
    let channels =
        ChannelSet::beyond_texels(&path, Pick::default(), Budget::new(max_memory)).map_err(|e| e.to_string())?;
    match (entry.kind.as_str(), channels) {
        ("texels", None) => {
            let mut source = source::open(&path, Budget::new(max_memory)).map_err(|e| e.to_string())?;
            let layout = source.layout();
            let samples = entry.shape[2];
            if layout.depth != depth || layout.channels.count() != samples {
                return Err(format!("read as {layout} where tifffile's is {samples} samples of {dtype}"));
            }
            let ours = rows(source.as_mut())?;
            if ours != expect {
                return Err(format!("{} ({})", first_difference(&ours, &expect, size), source.describe()));
            }
        }
        ("channels", Some(set)) => {
            let (count, plane) = (entry.shape[0], entry.shape[1] * entry.shape[2] * size);
            if set.count() != count || set.depth != depth {
                return Err(format!(
                    "{} channels of {:?} where tifffile's are {count} of {dtype}",
                    set.count(),
                    set.depth
                ));
            }
            for k in 0..count {
                let mut channel = set.channel(k).map_err(|e| e.to_string())?;
                let ours = rows(channel.as_mut())?;
                let theirs = &expect[k * plane..][..plane];
                if ours != theirs {
                    return Err(format!(
                        "channel {k}: {} ({})",
                        first_difference(&ours, theirs, size),
                        channel.describe()
                    ));
                }
            }
        }
        (kind, set) => {
            return Err(format!(
                "read as {} where {kind} were expected",
                if set.is_some() { "channels" } else { "texels" }
            ));
        }
    }
    Ok(())
}

/// Reads every file of the corpus `which`, failing with the list of disagreements.
fn read_all_as_tifffile_does(which: &str) {
    let Some(python_path) = venv_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let entries = corpus(&python_path, dir.path(), which);
    assert!(entries.len() > 100, "{which}: only {} files", entries.len());
    let failures: Vec<String> =
        entries.iter().filter_map(|e| check(dir.path(), e).err().map(|why| format!("{}: {why}", e.name))).collect();
    assert!(
        failures.is_empty(),
        "{which}: {} of {} files read otherwise than tifffile reads them:\n{}",
        failures.len(),
        entries.len(),
        failures.join("\n")
    );
}

#[test]
fn tifffile_and_tiffcp_files_read_as_tifffile_reads_them() {
    // tiffcp's files join tifffile's where it is installed (and must be, under CI).
    crate::common::have_program("tiffcp", "-h", "libtiff-tools");
    read_all_as_tifffile_does("tifffile");
}

#[test]
fn libvips_files_read_as_tifffile_reads_them() {
    read_all_as_tifffile_does("vips");
}

/// Issue 41's first finding: 5 bands of 16 bits as libvips writes them (RGB and two extra
/// samples, Deflate strips) and as tifffile writes the same pixels (MinIsBlack and four extra);
/// OUT.expect holds tifffile's samples of the libvips file, channel by channel.
const FIVE_BANDS: &str = r#"
import sys
import numpy as np, pyvips, tifffile
out = sys.argv[1]
h, w, c = 201, 333, 5
rng = np.random.default_rng(41)
y, x = np.mgrid[0:h, 0:w]
data = np.stack([(x * (k + 3) * 97 + y * 13 * (k + 1) + k * 9000) % 65536 for k in range(c)], -1).astype(np.uint16)
data ^= rng.integers(0, 64, data.shape, dtype=np.uint16)
pyvips.Image.new_from_array(data).tiffsave(f"{out}/vips.tif", compression="deflate")
tifffile.imwrite(f"{out}/tifffile.tif", data, photometric="minisblack", planarconfig="contig", compression="zlib")
with tifffile.TiffFile(f"{out}/vips.tif") as t:
    p = t.pages[0]
    assert (int(p.photometric), p.samplesperpixel, len(p.extrasamples)) == (2, 5, 2), (p.photometric, p.extrasamples)
    got = p.asarray()
assert np.array_equal(got, data)
np.ascontiguousarray(np.moveaxis(got, -1, 0)).astype("<u2").tofile(f"{out}/expect")
"#;

/// Level 0 of an OME-Zarr of channels equals the TIFF's samples (channels first), exactly.
const ZARR_LEVEL_0: &str = r#"
import sys
import numpy as np, tifffile, zarr
root = zarr.open_group(sys.argv[1], mode="r")
attrs = root.attrs.asdict()
ome = attrs.get("ome", attrs)
a = root[ome["multiscales"][0]["datasets"][0]["path"]][...]
b = np.moveaxis(tifffile.imread(sys.argv[2]), -1, 0)
assert a.dtype == b.dtype and np.array_equal(a, b), (a.dtype, a.shape, b.shape, int((a != b).sum()))
print(f"{a.shape[0]} channels exact")
"#;

#[test]
fn libvips_five_bands_are_five_channels_as_stored() {
    let Some(py) = venv_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    python(&py, FIVE_BANDS, &[s(d)]);
    let expect = native(std::fs::read(d.join("expect")).unwrap(), 2);
    let plane = expect.len() / 5;
    for file in ["vips.tif", "tifffile.tif"] {
        let path = d.join(file);
        let set = ChannelSet::open(&path, Pick::default(), Budget::new(1 << 30)).unwrap();
        assert_eq!((set.count(), set.depth), (5, Depth::U16), "{file}");
        for k in 0..5 {
            let ours = rows(set.channel(k).unwrap().as_mut()).unwrap();
            assert!(ours == expect[k * plane..][..plane], "{file}: channel {k} differs from tifffile's");
        }
        // `--channels 3,4,0` into a pack or a viewer's layout: three channels as RGB texels.
        let ours = rows(set.interleave(&[3, 4, 0]).unwrap().as_mut()).unwrap();
        let expect = &expect;
        let theirs: Vec<u8> = (0..plane / 2)
            .flat_map(|i| [3, 4, 0].into_iter().flat_map(move |k| &expect[k * plane + 2 * i..][..2]))
            .copied()
            .collect();
        assert!(ours == theirs, "{file}: channels 3, 4, 0 as RGB differ from tifffile's");
        // And through the command line into OME-Zarr, read back by zarr.
        let out = d.join(format!("{file}.ome.zarr"));
        crate::common::cli::ok(&["split", s(&path), "--layout", "ome-zarr", "--tile-size", "128", "-q", "-o", s(&out)]);
        let said = python_stdout(&py, ZARR_LEVEL_0, &[s(&out), s(&path)]);
        assert!(said.contains("5 channels exact"), "{file}: {said}");
    }
}

/// `python script args` (asserting it succeeds): its standard output.
pub(crate) fn python_stdout(py: &std::ffi::OsStr, script: &str, args: &[&str]) -> String {
    let out = std::process::Command::new(py).arg("-c").arg(script).args(args).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout).into_owned()
}
