//! Viewer layouts (`--layout dzi|iiif|xyz|google`): every level a viewer reads is the exact
//! pipeline's level, cut where the viewer expects it; the file sets and tile sizes are those
//! `vips dzsave` writes for the same options; the command line refuses what makes no sense.

use std::collections::BTreeSet;
use std::path::Path;
use std::process::Command;

use proptest::prelude::*;
use vortex_tiler::background::Background;
use vortex_tiler::formats::viewer::{Viewer, ViewerTiles, dzi};
use vortex_tiler::output::{self, Product};
use vortex_tiler::pyramid::Filter;
use vortex_tiler::sink::DirSink;
use vortex_tiler::split::{SplitOptions, split};

use crate::common::cli::{fails_with, fixture, ok, run, s};
use crate::common::{Image, decode_png_sized, layouts, naive_level_filtered, png_options};

/// Writes `image` in `viewer`'s layout (PNG tiles) into `dir/out` through the library.
fn write_viewer(
    image: &Image,
    dir: &Path,
    viewer: Viewer,
    tile: u32,
    overlap: u32,
    opts: SplitOptions,
) -> std::path::PathBuf {
    let layout = viewer.page_grid(image.width, image.height, tile, overlap).unwrap();
    let dest = dir.join("out");
    let claim = output::claim(&dest, Product::Viewer(viewer), &[], false).unwrap();
    let tiles = ViewerTiles { viewer, layout, name: "img".into(), extension: "png", iiif: None };
    let sink = DirSink::for_viewer(&claim, tiles).unwrap();
    let opts = SplitOptions {
        tile_size: layout.tile_size,
        border: layout.border,
        down_to_one_texel: viewer.down_to_one_texel(),
        ..opts
    };
    let summary = split(image.source(), &sink, &opts, &()).unwrap();
    assert_eq!(summary.tiles, layout.total_tiles());
    sink.finish_viewer().unwrap();
    dest
}

/// Every file under `dir`, relative, sorted.
fn files(dir: &Path) -> BTreeSet<String> {
    fn walk(dir: &Path, prefix: &str, out: &mut BTreeSet<String>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let e = e.unwrap();
            let name = format!("{prefix}{}", e.file_name().to_string_lossy());
            if e.file_type().unwrap().is_dir() {
                walk(&e.path(), &format!("{name}/"), out);
            } else {
                out.insert(name);
            }
        }
    }
    let mut out = BTreeSet::new();
    walk(dir, "", &mut out);
    out
}

/// A level reassembled from tiles: each tile's texels placed at (x0, y0), checking that
/// texels several tiles hold (Deep Zoom's overlap) agree.
struct Canvas {
    width: u32,
    height: u32,
    channels: usize,
    samples: Vec<Option<u16>>,
}

impl Canvas {
    fn new(width: u32, height: u32, channels: usize) -> Canvas {
        Canvas { width, height, channels, samples: vec![None; width as usize * height as usize * channels] }
    }

    fn place(&mut self, name: &str, x0: u32, y0: u32, (w, h, texels): (u32, u32, Vec<u16>)) {
        assert!(
            x0 + w <= self.width && y0 + h <= self.height,
            "{name}: {w}x{h} at ({x0}, {y0}) is outside {}x{}",
            self.width,
            self.height
        );
        let c = self.channels;
        for y in 0..h as usize {
            for x in 0..w as usize {
                for k in 0..c {
                    let v = texels[(y * w as usize + x) * c + k];
                    let at = ((y0 as usize + y) * self.width as usize + x0 as usize + x) * c + k;
                    match self.samples[at] {
                        Some(old) => assert_eq!(old, v, "{name}: texel ({x}, {y}) differs from its neighbour's copy"),
                        None => self.samples[at] = Some(v),
                    }
                }
            }
        }
    }

    fn finish(self) -> Vec<u16> {
        self.samples.into_iter().map(|v| v.expect("every texel covered by a tile")).collect()
    }
}

