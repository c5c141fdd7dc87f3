//! DICOM whole-slide images in (docs/dicom.md, "Reading DICOM"): a series we wrote read back
//! (its frames decoded as the source's tiles were, and copied again where they fit), series
//! written by other writers (dicom-rs: uncompressed `TILED_FULL` and `TILED_SPARSE`; pydicom:
//! lossless JPEG 2000; read exactly), OpenSlide's DICOM test pair read as OpenSlide 4 reads it, and damaged series
//! refused naming the file and the frame or attribute.

use std::path::{Path, PathBuf};
use std::process::Command;

use dicom_core::value::DataSetSequence;
use dicom_core::{DataElement, PrimitiveValue, VR};
use dicom_dictionary_std::tags;
use dicom_object::{FileMetaTableBuilder, InMemDicomObject};
use vortex_tiler::pixel::{Channels, Depth, PixelLayout};
use vortex_tiler::source;

use crate::common::cli::{fails_with, ok, run, s};
use crate::ome_zarr::input;
use vortex_tiler::limits::Budget;

fn rgb8() -> PixelLayout {
    PixelLayout::new(Channels::Rgb, Depth::U8)
}

/// Every texel of `path` as our source reads it (no profile applied), its size and summary.
fn read_all(path: &Path) -> (u32, u32, Vec<u8>, String) {
    let mut source = source::open(path, Budget::new(1 << 30)).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let row = source.width() as usize * source.layout().bytes_per_pixel();
    let mut all = vec![0u8; row * source.height() as usize];
    for chunk in all.chunks_exact_mut(row) {
        source.read_row(chunk).unwrap();
    }
    (source.width(), source.height(), all, source.describe())
}

/// The files of a directory tree: (path under it, bytes), sorted.
fn tree(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    fn walk(root: &Path, dir: &Path, out: &mut Vec<(PathBuf, Vec<u8>)>) {
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            match path.is_dir() {
                true => walk(root, &path, out),
                false => out.push((path.strip_prefix(root).unwrap().to_path_buf(), std::fs::read(&path).unwrap())),
            }
        }
    }
    let mut out = Vec::new();
    walk(dir, dir, &mut out);
    out.sort();
    out
}

/// A JPEG-tiled TIFF whose every tile lies inside the image (1024 x 768 of 256-texel tiles), to
/// DICOM: every frame is a copied tile, so the series reads back texel for texel as the TIFF
/// does (the same JPEG bytes, the same decoder), whether named by its directory or an instance;
/// and the series to Deep Zoom copies the frames again: its full-resolution tiles are byte for
/// byte the tiles of the TIFF straight to Deep Zoom.
#[test]
fn a_jpeg_tiled_tiff_through_dicom_keeps_its_tiles() {
    if !crate::common::have_program("vips", "--version", "libvips-tools") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let tiled = crate::dicom_out::vips_jpeg_tiff(dir.path(), 1024, 768, 85);
    let series = dir.path().join("series");
    let json = ok(&["split", s(&tiled), "--layout", "dicom", "-o", s(&series), "--pixel-size", "0.5um", "--json"]);
    let json: serde_json::Value = serde_json::from_str(json.trim()).unwrap();
    assert_eq!(json["copied"], 12, "{json}");

    let (w, h, tiff_texels, _) = read_all(&tiled);
    for named in [series.clone(), series.join("level-0.dcm"), series.join("level-2.dcm")] {
        let (dw, dh, texels, said) = read_all(&named);
        assert_eq!((dw, dh), (w, h), "{}: {said}", named.display());
        assert!(texels == tiff_texels, "{}: texels differ from the TIFF's ({said})", named.display());
        assert!(said.contains("DICOM WSI level-0.dcm") && said.contains("TILED_FULL"), "{said}");
    }

    let from_tiff = dir.path().join("from-tiff");
    let from_dicom = dir.path().join("from-dicom");
    for (input, out) in [(&tiled, &from_tiff), (&series, &from_dicom)] {
        let json =
            ok(&["split", s(input), "-o", s(out), "--layout", "dzi", "--tile-size", "256", "--overlap", "0", "--json"]);
        let json: serde_json::Value = serde_json::from_str(json.trim()).unwrap();
        assert_eq!(json["copied"], 12, "{}: {json}", input.display());
    }
    // The descriptors name their image; the full-resolution level (10 for 1024 texels) is
    // the copied one.
    let level = |t: Vec<(PathBuf, Vec<u8>)>| -> Vec<(String, Vec<u8>)> {
        t.into_iter()
            .filter_map(|(p, b)| {
                let p = p.to_string_lossy().into_owned();
                p.contains("_files/10/").then(|| (p.rsplit('/').next().unwrap().to_string(), b))
            })
            .collect()
    };
    let (a, b) = (level(tree(&from_tiff)), level(tree(&from_dicom)));
    assert_eq!(a.len(), 12, "{:?}", a.iter().map(|(p, _)| p).collect::<Vec<_>>());
    assert!(a == b, "the full-resolution tiles differ between the TIFF's and the series' Deep Zoom");
}

