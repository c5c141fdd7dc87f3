//! 32-bit unsigned, float, half-float and 16-bit signed samples (docs/sources.md, "More sample
//! types"): TIFFs written by the `tiff` crate here and by tifffile (PyPI) through `split` into
//! raw and zstd packs and OME-Zarr, every level compared with a naive pyramid computed in the
//! test from the array the writer was given; the label filters on 32-bit labels; the refusals.

use std::path::{Path, PathBuf};
use std::process::Command;

use tiff::encoder::{TiffEncoder, colortype};
use vortex_pack::{Pack, Tile};

use crate::common::cli::{fails_with, ok, run, s};

/// One level of a pack of `border 0` tiles as `(width, height, samples)`, samples as their
/// little-endian bytes per texel sample (`sample_bytes` each).
fn pack_level(pack: &Pack, lod: u32) -> (usize, usize, Vec<Vec<u8>>) {
    let d = *pack.description();
    assert_eq!(d.border, 0, "the comparisons read payloads only");
    let level = pack.levels()[lod as usize];
    let (w, h, side) = (level.width as usize, level.height as usize, d.tile_size as usize);
    let (c, sb) = (d.channels as usize, d.sample_bytes as usize);
    let mut out = vec![Vec::new(); w * h * c];
    for ty in 0..level.tiles_h {
        for tx in 0..level.tiles_w {
            let texels = match pack.tile_checked(vortex_pack::TileId::new(lod, tx, ty)).unwrap() {
                tile @ Tile::Data(..) => tile.decode_texels(&d, 1 << 30).unwrap(),
                Tile::Constant(texel) => texel.repeat(side * side),
                Tile::Absent => panic!("tile ({lod}, {tx}, {ty}) is absent"),
            };
            for y in 0..side {
                for x in 0..side {
                    let (ix, iy) = (tx as usize * side + x, ty as usize * side + y);
                    if ix < w && iy < h {
                        for ch in 0..c {
                            let at = ((y * side + x) * c + ch) * sb;
                            out[(iy * w + ix) * c + ch] = texels[at..at + sb].to_vec();
                        }
                    }
                }
            }
        }
    }
    (w, h, out)
}

/// The real source pixels under texel `(x, y)` of level `lod` of a `w x h` image of `c`
/// channels: channel `ch` of each, row by row.
fn footprint<T: Copy>(
    src: &[T],
    (w, h, c): (usize, usize, usize),
    lod: u32,
    (x, y): (usize, usize),
    ch: usize,
) -> Vec<T> {
    let f = 1usize << lod;
    let (x1, y1) = (((x + 1) * f).min(w), ((y + 1) * f).min(h));
    (y * f..y1).flat_map(|sy| (x * f..x1).map(move |sx| src[(sy * w + sx) * c + ch])).collect()
}

/// The spacing of `f32`s at `m` (the gap to the next one away from zero, or below the largest).
fn ulp32(m: f64) -> f64 {
    let f = (m.abs() as f32).min(f32::MAX);
    let next = f32::from_bits(f.to_bits() + 1);
    if next.is_finite() { (next - f) as f64 } else { (f - f32::from_bits(f.to_bits() - 1)) as f64 }
}