/// The oracle's LOD: the source itself at LOD 0 (stored as it is, whatever the filter).
fn exact_level(image: &Image, lod: u32, filter: Filter) -> (u32, u32, Vec<u16>) {
    match lod {
        0 => (image.width, image.height, image.samples.clone()),
        _ => naive_level_filtered(image, lod, filter),
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 12, ..ProptestConfig::default() })]

    /// Each Deep Zoom level, tiles laid side by side with their overlaps, is the exact level of
    /// the source, down to 1 x 1; overlaps hold the neighbour's texels; edge tiles stop at the
    /// image.
    #[test]
    fn deep_zoom_levels_are_the_exact_levels(
        w in 1u32..200, h in 1u32..200, tile in 8u32..40, overlap in 0u32..4, li in 0usize..8, seed: u64, linear: bool,
    ) {
        let layout = layouts()[li % layouts().len()];
        let image = Image::random(w, h, layout, seed);
        let filter = if linear { Filter::LinearPremultiplied } else { Filter::Box };
        let dir = tempfile::tempdir().unwrap();
        let opts = SplitOptions { filter, ..png_options(8, 0, Background::Edge) };
        let out = write_viewer(&image, dir.path(), Viewer::Dzi, tile, overlap, opts);
        let max = dzi::max_level(w, h);
        let names = files(&out);
        prop_assert!(names.contains("img.dzi"));
        for level in 0..=max {
            let (lw, lh, expected) = exact_level(&image, max - level, filter);
            let mut canvas = Canvas::new(lw, lh, image.channels());
            let (cols, rows) = (lw.div_ceil(tile), lh.div_ceil(tile));
            for r in 0..rows {
                for c in 0..cols {
                    let name = format!("img_files/{level}/{c}_{r}.png");
                    let png = std::fs::read(out.join(&name)).unwrap();
                    let (x0, y0) = ((c * tile).saturating_sub(overlap), (r * tile).saturating_sub(overlap));
                    let decoded = decode_png_sized(&png);
                    // Overlap only towards neighbours, nothing past the image.
                    let right = ((c + 1) * tile + overlap).min(lw);
                    let bottom = ((r + 1) * tile + overlap).min(lh);
                    prop_assert_eq!((decoded.0, decoded.1), (right - x0, bottom - y0), "{}", name);
                    canvas.place(&name, x0, y0, decoded);
                }
            }
            prop_assert_eq!(canvas.finish(), expected, "level {}", level);
        }
        prop_assert_eq!(names.len() as u64, 1 + (0..=max).map(|l| {
            let (lw, lh) = (w.div_ceil(1 << (max - l)), h.div_ceil(1 << (max - l)));
            lw.div_ceil(tile) as u64 * lh.div_ceil(tile) as u64
        }).sum::<u64>());
    }

    /// Each IIIF scale factor f = 2^k, its tiles read from the names the IIIF Image API gives
    /// them (region of the full image, size) and placed side by side, is the exact LOD k; the
    /// coarsest is `full/{w},{h}`.
    #[test]
    fn iiif_scale_factors_are_the_exact_levels(w in 1u32..300, h in 1u32..300, tile in 8u32..64, li in 0usize..8, seed: u64) {
        let layout = layouts()[li % layouts().len()];
        let image = Image::random(w, h, layout, seed);
        let dir = tempfile::tempdir().unwrap();
        let out = write_viewer(&image, dir.path(), Viewer::Iiif, tile, 0, png_options(8, 0, Background::Edge));
        let info: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("info.json")).unwrap()).unwrap();
        let factors: Vec<u64> = info["tiles"][0]["scaleFactors"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap()).collect();
        let lods = (w.max(h).div_ceil(tile)).next_power_of_two().trailing_zeros() + 1;
        prop_assert_eq!(factors, (0..lods).map(|k| 1u64 << k).collect::<Vec<_>>());
        let mut names = BTreeSet::from(["info.json".to_string()]);
        for k in 0..lods {
            let f = 1u32 << k;
            let (_, _, expected) = exact_level(&image, k, Filter::Box);
            let (lw, lh) = (w.div_ceil(f), h.div_ceil(f));
            let mut canvas = Canvas::new(lw, lh, image.channels());
            for r in 0..lh.div_ceil(tile) {
                for c in 0..lw.div_ceil(tile) {
                    let (sw, sh) = (tile.min(lw - c * tile), tile.min(lh - r * tile));
                    let name = if k + 1 == lods {
                        format!("full/{sw},{sh}/0/default.png")
                    } else {
                        let (x, y) = (c * tile * f, r * tile * f);
                        format!("{x},{y},{},{}/{sw},{sh}/0/default.png", (tile * f).min(w - x), (tile * f).min(h - y))
                    };
                    let decoded = decode_png_sized(&std::fs::read(out.join(&name)).unwrap());
                    prop_assert_eq!((decoded.0, decoded.1), (sw, sh), "{}", name);
                    canvas.place(&name, c * tile, r * tile, decoded);
                    names.insert(name);
                }
            }
            prop_assert_eq!(canvas.finish(), expected, "scale factor {}", f);
        }
        if lods == 1 {
            names.insert("full/max/0/default.png".into());
        }
        prop_assert_eq!(files(&out), names);
    }
}