/// An image we encode into DICOM (JPEG 4:2:0 frames, edge frames padded) reads back as the
/// frames decode: within JPEG's error of the image (30 dB: the writer's Q85 measures 35 dB on
/// these images, a reader taking YCbCr for RGB or misplacing a frame under 20), the same from
/// the directory and from the instance, and equal to OpenSlide 4's `read_region` of the series
/// where OpenSlide is installed (the same libjpeg-turbo, so exactly).
#[test]
fn an_encoded_series_reads_back_as_its_frames_decode() {
    let dir = tempfile::tempdir().unwrap();
    let png = input(dir.path(), "slide", 1000, 700, rgb8());
    let series = dir.path().join("series");
    ok(&["split", s(&png), "--layout", "dicom", "-o", s(&series), "--pixel-size", "0.5um", "-q"]);
    let (w, h, texels, said) = read_all(&series);
    assert_eq!((w, h), (1000, 700), "{said}");
    assert!(said.contains("0.5000 µm/texel") && said.contains("level of 3"), "{said}");
    let (_, _, from_file, _) = read_all(&series.join("level-1.dcm"));
    assert!(from_file == texels);
    let (_, _, original, _) = read_all(&png);
    let psnr = psnr(&texels, &original);
    assert!(psnr >= 30.0, "{psnr:.1} dB from the image");

    if let Some(py) = crate::tiff_slides::venv_python() {
        let out = dir.path().join("openslide.rgb");
        crate::tiff_corpus::python_stdout(&py, READ_REGION, &[s(&series.join("level-0.dcm")), s(&out)]);
        let theirs = std::fs::read(&out).unwrap();
        let differ = theirs.iter().zip(&texels).filter(|(a, b)| a != b).count();
        assert_eq!(theirs.len(), texels.len());
        assert!(differ == 0, "{differ} samples differ from OpenSlide 4's read_region");
    }

    // split and convert read a series alike.
    let a = dir.path().join("a.vtpk");
    let b = dir.path().join("b.vtpk");
    ok(&["split", s(&series), "--pack", s(&a), "-q"]);
    ok(&["convert", s(&series), "--pack", s(&b), "-q"]);
    assert!(std::fs::read(&a).unwrap() == std::fs::read(&b).unwrap(), "convert wrote another pack than split");
}

/// OpenSlide 4's level 0 of a slide, RGB (its alpha checked opaque), to argv[2].
const READ_REGION: &str = r#"
import sys, openslide, numpy
slide = openslide.OpenSlide(sys.argv[1])
rgba = numpy.asarray(slide.read_region((0, 0), 0, slide.dimensions))
assert (rgba[:, :, 3] == 255).all()
open(sys.argv[2], "wb").write(rgba[:, :, :3].tobytes())
print(slide.properties["openslide.vendor"], *slide.dimensions)
"#;

fn psnr(a: &[u8], b: &[u8]) -> f64 {
    assert_eq!(a.len(), b.len());
    let mse = a.iter().zip(b).map(|(&x, &y)| (x as f64 - y as f64).powi(2)).sum::<f64>() / a.len() as f64;
    10.0 * (255.0f64 * 255.0 / mse.max(1e-9)).log10()
}