/// Checks every level of a float pack against a naive f64 mean of each texel's footprint.
///
/// The bound: the pipeline sums in f64 as a tree of depth about 2 per level (at most 2^25
/// additions deep in a stripe's coarse pass), so its mean is within 2^-28 x mean|x| of the
/// exact one; the f32 it stores is within half an ulp of that; the naive left-to-right oracle is
/// within n x 2^-53 x mean|x| of the exact mean. Hence |got - oracle| <= ulp(oracle) +
/// (2^-28 + n 2^-53) mean|x|, which for same-sign footprints is about one ulp. NaN and
/// infinities: a footprint with a NaN, or with both infinities, gives NaN; one with infinities of
/// one sign gives that infinity (IEEE addition; nothing is skipped).
fn check_float_pyramid(pack: &Pack, src: &[f32], w: usize, h: usize, c: usize) -> usize {
    let mut checked = 0;
    for lod in 0..pack.levels().len() as u32 {
        let (lw, lh, level) = pack_level(pack, lod);
        assert_eq!((lw, lh), (w.div_ceil(1 << lod), h.div_ceil(1 << lod)));
        for y in 0..lh {
            for x in 0..lw {
                for ch in 0..c {
                    let got = f32::from_le_bytes(level[(y * lw + x) * c + ch][..].try_into().unwrap()) as f64;
                    let px = footprint(src, (w, h, c), lod, (x, y), ch);
                    let n = px.len() as f64;
                    let (nan, pos, neg) =
                        (px.iter().any(|v| v.is_nan()), px.contains(&f32::INFINITY), px.contains(&f32::NEG_INFINITY));
                    let at = format!("lod {lod} ({x}, {y}) channel {ch}: got {got:e} of {px:?}");
                    if nan || (pos && neg) {
                        assert!(got.is_nan(), "{at}");
                    } else if pos || neg {
                        assert_eq!(got, if pos { f64::INFINITY } else { f64::NEG_INFINITY }, "{at}");
                    } else {
                        let oracle = px.iter().map(|v| *v as f64).sum::<f64>() / n;
                        let mean_abs = px.iter().map(|v| v.abs() as f64).sum::<f64>() / n;
                        let bound = ulp32(oracle) + (2f64.powi(-28) + n * 2f64.powi(-53)) * mean_abs;
                        assert!((got - oracle).abs() <= bound, "{at}: oracle {oracle:e}, bound {bound:e}");
                    }
                    checked += 1;
                }
            }
        }
    }
    checked
}

/// Checks every level of a 32-bit unsigned pack against the exact integer mean of each
/// texel's footprint, rounded half up (u128 sums: no bound needed, the pipeline is exact).
fn check_u32_pyramid(pack: &Pack, src: &[u32], w: usize, h: usize, c: usize) {
    for lod in 0..pack.levels().len() as u32 {
        let (lw, lh, level) = pack_level(pack, lod);
        for y in 0..lh {
            for x in 0..lw {
                for ch in 0..c {
                    let got = u32::from_le_bytes(level[(y * lw + x) * c + ch][..].try_into().unwrap());
                    let px = footprint(src, (w, h, c), lod, (x, y), ch);
                    let (sum, n) = (px.iter().map(|v| *v as u128).sum::<u128>(), px.len() as u128);
                    let want = ((2 * sum + n) / (2 * n)) as u32;
                    assert_eq!(got, want, "lod {lod} ({x}, {y}) channel {ch} of {px:?}");
                }
            }
        }
    }
}

/// Floats of every kind: ordinary, huge (up to f32::MAX), tiny (normal and subnormal), both
/// signs, with a few NaNs and infinities where `specials`.
fn awkward_floats(n: usize, seed: u64, specials: bool) -> Vec<f32> {
    let mut state = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    (0..n)
        .map(|i| {
            let r = next();
            let unit = (r >> 11) as f64 / (1u64 << 53) as f64;
            let sign = if r & 1 == 0 { 1.0 } else { -1.0 };
            let v = match (r >> 1) % 8 {
                0 => f32::MAX as f64 * unit,
                1 => 1e30 * unit,
                2 => 1e-38 * unit,
                3 => 1e-44 * unit, // subnormal
                _ => 1000.0 * unit,
            };
            match (specials, i % 97) {
                (true, 13) => f32::NAN,
                (true, 40) => f32::INFINITY,
                (true, 41) => f32::NEG_INFINITY,
                (true, 70) => f32::INFINITY,
                _ => (sign * v) as f32,
            }
        })
        .collect()
}

fn split_to_pack(input: &Path, pack: &Path, extra: &[&str]) -> Pack {
    split_saying(input, pack, extra).0
}

