//! Real files others wrote (issue 41): the OpenSlide project's own test slides, which ship in
//! openslide-python's source package (`.ci/run` unpacks them into target/ and names the folder
//! in VORTEX_OPENSLIDE_FIXTURES), read as OpenSlide 4 (openslide-bin, in VORTEX_PYVIPS's
//! Python) reads them: every level of `boxes.tiff` (a generic tiled Deflate pyramid) and
//! `small.svs` (an Aperio JPEG slide) exactly, texel for texel, as stored (no profile applied,
//! as OpenSlide's `read_region` gives them; the DICOM pair `boxes_0.dcm` and `boxes_1.dcm` is
//! read in `dicom_in`); the rest refused with a message naming the file and why:
//! `unreadable.svs` (a damaged JPEG tile, which OpenSlide opens and fails to read) and
//! `unopenable.tiff` (compression 52479).

use std::path::{Path, PathBuf};

use crate::common::cli::{self, s};
use crate::tiff_corpus::python_stdout;
use crate::tiff_slides::venv_python;
use vortex_tiler::pixel::{Channels, Depth, PixelLayout};
use vortex_tiler::source::{self, Pick};

/// The folder of OpenSlide's test slides, or a skip with a note outside CI.
fn fixtures() -> Option<PathBuf> {
    let dir = std::env::var_os("VORTEX_OPENSLIDE_FIXTURES").map(PathBuf::from);
    if !dir.as_ref().is_some_and(|d| d.join("small.svs").is_file()) {
        crate::common::skip_unless_ci(
            "OpenSlide's test slides",
            "VORTEX_OPENSLIDE_FIXTURES unset or without small.svs: .ci/run unpacks them from openslide-python's sdist",
        );
        return None;
    }
    dir
}

/// OpenSlide 4's levels of a slide: each level's RGBA texels to OUT.levelN.rgba; prints
/// "vendor levels" and each level's "width height".
const LEVELS: &str = r#"
import sys, openslide
assert int(openslide.__library_version__.split(".")[0]) >= 4, openslide.__library_version__
slide, out = openslide.OpenSlide(sys.argv[1]), sys.argv[2]
print(slide.properties["openslide.vendor"], slide.level_count)
for level, (w, h) in enumerate(slide.level_dimensions):
    open(f"{out}.level{level}.rgba", "wb").write(slide.read_region((0, 0), level, (w, h)).tobytes())
    print(w, h)
"#;

/// Our texels of `pick` of `path`, as stored (no profile applied), and their size.
fn ours(path: &Path, pick: Pick) -> (u32, u32, Vec<u8>) {
    let mut source = source::open_picked(path, vortex_tiler::limits::Budget::new(1 << 30), pick)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let layout = source.layout();
    assert_eq!(layout, PixelLayout::new(Channels::Rgb, Depth::U8), "{}: {}", path.display(), source.describe());
    let row = source.width() as usize * 3;
    let mut all = vec![0u8; row * source.height() as usize];
    for chunk in all.chunks_exact_mut(row) {
        source.read_row(chunk).unwrap();
    }
    (source.width(), source.height(), all)
}

#[test]
fn openslide_test_slides_read_as_openslide_4_reads_them() {
    let Some(fixtures) = fixtures() else { return };
    let Some(py) = venv_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    // (slide, OpenSlide's vendor, the TIFF page of each of its levels)
    for (name, vendor, pages) in
        [("boxes.tiff", "generic-tiff", &[0u32, 1, 2, 3][..]), ("small.svs", "aperio", &[0][..])]
    {
        let slide = fixtures.join(name);
        let out = dir.path().join(name);
        let said = python_stdout(&py, LEVELS, &[s(&slide), s(&out)]);
        let mut lines = said.lines();
        assert_eq!(lines.next(), Some(format!("{vendor} {}", pages.len()).as_str()), "{name}: {said}");
        for (level, &page) in pages.iter().enumerate() {
            let size: Vec<u32> = lines.next().unwrap().split(' ').map(|v| v.parse().unwrap()).collect();
            let rgba = std::fs::read(format!("{}.level{level}.rgba", out.display())).unwrap();
            assert!(rgba.chunks_exact(4).all(|t| t[3] == 255), "{name} level {level}: OpenSlide left texels blank");
            let theirs: Vec<u8> = rgba.chunks_exact(4).flat_map(|t| [t[0], t[1], t[2]]).collect();
            let (w, h, texels) = ours(&slide, Pick { page: Some(page), series: None });
            assert_eq!([w, h], [size[0], size[1]], "{name} level {level} (page {page})");
            let differ = texels.iter().zip(&theirs).filter(|(a, b)| a != b).count();
            assert!(differ == 0, "{name} level {level} (page {page}): {differ} samples differ from OpenSlide 4's");
        }
        // The full-resolution image is what a plain open reads.
        let (_, _, level0) = ours(&slide, Pick::default());
        let (_, _, page0) = ours(&slide, Pick { page: Some(pages[0]), series: None });
        assert!(level0 == page0, "{name}: the default image is not level 0");
    }
}

#[test]
fn damaged_slides_are_refused_naming_the_file() {
    let Some(fixtures) = fixtures() else { return };
    let dir = tempfile::tempdir().unwrap();
    // (file, what the message must say besides the file's name)
    for (name, needles) in [("unreadable.svs", &["tile"][..]), ("unopenable.tiff", &["compression", "52479"][..])] {
        let pack = dir.path().join(format!("{name}.vtpk"));
        let out = cli::run(&["split", s(&fixtures.join(name)), "--pack", s(&pack), "-q"]);
        let mut all = vec![name];
        all.extend_from_slice(needles);
        cli::fails_with(&out, &all);
        assert!(!pack.exists(), "{name}: a pack was left behind");
    }
}