/// OpenSlide's DICOM test pair: `boxes_0.dcm` (a VOLUME instance, one 64x64 JPEG frame of RGB
/// with an Adobe marker over a 16x16 matrix) and `boxes_1.dcm` (its uncompressed thumbnail):
/// either file, or their directory, reads as OpenSlide 4's level 0, exactly (OpenSlide and we
/// decode the same frame with libjpeg-turbo, no chroma subsampling: no decoder difference to
/// allow for).
#[test]
fn openslides_dicom_pair_reads_as_openslide_4_reads_it() {
    let Some(fixtures) = std::env::var_os("VORTEX_OPENSLIDE_FIXTURES").map(PathBuf::from) else {
        crate::common::skip_unless_ci(
            "OpenSlide's test slides",
            "VORTEX_OPENSLIDE_FIXTURES unset: .ci/run unpacks them",
        );
        return;
    };
    let Some(py) = crate::tiff_slides::venv_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let pair = dir.path().join("pair");
    std::fs::create_dir(&pair).unwrap();
    for name in ["boxes_0.dcm", "boxes_1.dcm"] {
        std::fs::copy(fixtures.join(name), pair.join(name)).unwrap();
    }
    let out = dir.path().join("openslide.rgb");
    let said = crate::tiff_corpus::python_stdout(&py, READ_REGION, &[s(&pair.join("boxes_0.dcm")), s(&out)]);
    assert_eq!(said.trim(), "dicom 16 16");
    let theirs = std::fs::read(&out).unwrap();
    for named in [pair.join("boxes_0.dcm"), pair.join("boxes_1.dcm"), pair.clone()] {
        let (w, h, texels, said) = read_all(&named);
        assert_eq!((w, h), (16, 16), "{said}");
        let differ = theirs.iter().zip(&texels).filter(|(a, b)| a != b).count();
        assert!(differ == 0, "{}: {differ} samples differ from OpenSlide 4's ({said})", named.display());
    }
}

/// A series another writer made: dicom-rs (not our writer), uncompressed RGB frames of 16x16
/// over a 40x30 matrix, `TILED_FULL` and `TILED_SPARSE` (frames in another order, placed by
/// their Plane Position (Slide), and a second focal plane's frame left out), read exactly.
#[test]
fn uncompressed_full_and_sparse_series_of_another_writer_read_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h, t) = (40u32, 30u32, 16u32);
    let texels: Vec<u8> = (0..w * h * 3).map(|i| (i * 7 % 251) as u8).collect();
    let (across, down) = (w.div_ceil(t), h.div_ceil(t));
    let frame = |c: u32, r: u32| -> Vec<u8> {
        let mut f = vec![0u8; (t * t * 3) as usize];
        for y in 0..t {
            for x in 0..t {
                let (ix, iy) = (c * t + x, r * t + y);
                if ix < w && iy < h {
                    let at = ((iy * w + ix) * 3) as usize;
                    f[((y * t + x) * 3) as usize..][..3].copy_from_slice(&texels[at..at + 3]);
                }
            }
        }
        f
    };
    let full: Vec<(u32, u32)> = (0..down).flat_map(|r| (0..across).map(move |c| (c, r))).collect();
    let path = dir.path().join("full.dcm");
    write_native(&path, (w, h, t), &full.iter().map(|&(c, r)| (c, r, frame(c, r))).collect::<Vec<_>>(), false);
    let (rw, rh, read, said) = read_all(&path);
    assert_eq!((rw, rh), (w, h), "{said}");
    assert!(read == texels, "TILED_FULL: {said}");
    assert!(said.contains("uncompressed RGB"), "{said}");

    let mut sparse: Vec<(u32, u32, Vec<u8>)> = full.iter().rev().map(|&(c, r)| (c, r, frame(c, r))).collect();
    sparse.push((0, 0, vec![9u8; (t * t * 3) as usize]));
    let dir2 = dir.path().join("sparse");
    std::fs::create_dir(&dir2).unwrap();
    let path = dir2.join("sparse.dcm");
    write_native(&path, (w, h, t), &sparse, true);
    let (_, _, read, said) = read_all(&dir2);
    assert!(read == texels, "TILED_SPARSE: {said}");
    assert!(said.contains("TILED_SPARSE (1 frames of other focal planes or optical paths left out)"), "{said}");
}