/// Web-map tiles: zoom z is LOD Z - z, at the top left of the square, the rest of an edge tile
/// the background.
#[test]
fn xyz_tiles_are_levels_padded_with_the_background() {
    let image = Image::random(70, 30, layouts()[2], 7);
    let dir = tempfile::tempdir().unwrap();
    let opts = png_options(8, 0, Background::Colour([10, 20, 30, 255]));
    let out = write_viewer(&image, dir.path(), Viewer::Xyz, 32, 0, opts);
    // 70 x 30 in 32-texel tiles: 3 x 1, 2 x 1, 1 x 1 tiles at zooms 2, 1, 0.
    let expected: BTreeSet<String> =
        ["0/0/0.png", "1/0/0.png", "1/1/0.png", "2/0/0.png", "2/1/0.png", "2/2/0.png", "tilejson.json"]
            .map(String::from)
            .into();
    assert_eq!(files(&out), expected);
    let (w, h, texels) = decode_png_sized(&std::fs::read(out.join("2/2/0.png")).unwrap());
    assert_eq!((w, h), (32, 32));
    let c = image.channels();
    let level = &image.samples;
    let background = Background::Colour([10, 20, 30, 255]).texel::<u8>(image.layout.channels).unwrap();
    for y in 0..32usize {
        for x in 0..32usize {
            let got = &texels[(y * 32 + x) * c..][..c];
            if 64 + x < 70 && y < 30 {
                assert_eq!(got, &level[(y * 70 + 64 + x) * c..][..c]);
            } else {
                assert_eq!(got, background.iter().map(|v| *v as u16).collect::<Vec<_>>(), "padding at ({x}, {y})");
            }
        }
    }
}

/// Whether `vips` (libvips-tools) can run; outside CI a missing one skips the test with a note.
fn have_vips() -> bool {
    crate::common::have_program("vips", "--version", "libvips-tools")
}

/// The width and height of every PNG tile under `dir`, by relative name (vips' metadata and
/// our manifests left out).
fn tile_sizes(dir: &Path) -> Vec<(String, u32, u32)> {
    files(dir)
        .into_iter()
        .filter(|n| n.ends_with(".png") && !n.ends_with("blank.png"))
        .map(|n| {
            let d = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(dir.join(&n)).unwrap()));
            let info = d.read_info().unwrap();
            let (w, h) = (info.info().width, info.info().height);
            (n, w, h)
        })
        .collect()
}