/// The pack of 8-texel tiles, border 0, `split` makes of `input`, and its summary line.
fn split_saying(input: &Path, pack: &Path, extra: &[&str]) -> (Pack, String) {
    let mut args = vec!["split", s(input), "--pack", s(pack), "--tile-size", "8", "--border", "0"];
    args.extend_from_slice(extra);
    let said = ok(&args);
    (Pack::open(pack).unwrap(), said)
}

#[test]
fn float_means_hold_their_bound_over_deep_pyramids_odd_sizes_and_stripes() {
    let dir = tempfile::tempdir().unwrap();
    // 261 x 67: odd both ways, 7 levels of 8-texel tiles; 2000 x 5 under 300K of memory is cut
    // in stripes and a coarse pass, whose first levels are summed row by row.
    for (w, h, specials, extra) in [
        (261usize, 67usize, false, &["--codec", "raw"][..]),
        (261, 67, true, &["--codec", "zstd"][..]),
        (37, 300, true, &["--codec", "zstd-delta"][..]),
        (2000, 5, true, &["--codec", "raw", "--max-memory", "300K"][..]),
    ] {
        let samples = awkward_floats(w * h, (w * h) as u64, specials);
        let path = dir.path().join(format!("f{w}x{h}.tif"));
        let mut tif = TiffEncoder::new(std::fs::File::create(&path).unwrap()).unwrap();
        tif.write_image::<colortype::Gray32Float>(w as u32, h as u32, &samples).unwrap();
        let (pack, said) = split_saying(&path, &dir.path().join(format!("f{w}x{h}.vtpk")), extra);
        assert_eq!(said.contains("vertical stripes"), w == 2000, "{said}");
        assert_eq!((pack.description().sample_bytes, pack.description().sample_format), (4, 1));
        assert!(check_float_pyramid(&pack, &samples, w, h, 1) > w * h);
    }
}

#[test]
fn u32_means_are_exact_with_values_near_the_top() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (45usize, 29usize);
    // RGB, values in the top 1% of the range: any overflow or 64-bit shortcut would show.
    let samples: Vec<u32> =
        (0..w * h * 3).map(|i| u32::MAX - (i as u32).wrapping_mul(2_654_435_761) % 40_000_000).collect();
    let path = dir.path().join("u32.tif");
    let mut tif = TiffEncoder::new(std::fs::File::create(&path).unwrap()).unwrap();
    tif.write_image::<colortype::RGB32>(w as u32, h as u32, &samples).unwrap();
    let pack = split_to_pack(&path, &dir.path().join("u32.vtpk"), &["--codec", "zstd"]);
    assert_eq!((pack.description().sample_bytes, pack.description().sample_format), (4, 0));
    check_u32_pyramid(&pack, &samples, w, h, 3);
    let info: serde_json::Value = serde_json::from_slice(pack.metadata()).unwrap();
    assert_eq!(info["tileType"], "unsignedInt");
}