/// An uncompressed VL WSI instance written by dicom-rs: frames `(column, row, texels)`, placed
/// `TILED_FULL` in the order given, or `TILED_SPARSE` by a Plane Position (Slide) each.
fn write_native(path: &Path, (w, h, t): (u32, u32, u32), frames: &[(u32, u32, Vec<u8>)], sparse: bool) {
    let mut obj = InMemDicomObject::new_empty();
    let uid = "1.2.826.0.1.3680043.10.999.1";
    let put = |obj: &mut InMemDicomObject, tag, vr, value: PrimitiveValue| {
        obj.put(DataElement::new(tag, vr, value));
    };
    put(&mut obj, tags::SOP_CLASS_UID, VR::UI, "1.2.840.10008.5.1.4.1.1.77.1.6".into());
    put(&mut obj, tags::SOP_INSTANCE_UID, VR::UI, format!("{uid}.1").into());
    put(&mut obj, tags::SERIES_INSTANCE_UID, VR::UI, format!("{uid}.2").into());
    put(
        &mut obj,
        tags::IMAGE_TYPE,
        VR::CS,
        PrimitiveValue::Strs(["ORIGINAL", "PRIMARY", "VOLUME", "NONE"].map(String::from).to_vec().into()),
    );
    put(&mut obj, tags::SAMPLES_PER_PIXEL, VR::US, PrimitiveValue::from(3u16));
    put(&mut obj, tags::PHOTOMETRIC_INTERPRETATION, VR::CS, "RGB".into());
    put(&mut obj, tags::PLANAR_CONFIGURATION, VR::US, PrimitiveValue::from(0u16));
    put(&mut obj, tags::NUMBER_OF_FRAMES, VR::IS, frames.len().to_string().into());
    put(&mut obj, tags::ROWS, VR::US, PrimitiveValue::from(t as u16));
    put(&mut obj, tags::COLUMNS, VR::US, PrimitiveValue::from(t as u16));
    put(&mut obj, tags::BITS_ALLOCATED, VR::US, PrimitiveValue::from(8u16));
    put(&mut obj, tags::BITS_STORED, VR::US, PrimitiveValue::from(8u16));
    put(&mut obj, tags::HIGH_BIT, VR::US, PrimitiveValue::from(7u16));
    put(&mut obj, tags::PIXEL_REPRESENTATION, VR::US, PrimitiveValue::from(0u16));
    put(&mut obj, tags::TOTAL_PIXEL_MATRIX_COLUMNS, VR::UL, PrimitiveValue::from(w));
    put(&mut obj, tags::TOTAL_PIXEL_MATRIX_ROWS, VR::UL, PrimitiveValue::from(h));
    put(&mut obj, tags::DIMENSION_ORGANIZATION_TYPE, VR::CS, if sparse { "TILED_SPARSE" } else { "TILED_FULL" }.into());
    if sparse {
        let items: Vec<InMemDicomObject> = frames
            .iter()
            .map(|(c, r, _)| {
                let mut position = InMemDicomObject::new_empty();
                put(
                    &mut position,
                    tags::COLUMN_POSITION_IN_TOTAL_IMAGE_PIXEL_MATRIX,
                    VR::SL,
                    PrimitiveValue::from((c * t + 1) as i32),
                );
                put(
                    &mut position,
                    tags::ROW_POSITION_IN_TOTAL_IMAGE_PIXEL_MATRIX,
                    VR::SL,
                    PrimitiveValue::from((r * t + 1) as i32),
                );
                let mut item = InMemDicomObject::new_empty();
                item.put(DataElement::new(
                    tags::PLANE_POSITION_SLIDE_SEQUENCE,
                    VR::SQ,
                    DataSetSequence::from(vec![position]),
                ));
                item
            })
            .collect();
        obj.put(DataElement::new(tags::PER_FRAME_FUNCTIONAL_GROUPS_SEQUENCE, VR::SQ, DataSetSequence::from(items)));
    }
    let pixels: Vec<u8> = frames.iter().flat_map(|(_, _, f)| f.iter().copied()).collect();
    put(&mut obj, tags::PIXEL_DATA, VR::OB, PrimitiveValue::from(pixels));
    let meta = FileMetaTableBuilder::new()
        .transfer_syntax("1.2.840.10008.1.2.1")
        .media_storage_sop_class_uid("1.2.840.10008.5.1.4.1.1.77.1.6")
        .media_storage_sop_instance_uid(format!("{uid}.1"));
    obj.with_meta(meta).unwrap().write_to_file(path).unwrap();
}