fn write_png(path: &Path, image: &Image) {
    let mut enc = png::Encoder::new(std::fs::File::create(path).unwrap(), image.width, image.height);
    enc.set_color(png::ColorType::Rgb);
    let bytes: Vec<u8> = image.samples.iter().map(|v| *v as u8).collect();
    enc.write_header().unwrap().write_image_data(&bytes).unwrap();
}

/// `split --layout dzi` writes the files `vips dzsave` writes for the same tile size and
/// overlap, each of the same width and height, for sizes that stress the edges.
#[test]
fn deep_zoom_file_set_matches_vips_dzsave() {
    if !have_vips() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let rgb = vortex_tiler::pixel::PixelLayout::new(vortex_tiler::pixel::Channels::Rgb, vortex_tiler::pixel::Depth::U8);
    for (w, h, tile, overlap) in
        [(700, 500, 254, 1), (1, 1, 254, 1), (513, 3, 256, 0), (300, 301, 100, 3), (1000, 17, 64, 2)]
    {
        let input = dir.path().join(format!("img{w}x{h}.png"));
        write_png(&input, &Image::random(w, h, rgb, w as u64));
        let (vips_dir, ours) =
            (dir.path().join(format!("vips-{w}-{tile}")), dir.path().join(format!("ours-{w}-{tile}")));
        std::fs::create_dir(&vips_dir).unwrap();
        let status = Command::new("vips")
            .args(["dzsave", s(&input), &format!("{}/img", s(&vips_dir))])
            .args(["--tile-size", &tile.to_string(), "--overlap", &overlap.to_string(), "--suffix", ".png"])
            .status()
            .unwrap();
        assert!(status.success());
        let (t, o) = (tile.to_string(), overlap.to_string());
        ok(&[
            "split",
            s(&input),
            "--layout",
            "dzi",
            "--name",
            "img",
            "-o",
            s(&ours),
            "--tile-size",
            &t,
            "--overlap",
            &o,
            "--codec",
            "png",
            "-q",
        ]);
        let ours_files = files(&ours);
        let vips_files: BTreeSet<String> =
            files(&vips_dir).into_iter().filter(|f| !f.ends_with("vips-properties.xml")).collect();
        assert_eq!(ours_files, vips_files, "{w}x{h} tile {tile} overlap {overlap}");
        assert_eq!(tile_sizes(&ours), tile_sizes(&vips_dir), "{w}x{h} tile {tile} overlap {overlap}");
        let dzi = std::fs::read_to_string(ours.join("img.dzi")).unwrap();
        assert!(dzi.contains(&format!("Overlap=\"{overlap}\" TileSize=\"{tile}\"")), "{dzi}");
    }
}

/// `--layout google` writes the tiles `vips dzsave --layout google` writes (vips adds a
/// blank.png for the tiles it leaves out; we write a tilejson.json).
#[test]
fn google_file_set_matches_vips_dzsave() {
    if !have_vips() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let vips_dir = dir.path().join("vips");
    std::fs::create_dir(&vips_dir).unwrap();
    let input = fixture("sample.png");
    let status = Command::new("vips")
        .args(["dzsave", s(&input), &format!("{}/s", s(&vips_dir)), "--layout", "google", "--suffix", ".png"])
        .status()
        .unwrap();
    assert!(status.success());
    let ours = dir.path().join("ours");
    ok(&["split", s(&input), "--layout", "google", "-o", s(&ours), "--codec", "png", "-q"]);
    let vips_files: BTreeSet<String> = files(&vips_dir.join("s"))
        .into_iter()
        .filter(|f| !f.ends_with("vips-properties.xml") && f != "blank.png")
        .collect();
    let ours_files: BTreeSet<String> = files(&ours).into_iter().filter(|f| f != "tilejson.json").collect();
    assert_eq!(ours_files, vips_files);
    assert_eq!(tile_sizes(&ours), tile_sizes(&vips_dir.join("s")));
}