#[test]
fn label_filters_on_u32_labels_never_invent_one() {
    let dir = tempfile::tempdir().unwrap();
    // Large label values (above 2^16 and near 2^32), in runs so that blocks repeat and tie.
    let labels = [0u32, 70_000, 1 << 31, u32::MAX - 1, u32::MAX];
    for (seed, (w, h)) in [(1u64, (33usize, 17usize)), (2, (8, 8)), (3, (1, 21)), (4, (50, 3))] {
        let mut v = seed;
        let samples: Vec<u32> = (0..w * h)
            .map(|i| {
                if i % 3 != 0 {
                    v = v.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
                }
                labels[(v >> 33) as usize % labels.len()]
            })
            .collect();
        let path = dir.path().join(format!("l{seed}.tif"));
        let mut tif = TiffEncoder::new(std::fs::File::create(&path).unwrap()).unwrap();
        tif.write_image::<colortype::Gray32>(w as u32, h as u32, &samples).unwrap();
        for mode in [true, false] {
            let filter = if mode { "mode" } else { "nearest" };
            let pack = split_to_pack(
                &path,
                &dir.path().join(format!("l{seed}{filter}.vtpk")),
                &["--codec", "raw", "--filter", filter],
            );
            let mut above = (w, h, samples.clone());
            for lod in 0..pack.levels().len() as u32 {
                let (lw, lh, level) = pack_level(&pack, lod);
                let level: Vec<u32> = level.iter().map(|b| u32::from_le_bytes(b[..].try_into().unwrap())).collect();
                assert!(level.iter().all(|v| samples.contains(v)), "{filter} level {lod} invents a label");
                if lod > 0 {
                    let (aw, ah, prev) = &above;
                    for y in 0..lh {
                        for x in 0..lw {
                            let block: Vec<u32> = [(0, 0), (1, 0), (0, 1), (1, 1)]
                                .iter()
                                .map(|(dx, dy)| (2 * x + dx, 2 * y + dy))
                                .filter(|(bx, by)| bx < aw && by < ah)
                                .map(|(bx, by)| prev[by * aw + bx])
                                .collect();
                            let count = |v: u32| block.iter().filter(|b| **b == v).count();
                            let most = block.iter().map(|v| count(*v)).max().unwrap();
                            let want =
                                if mode { *block.iter().find(|v| count(**v) == most).unwrap() } else { block[0] };
                            assert_eq!(level[y * lw + x], want, "{filter} lod {lod} ({x}, {y}) of {block:?}");
                        }
                    }
                }
                above = (lw, lh, level);
            }
        }
    }
}

#[test]
fn half_tiles_store_the_nearest_half() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (19usize, 11usize);
    let samples: Vec<f32> = (0..w * h).map(|i| (i as f32 * 0.37).sin() * 70000.0 / (1 + i % 5) as f32).collect();
    let path = dir.path().join("f.tif");
    let mut tif = TiffEncoder::new(std::fs::File::create(&path).unwrap()).unwrap();
    tif.write_image::<colortype::Gray32Float>(w as u32, h as u32, &samples).unwrap();
    let full = split_to_pack(&path, &dir.path().join("f.vtpk"), &["--codec", "raw"]);
    let half = split_to_pack(&path, &dir.path().join("h.vtpk"), &["--codec", "zstd", "--tile-type", "half"]);
    assert_eq!((half.description().sample_bytes, half.description().sample_format), (2, 1));
    let info: serde_json::Value = serde_json::from_slice(half.metadata()).unwrap();
    assert_eq!(info["tileType"], "half");
    // Every level: the half is the f32 level rounded to nearest even (half::f16 is the oracle's
    // rounding; values past 65504 become infinite, as IEEE rounding makes them).
    for lod in 0..full.levels().len() as u32 {
        let (_, _, f) = pack_level(&full, lod);
        let (_, _, hf) = pack_level(&half, lod);
        for (a, b) in f.iter().zip(&hf) {
            let want = half::f16::from_f32(f32::from_le_bytes(a[..].try_into().unwrap()));
            assert_eq!(u16::from_le_bytes(b[..].try_into().unwrap()), want.to_bits());
        }
    }
}