/// Damaged series fail naming the file and what is wrong: a level cut short (its last frame
/// past the end of the file), a wrong Basic Offset Table, a transfer syntax we do not read
/// (named by its UID), a frame's JPEG data damaged; and nothing is left behind.
#[test]
fn damaged_series_are_refused_naming_the_file_and_the_frame() {
    let dir = tempfile::tempdir().unwrap();
    let png = input(dir.path(), "slide", 600, 300, rgb8());
    let series = dir.path().join("series");
    ok(&["split", s(&png), "--layout", "dicom", "-o", s(&series), "--pixel-size", "1um", "-q"]);
    let level0 = std::fs::read(series.join("level-0.dcm")).unwrap();
    let damaged = |name: &str, bytes: &[u8]| -> PathBuf {
        let d = dir.path().join(name);
        std::fs::create_dir(&d).unwrap();
        std::fs::write(d.join("level-0.dcm"), bytes).unwrap();
        d.join("level-0.dcm")
    };
    // Where the frames start: the Pixel Data's header, then the offset table item.
    let pixel_data = level0.windows(8).rposition(|w| w == [0xE0, 0x7F, 0x10, 0x00, b'O', b'B', 0, 0]).unwrap();
    let bot = pixel_data + 12;
    assert_eq!(&level0[bot..bot + 4], &[0xFE, 0xFF, 0x00, 0xE0]);

    let cut = damaged("cut", &level0[..level0.len() - 100]);
    let mut wrong_bot = level0.clone();
    wrong_bot[bot + 8 + 4] ^= 0x10; // frame 1's entry
    let wrong_bot = damaged("bot", &wrong_bot);
    let mut other_ts = level0.clone();
    let at = other_ts.windows(22).position(|w| w == b"1.2.840.10008.1.2.4.50").unwrap();
    other_ts[at..at + 22].copy_from_slice(b"1.2.840.10008.1.2.4.70");
    let other_ts = damaged("ts", &other_ts);
    let mut broken = level0.clone();
    let first_frame = bot + 8 + u32::from_le_bytes(level0[bot + 4..bot + 8].try_into().unwrap()) as usize + 8;
    for b in &mut broken[first_frame + 700..first_frame + 900] {
        *b = 0xFF;
    }
    let broken = damaged("broken", &broken);
    for (file, want) in [
        (&cut, &["level-0.dcm", "frame 5", "past the end of the file"][..]),
        (&wrong_bot, &["level-0.dcm", "Basic Offset Table", "frame 1", "wrong offset table"][..]),
        (&other_ts, &["level-0.dcm", "transfer syntax 1.2.840.10008.1.2.4.70"][..]),
        (&broken, &["level-0.dcm", "tile at column 0, row 0"][..]),
    ] {
        let out = dir.path().join("out.vtpk");
        fails_with(&run(&["split", s(file), "--pack", s(&out), "-q"]), want);
        assert!(!out.exists(), "{}: a pack was left behind", file.display());
    }
}