/// libvips 8.18 (PyPI's pyvips-binary) is the reference for IIIF 3; the test runs where a
/// Python with pyvips is named by VORTEX_PYVIPS (`.ci/run` makes one), else skips with a note.
#[test]
fn iiif_file_set_matches_libvips_8_18() {
    let Some(python) = std::env::var_os("VORTEX_PYVIPS") else {
        crate::common::skip_unless_ci(
            "the IIIF comparison with libvips 8.18",
            "VORTEX_PYVIPS unset: set it to a Python with pyvips",
        );
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let rgb = vortex_tiler::pixel::PixelLayout::new(vortex_tiler::pixel::Channels::Rgb, vortex_tiler::pixel::Depth::U8);
    for (w, h, tile) in [(700, 500, 512), (3000, 1100, 256), (300, 200, 512), (257, 1000, 128)] {
        let input = dir.path().join(format!("img{w}x{h}.png"));
        write_png(&input, &Image::random(w, h, rgb, h as u64));
        let vips_dir = dir.path().join(format!("vips-{w}"));
        std::fs::create_dir(&vips_dir).unwrap();
        let script = format!(
            "import pyvips; pyvips.Image.new_from_file({:?}).dzsave({:?}, layout='iiif3', tile_size={tile}, suffix='.png')",
            s(&input),
            format!("{}/img", s(&vips_dir))
        );
        let status = Command::new(&python).args(["-c", &script]).status().unwrap();
        assert!(status.success(), "pyvips failed");
        let ours = dir.path().join(format!("ours-{w}"));
        ok(&[
            "split",
            s(&input),
            "--layout",
            "iiif",
            "-o",
            s(&ours),
            "--tile-size",
            &tile.to_string(),
            "--codec",
            "png",
            "-q",
        ]);
        let vips_files: BTreeSet<String> =
            files(&vips_dir.join("img")).into_iter().filter(|f| !f.ends_with("vips-properties.xml")).collect();
        // Ours adds full/max for a one-tile image, the name OpenSeadragon asks for then.
        let ours_files: BTreeSet<String> = files(&ours).into_iter().filter(|f| !f.starts_with("full/max/")).collect();
        assert_eq!(ours_files, vips_files, "{w}x{h} tile {tile}");
        let ours_sizes: Vec<_> = tile_sizes(&ours).into_iter().filter(|(n, ..)| !n.starts_with("full/max/")).collect();
        assert_eq!(ours_sizes, tile_sizes(&vips_dir.join("img")));
    }
}

/// What makes no sense in a viewer layout is refused, naming the flag; a directory that is not
/// a previous output of ours is never replaced; ours is.
#[test]
fn the_command_line_guards_viewer_layouts() {
    let dir = tempfile::tempdir().unwrap();
    let input = fixture("sample.png");
    let out = dir.path().join("dz");
    let o = s(&out);
    let cases: [(&[&str], &[&str]); 7] = [
        (&["--layout", "dzi", "--pack", "x.vtpk"], &["writes a directory", "serve"]),
        (&["--layout", "dzi", "-o", o, "--border", "2"], &["--overlap"]),
        (&["--layout", "iiif", "-o", o, "--overlap", "2"], &["--overlap is Deep Zoom's"]),
        (&["--layout", "xyz", "-o", o, "--codec", "raw"], &["image files", "raw"]),
        (&["--layout", "dzi", "-o", o, "--ff", "a%1$s.png"], &["--filename-format"]),
        (&["--layout", "dzi", "-o", o, "--name", "a/b"], &["--name"]),
        (&["-o", o, "--overlap", "1"], &["--overlap belongs to a viewer layout"]),
    ];
    for (args, needles) in cases {
        let out = run(&[&["split", s(&input)][..], args].concat());
        fails_with(&out, needles);
    }
    // A directory of photos is not ours to replace.
    let photos = dir.path().join("photos");
    std::fs::create_dir_all(photos.join("2024/01")).unwrap();
    std::fs::write(photos.join("2024/01/05.jpg"), b"a photo").unwrap();
    for layout in ["dzi", "iiif", "xyz", "google"] {
        let out = run(&["split", s(&input), "--layout", layout, "-o", s(&photos)]);
        fails_with(&out, &[s(&photos)]);
    }
    assert_eq!(std::fs::read(photos.join("2024/01/05.jpg")).unwrap(), b"a photo");
    // Our previous output is replaced, with the new options; --json says what was written.
    let json: serde_json::Value =
        serde_json::from_str(&ok(&["split", s(&input), "--layout", "dzi", "-o", o, "--json"])).unwrap();
    assert_eq!(
        (json["layout"].as_str(), json["tiles"].as_u64(), json["lodCount"].as_u64()),
        (Some("dzi"), Some(17), Some(11))
    );
    assert_eq!((json["viewer"]["tileSize"].as_u64(), json["viewer"]["overlap"].as_u64()), (Some(254), Some(1)));
    ok(&["split", s(&input), "--layout", "dzi", "-o", o, "-q", "--tile-size", "510"]);
    let dzi = std::fs::read_to_string(out.join("sample.dzi")).unwrap();
    assert!(dzi.contains("TileSize=\"510\""), "{dzi}");
    assert!(!out.join("sample_files/10/2_0.jpeg").exists());
}

/// `convert` writes viewer layouts too: a pack re-tiled to Deep Zoom gives the files `split`
/// of the same image gives.
#[test]
fn convert_writes_viewer_layouts() {
    let dir = tempfile::tempdir().unwrap();
    let input = fixture("sample.png");
    let pack = dir.path().join("s.vtpk");
    ok(&["split", s(&input), "--pack", s(&pack), "--codec", "png", "--tile-size", "64", "-q"]);
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    ok(&["split", s(&input), "--layout", "dzi", "--codec", "png", "-o", s(&a), "-q"]);
    ok(&["convert", s(&pack), "--layout", "dzi", "--name", "sample", "--codec", "png", "-o", s(&b), "-q"]);
    assert_eq!(files(&a), files(&b));
    for f in files(&a) {
        assert_eq!(std::fs::read(a.join(&f)).unwrap(), std::fs::read(b.join(&f)).unwrap(), "{f}");
    }
}

/// `convert` reads each viewer layout we write back: every tile it cuts from them equals the
/// tile `split` cuts from the original (PNG, so lossless), LOD 0 and the same file set. A
/// web-map directory's padding past the image (700 x 500 in 256-texel tiles is 768 x 512) is
/// left out by the size `tilejson.json` records.
#[test]
fn convert_reads_every_viewer_layout_back() {
    let dir = tempfile::tempdir().unwrap();
    let input = fixture("sample.png");
    let direct = dir.path().join("direct");
    ok(&["split", s(&input), "-o", s(&direct), "--codec", "png", "--tile-size", "100", "-q"]);
    let cases: [(&str, &str, &[&str]); 4] = [
        ("dzi", "sample.dzi", &[]),
        ("iiif", "", &[]),
        ("xyz", "", &["--input-layout", "xyz"]),
        ("google", "", &["--input-layout", "google"]),
    ];
    for (layout, file, flags) in cases {
        let written = dir.path().join(layout);
        ok(&["split", s(&input), "--layout", layout, "-o", s(&written), "--codec", "png", "-q"]);
        let back = dir.path().join(format!("{layout}-back"));
        let from = written.join(file);
        let mut args = vec!["convert", s(&from), "-o", s(&back), "--codec", "png", "--tile-size", "100", "-q"];
        args.extend_from_slice(flags);
        ok(&args);
        assert_eq!(files(&back), files(&direct), "{layout}");
        for name in files(&direct).into_iter().filter(|n| n.starts_with("lod00")) {
            let read = |d: &Path| decode_png_sized(&std::fs::read(d.join(&name)).unwrap());
            assert_eq!(read(&direct), read(&back), "{layout}: {name}");
        }
    }
}