#[test]
fn refusals_name_the_codec_the_filter_and_the_field() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("f.tif");
    let mut tif = TiffEncoder::new(std::fs::File::create(&path).unwrap()).unwrap();
    tif.write_image::<colortype::Gray32Float>(4, 4, &[0.5f32; 16]).unwrap();
    let out = dir.path().join("out");
    let pack = dir.path().join("p.vtpk");
    fails_with(&run(&["split", s(&path), "-o", s(&out), "--codec", "jpeg"]), &["32-bit float", "--codec jpeg", "raw"]);
    fails_with(&run(&["split", s(&path), "-o", s(&out)]), &["32-bit float", "png"]);
    fails_with(&run(&["split", s(&path), "--pack", s(&pack), "--codec", "bc7"]), &["--codec bc7"]);
    fails_with(
        &run(&["split", s(&path), "--pack", s(&pack), "--codec", "raw", "--filter", "linear"]),
        &["--filter linear", "use box"],
    );
    fails_with(
        &run(&["split", s(&path), "--pack", s(&pack), "--codec", "raw", "--filter", "lanczos3"]),
        &["--filter lanczos3"],
    );
    fails_with(
        &run(&["split", s(&path), "--pack", s(&pack), "--codec", "raw", "--filter", "mode"]),
        &["--filter mode", "nearest"],
    );
    fails_with(
        &run(&["split", s(&path), "--pack", s(&pack), "--codec", "raw", "--tile-type", "unsignedShort"]),
        &["--tile-type unsignedShort", "float"],
    );
    assert!(!out.exists() && !pack.exists(), "a refused run leaves nothing");

    // Sample formats the pipeline does not take name the TIFF field.
    let i32_path = dir.path().join("i32.tif");
    let mut tif = TiffEncoder::new(std::fs::File::create(&i32_path).unwrap()).unwrap();
    tif.write_image::<colortype::GrayI32>(4, 4, &[-1i32; 16]).unwrap();
    fails_with(&run(&["split", s(&i32_path), "--pack", s(&pack), "--codec", "raw"]), &["i32.tif", "SampleFormat 2"]);
}

/// The Python with tifffile and zarr: VORTEX_PYVIPS, if it imports them; else a skip with a
/// note, and a failure under CI.
fn tifffile() -> Option<PathBuf> {
    let python = std::env::var_os("VORTEX_PYVIPS").map(PathBuf::from);
    let works = python.as_ref().is_some_and(|p| {
        Command::new(p).args(["-c", "import tifffile, zarr, numpy"]).output().is_ok_and(|o| o.status.success())
    });
    if !works {
        crate::common::skip_unless_ci("sample_types (tifffile)", "no Python with tifffile, zarr, numpy");
        return None;
    }
    python
}

fn python(python: &Path, script: &str, args: &[&str]) -> String {
    let out = Command::new(python).arg("-c").arg(script).args(args).output().unwrap();
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "{args:?}: {text}");
    text
}

/// tifffile writes each kind of sample, in strips and tiles, compressed or not, and dumps the
/// array it was given (as the pipeline carries it: little-endian f32 or u32) beside the TIFF.
const WRITE: &str = r#"
import sys, numpy as np, tifffile
d = sys.argv[1]
rng = np.random.default_rng(7)
h, w = 29, 43
def save(name, a, carried, **kw):
    tifffile.imwrite(f"{d}/{name}.tif", a, metadata=None, **kw)
    np.ascontiguousarray(tifffile.imread(f"{d}/{name}.tif").astype(carried)).astype(carried.newbyteorder("<")).tofile(f"{d}/{name}.raw")
f32 = (rng.standard_normal((h, w)) * 1e5).astype(np.float32)
save("f32_tiles_zlib", f32, np.dtype(np.float32), tile=(16, 16), compression="zlib")
save("f32_rgb_predictor", rng.random((h, w, 3), dtype=np.float32), np.dtype(np.float32), photometric="rgb", compression="zlib", predictor=3, rowsperstrip=4)
save("f16_strips", (rng.standard_normal((h, w)) * 100).astype(np.float16), np.dtype(np.float32), rowsperstrip=5)
save("f16_rgba_tiles", rng.random((h, w, 4)).astype(np.float16), np.dtype(np.float32), photometric="rgb", extrasamples=[2], tile=(16, 16), compression="zlib")
save("u32_lzw", rng.integers(0, 2**32, (h, w), dtype=np.uint64).astype(np.uint32), np.dtype(np.uint32), compression="lzw", rowsperstrip=7)
save("u32_rgb_tiles", rng.integers(2**31, 2**32, (h, w, 3), dtype=np.uint64).astype(np.uint32), np.dtype(np.uint32), photometric="rgb", tile=(16, 16), compression="zlib")
save("i16", rng.integers(-32768, 32768, (h, w)).astype(np.int16), np.dtype(np.float32), compression="packbits")
print("written")
"#;