/// A JPEG 2000 series another writer made: pydicom's data set around lossless J2K codestreams
/// (imagecodecs' OpenJPEG, reversible colour transform: `YBR_RCT`), 32x32 frames over a 70x50
/// matrix, a Basic Offset Table: read exactly as the array it was made from (lossless).
const J2K_SERIES: &str = r#"
import sys, numpy, imagecodecs, pydicom
from pydicom.dataset import Dataset, FileMetaDataset
from pydicom.encaps import encapsulate
from pydicom.uid import generate_uid
w, h, t = 70, 50, 32
rng = numpy.random.default_rng(7)
image = rng.integers(0, 256, (h, w, 3), dtype=numpy.uint8)
frames = []
for r in range(0, h, t):
    for c in range(0, w, t):
        tile = numpy.zeros((t, t, 3), numpy.uint8)
        part = image[r:r + t, c:c + t]
        tile[:part.shape[0], :part.shape[1]] = part
        frames.append(imagecodecs.jpeg2k_encode(tile, level=0, codecformat="j2k", reversible=True, mct=True))
meta = FileMetaDataset()
meta.MediaStorageSOPClassUID = "1.2.840.10008.5.1.4.1.1.77.1.6"
meta.MediaStorageSOPInstanceUID = generate_uid()
meta.TransferSyntaxUID = "1.2.840.10008.1.2.4.90"
ds = Dataset()
ds.file_meta = meta
ds.SOPClassUID, ds.SOPInstanceUID = meta.MediaStorageSOPClassUID, meta.MediaStorageSOPInstanceUID
ds.SeriesInstanceUID = generate_uid()
ds.ImageType = ["ORIGINAL", "PRIMARY", "VOLUME", "NONE"]
ds.SamplesPerPixel, ds.PhotometricInterpretation, ds.PlanarConfiguration = 3, "YBR_RCT", 0
ds.Rows = ds.Columns = t
ds.BitsAllocated, ds.BitsStored, ds.HighBit, ds.PixelRepresentation = 8, 8, 7, 0
ds.TotalPixelMatrixColumns, ds.TotalPixelMatrixRows = w, h
ds.NumberOfFrames = len(frames)
ds.DimensionOrganizationType = "TILED_FULL"
ds.PixelData = encapsulate(frames, has_bot=True)
ds["PixelData"].VR = "OB"
ds.save_as(sys.argv[1], enforce_file_format=True)
open(sys.argv[2], "wb").write(image.tobytes())
"#;

#[test]
fn a_jpeg_2000_series_of_another_writer_reads_exactly() {
    let Some(py) =
        crate::common::python_with("pydicom, imagecodecs, numpy", "a JPEG 2000 DICOM", "pydicom, imagecodecs")
    else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let (dcm, raw) = (dir.path().join("j2k.dcm"), dir.path().join("image.rgb"));
    let out = Command::new(&py).arg("-c").arg(J2K_SERIES).args([s(&dcm), s(&raw)]).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let (w, h, texels, said) = read_all(&dcm);
    assert_eq!((w, h), (70, 50), "{said}");
    assert!(said.contains("jpeg 2000"), "{said}");
    assert!(texels == std::fs::read(&raw).unwrap(), "the J2K frames read otherwise than the array ({said})");
}

/// MONOCHROME2 JPEG frames (a grey image we encode) read back grey, within JPEG's error (the
/// 30 dB of the colour round trip above).
#[test]
fn grey_frames_read_back_grey() {
    let dir = tempfile::tempdir().unwrap();
    let grey = PixelLayout::new(Channels::Grey, Depth::U8);
    let png = input(dir.path(), "grey", 500, 300, grey);
    let series = dir.path().join("series");
    ok(&["split", s(&png), "--layout", "dicom", "-o", s(&series), "--pixel-size", "1um", "-q"]);
    let source = source::open(&series, Budget::new(1 << 30)).unwrap();
    assert_eq!(source.layout(), grey, "{}", source.describe());
    let (_, _, texels, said) = read_all(&series);
    let (_, _, original, _) = read_all(&png);
    let psnr = psnr(&texels, &original);
    assert!(psnr >= 30.0, "{psnr:.1} dB from the image ({said})");
}