/// Every OME-Zarr level against a naive numpy pyramid of the array tifffile wrote: exact means
/// for uint32 (Python integers), f64 means rounded to f32 for floats, within the bound of
/// `check_float_pyramid` (one ulp plus 2^-28 of the mean magnitude).
const COMPARE_ZARR: &str = r#"
import sys, numpy as np, zarr
path, raw, dtype, c = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4])
root = zarr.open_group(path, mode="r")
attrs = root.attrs.asdict()
ms = attrs["ome"]["multiscales"] if "ome" in attrs else attrs["multiscales"]
levels = [root[d["path"]][...] for d in ms[0]["datasets"]]
h0, w0 = levels[0].shape[-2:]
src = np.fromfile(raw, dtype=np.dtype(dtype).newbyteorder("<")).reshape(h0, w0, c)
for lod, got in enumerate(levels):
    assert got.dtype == np.dtype(dtype), (got.dtype, dtype)
    got = got[:, :, None] if got.ndim == 2 else np.moveaxis(got, 0, -1)
    f = 1 << lod
    h, w = got.shape[:2]
    assert (h, w) == (-(-h0 // f), -(-w0 // f)), (lod, got.shape)
    for y in range(h):
        for x in range(w):
            block = src[y * f:(y + 1) * f, x * f:(x + 1) * f]
            n = block.shape[0] * block.shape[1]
            for ch in range(c):
                if dtype == "uint32":
                    s = sum(int(v) for v in block[:, :, ch].ravel())
                    want = (2 * s + n) // (2 * n)
                    assert int(got[y, x, ch]) == want, (lod, x, y, ch, got[y, x, ch], want)
                else:
                    vals = block[:, :, ch].astype(np.float64).ravel()
                    mean = vals.sum() / n
                    bound = float(np.spacing(np.float32(abs(mean)))) + (2.0**-28 + n * 2.0**-53) * np.abs(vals).mean()
                    assert abs(float(got[y, x, ch]) - mean) <= bound, (lod, x, y, ch, got[y, x, ch], mean)
print(f"{len(levels)} levels match")
"#;

#[test]
fn tifffile_samples_match_a_naive_pyramid_in_packs_and_ome_zarr() {
    let Some(py) = tifffile() else { return };
    let dir = tempfile::tempdir().unwrap();
    python(&py, WRITE, &[s(dir.path())]);
    let (w, h) = (43usize, 29usize);
    for (name, c, float) in [
        ("f32_tiles_zlib", 1, true),
        ("f32_rgb_predictor", 3, true),
        ("f16_strips", 1, true),
        ("f16_rgba_tiles", 4, true),
        ("u32_lzw", 1, false),
        ("u32_rgb_tiles", 3, false),
        ("i16", 1, true),
    ] {
        let tif = dir.path().join(format!("{name}.tif"));
        let raw = std::fs::read(dir.path().join(format!("{name}.raw"))).unwrap();
        let codec = if c * 4 > 8 { "raw" } else { "zstd" };
        let pack = split_to_pack(&tif, &dir.path().join(format!("{name}.vtpk")), &["--codec", codec]);
        if float {
            let src: Vec<f32> = raw.chunks_exact(4).map(|b| f32::from_le_bytes(b.try_into().unwrap())).collect();
            check_float_pyramid(&pack, &src, w, h, c);
        } else {
            let src: Vec<u32> = raw.chunks_exact(4).map(|b| u32::from_le_bytes(b.try_into().unwrap())).collect();
            check_u32_pyramid(&pack, &src, w, h, c);
        }
        for version in ["0.4", "0.5"] {
            let zarr = dir.path().join(format!("{name}-{version}.ome.zarr"));
            ok(&["split", s(&tif), "-o", s(&zarr), "--layout", "ome-zarr", "--ome-zarr-version", version]);
            let dtype = if float { "float32" } else { "uint32" };
            let raw = dir.path().join(format!("{name}.raw"));
            let said = python(&py, COMPARE_ZARR, &[s(&zarr), s(&raw), dtype, &c.to_string()]);
            assert!(said.contains("levels match"), "{said}");
        }
    }
}
