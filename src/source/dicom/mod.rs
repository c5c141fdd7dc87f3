//! DICOM whole-slide images in (docs/dicom.md, "Reading DICOM"): a VL Whole Slide Microscopy
//! Image series, given as any one of its instance files or as the directory holding them (as
//! OpenSlide 4 takes it), read as the image of its full-resolution level.
//!
//! * [`instance`]: one file's attributes up to its Pixel Data (dicom-rs) and where the Pixel
//!   Data starts.
//! * [`frames`]: where each frame lies: the encapsulated items walked, the offset tables checked
//!   against them; or the native Pixel Data cut.
//! * [`native`]: uncompressed frames read straight from the file.
//! * [`jxl`]: JPEG XL frames, decoded a row of frames at a time.
//!
//! The series is the instances of the given file's directory that share its Series Instance
//! UID; of those whose Image Type says `VOLUME`, the one of the largest Total Pixel Matrix is
//! read. Its frames go to the readers that already read the same bytes in a TIFF: JPEG baseline
//! frames are complete JPEG streams, a JPEG-tiled TIFF's tiles without shared tables
//! (`tiff::jpeg`: decoded by libjpeg-turbo, and copied as stored where the output's tiles line
//! up with them); JPEG 2000 frames are codestreams, Aperio's tiles (`tiff::jp2k`: OpenJPEG);
//! JPEG XL frames ([`jxl`]) are decoded by libjxl, as a JPEG XL tile directory's tiles are.
//! The first focal plane and the first optical path are read, and the summary says when there
//! are more. The optical path's ICC profile is not applied (as OpenSlide's `read_region`).

mod frames;
mod instance;
mod jxl;
mod native;

use std::path::{Path, PathBuf};

use dicom_core::Tag;
use dicom_dictionary_std::tags;

use self::frames::{Frames, Tables};
use self::instance::{Instance, PixelData, show_tag};
use super::RowSource;
use super::stored;
use super::tiff::jp2k;
use super::tiff::libjpeg::Colour;
use super::tiff::{Pages, jpeg};
use crate::error::{Result, TilerError};

pub(crate) use self::instance::{MAGIC_AT, is_dicom};

/// The VL Whole Slide Microscopy Image Storage SOP Class.
const WSI_SOP_CLASS: &str = "1.2.840.10008.5.1.4.1.1.77.1.6";
const JPEG_BASELINE: &str = "1.2.840.10008.1.2.4.50";
const JPEG_2000_LOSSLESS: &str = "1.2.840.10008.1.2.4.90";
const JPEG_2000: &str = "1.2.840.10008.1.2.4.91";
const JPEG_XL_LOSSLESS: &str = "1.2.840.10008.1.2.4.110";
const JPEG_XL_RECOMPRESSION: &str = "1.2.840.10008.1.2.4.111";
const JPEG_XL: &str = "1.2.840.10008.1.2.4.112";
const EXPLICIT_LITTLE: &str = "1.2.840.10008.1.2.1";
const IMPLICIT_LITTLE: &str = "1.2.840.10008.1.2";

/// Bytes of the frame index per frame (an offset and a length): counted against `--max-memory`
/// before the index is built.
const INDEX_BYTES_PER_FRAME: u64 = 16;

/// Whether the directory `dir` holds a DICOM file (one is enough to try it as a series).
pub(crate) fn holds_dicom(dir: &Path) -> bool {
    dicom_files(dir).is_ok_and(|files| !files.is_empty())
}

/// The DICOM Part-10 files of `dir`, by name.
fn dicom_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut files = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(|e| TilerError::io(dir, e))? {
        let path = entry.map_err(|e| TilerError::io(dir, e))?.path();
        if path.is_file() && starts_like_dicom(&path) {
            files.push(path);
        }
    }
    files.sort();
    Ok(files)
}

fn starts_like_dicom(path: &Path) -> bool {
    let mut head = Vec::with_capacity(MAGIC_AT + 4);
    std::fs::File::open(path)
        .and_then(|f| std::io::Read::read_to_end(&mut std::io::Read::take(f, MAGIC_AT as u64 + 4), &mut head))
        .is_ok_and(|_| is_dicom(&head))
}

/// Opens the series `path` is an instance of (or, a directory, holds) as its full-resolution
/// image.
pub(crate) fn open(path: &Path, max_memory: u64) -> Result<Box<dyn RowSource>> {
    let mut skipped = 0;
    let (series, given) = if path.is_dir() {
        (dicom_files(path)?.iter().map(|p| Instance::read(p)).collect::<Result<Vec<_>>>()?, None)
    } else {
        let given = Instance::read(path)?;
        let uid = given.text(tags::SERIES_INSTANCE_UID);
        let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
        let mut series = vec![given];
        for other in dicom_files(dir)? {
            if same_file(&other, path) {
                continue;
            }
            // Only the instances of the same series matter; a file beside it that cannot be
            // read is skipped (it may be of another series), and the summary says so.
            match Instance::read(&other) {
                Ok(instance) if uid.is_some() && instance.text(tags::SERIES_INSTANCE_UID) == uid => {
                    series.push(instance)
                }
                Ok(_) => {}
                Err(_) => skipped += 1,
            }
        }
        series.sort_by(|a, b| a.path.cmp(&b.path));
        (series, Some(path))
    };
    let slides: Vec<Instance> =
        series.into_iter().filter(|i| i.text(tags::SOP_CLASS_UID).as_deref() == Some(WSI_SOP_CLASS)).collect();
    let Some(first) = slides.first() else {
        return Err(TilerError::unsupported(
            path,
            "holds no VL Whole Slide Microscopy Image instance (SOP Class 1.2.840.10008.5.1.4.1.1.77.1.6): other DICOM images are not read",
        ));
    };
    let uid = first.text(tags::SERIES_INSTANCE_UID);
    if given.is_none() && slides.iter().any(|i| i.text(tags::SERIES_INSTANCE_UID) != uid) {
        let mut uids: Vec<String> =
            slides.iter().map(|i| i.text(tags::SERIES_INSTANCE_UID).unwrap_or_default()).collect();
        uids.sort();
        uids.dedup();
        return Err(TilerError::unsupported(
            path,
            format!("holds {} series ({}): name one of its instance files instead", uids.len(), uids.join(", ")),
        ));
    }
    let mut volumes = Vec::new();
    for instance in &slides {
        if instance.texts(tags::IMAGE_TYPE).get(2).is_some_and(|t| t == "VOLUME") {
            let columns = instance.required(tags::TOTAL_PIXEL_MATRIX_COLUMNS, "Total Pixel Matrix Columns")?;
            let rows = instance.required(tags::TOTAL_PIXEL_MATRIX_ROWS, "Total Pixel Matrix Rows")?;
            volumes.push((columns.saturating_mul(rows), instance));
        }
    }
    // The largest; of equal ones (other focal planes or optical paths), the first by name.
    let most = volumes.iter().map(|v| v.0).max();
    let Some(&(_, chosen)) = volumes.iter().find(|v| Some(v.0) == most) else {
        return Err(TilerError::unsupported(
            path,
            "the series has no VOLUME instance (Image Type's third value): only a label, overview or thumbnail",
        ));
    };
    let alike = volumes.iter().filter(|v| Some(v.0) == most).count();
    let name = chosen.path.file_name().map_or_else(String::new, |n| n.to_string_lossy().into_owned());
    let mut label = format!("DICOM WSI {name} (the full-resolution level of {}", volumes.len());
    if alike > 1 {
        label += &format!("; {} instances of this size: the first by name read", alike);
    }
    if skipped > 0 {
        label += &format!("; {skipped} unreadable DICOM files beside it skipped");
    }
    label.push(')');
    build(chosen, label, max_memory)
}

fn same_file(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(a), Ok(b)) => a == b,
        _ => a == b,
    }
}

/// What an instance's frames are, and the row source that reads them.
fn build(instance: &Instance, mut label: String, max_memory: u64) -> Result<Box<dyn RowSource>> {
    let path = &instance.path;
    let width = fits_u32(instance, tags::TOTAL_PIXEL_MATRIX_COLUMNS, "Total Pixel Matrix Columns")?;
    let height = fits_u32(instance, tags::TOTAL_PIXEL_MATRIX_ROWS, "Total Pixel Matrix Rows")?;
    let tile_w = fits_u32(instance, tags::COLUMNS, "Columns")?;
    let tile_h = fits_u32(instance, tags::ROWS, "Rows")?;
    if width == 0 || height == 0 || tile_w == 0 || tile_h == 0 {
        return Err(TilerError::decode(
            path,
            format!("a {width}x{height} Total Pixel Matrix of {tile_w}x{tile_h} frames: nothing to read"),
        ));
    }
    let frames = instance.number(tags::NUMBER_OF_FRAMES, "Number of Frames")?.unwrap_or(1);
    let samples = instance.number(tags::SAMPLES_PER_PIXEL, "Samples per Pixel")?.unwrap_or(1);
    let bits = instance.number(tags::BITS_ALLOCATED, "Bits Allocated")?.unwrap_or(8);
    let photometric = instance.text(tags::PHOTOMETRIC_INTERPRETATION).unwrap_or_default();
    if instance.number(tags::IN_CONCATENATION_TOTAL_NUMBER, "In-concatenation Total Number")?.unwrap_or(1) > 1 {
        return Err(TilerError::unsupported(
            path,
            "the instance is part of a concatenation (Concatenation UID (0020,9161)): frames split over several instances are not read",
        ));
    }
    let ts = instance.transfer_syntax.as_str();
    let jpeg_xl = matches!(ts, JPEG_XL_LOSSLESS | JPEG_XL_RECOMPRESSION | JPEG_XL);
    // JPEG XL frames may be 16-bit (`jxl::layout_of` checks them).
    if (bits != 8 && !jpeg_xl) || !matches!(samples, 1 | 3) {
        return Err(TilerError::unsupported(
            path,
            format!(
                "{samples} samples of {bits} bits (Samples per Pixel, Bits Allocated): 8-bit grey and colour frames are read"
            ),
        ));
    }
    let across = width.div_ceil(tile_w);
    let down = height.div_ceil(tile_h);
    let index = frames.saturating_mul(INDEX_BYTES_PER_FRAME);
    if index > max_memory / 4 {
        return Err(TilerError::unsupported(
            path,
            format!(
                "its {frames} frames' index ({} MiB) would take more than a quarter of --max-memory ({} MiB)",
                index >> 20,
                max_memory >> 20
            ),
        ));
    }
    let Some(pixel_data) = instance.pixel_data else {
        return Err(TilerError::decode(path, "the instance has no Pixel Data (7FE0,0010)"));
    };
    let stored = match (ts, pixel_data) {
        (
            JPEG_BASELINE | JPEG_2000_LOSSLESS | JPEG_2000 | JPEG_XL_LOSSLESS | JPEG_XL_RECOMPRESSION | JPEG_XL,
            PixelData::Encapsulated { items_at },
        ) => {
            let offsets = offset_table(instance, tags::EXTENDED_OFFSET_TABLE)?;
            let lengths = offset_table(instance, Tag(0x7FE0, 0x0002))?;
            let extended = match (&offsets, &lengths) {
                (Some(o), Some(l)) => Some((&o[..], &l[..])),
                (None, None) => None,
                _ => {
                    return Err(TilerError::decode(
                        path,
                        "the Extended Offset Table (7FE0,0001) comes without its lengths (7FE0,0002), or they without it",
                    ));
                }
            };
            frames::encapsulated(path, items_at, instance.file_len, frames, Tables { extended })?
        }
        (EXPLICIT_LITTLE | IMPLICIT_LITTLE, PixelData::Native { at, len }) => {
            if samples == 3 && instance.number(tags::PLANAR_CONFIGURATION, "Planar Configuration")?.unwrap_or(0) != 0 {
                return Err(TilerError::unsupported(
                    path,
                    "Planar Configuration (0028,0006) 1 (a frame's colour planes one after another) is not read",
                ));
            }
            let frame_bytes = tile_w as u64 * tile_h as u64 * samples;
            frames::native(path, at, len, frames, frame_bytes)?
        }
        (
            JPEG_BASELINE
            | JPEG_2000_LOSSLESS
            | JPEG_2000
            | JPEG_XL_LOSSLESS
            | JPEG_XL_RECOMPRESSION
            | JPEG_XL
            | EXPLICIT_LITTLE
            | IMPLICIT_LITTLE,
            _,
        ) => {
            return Err(TilerError::decode(
                path,
                format!("transfer syntax {ts} does not match how its Pixel Data (7FE0,0010) is stored"),
            ));
        }
        _ => {
            return Err(TilerError::unsupported(
                path,
                format!(
                    "transfer syntax {ts} is not read (JPEG baseline 1.2.840.10008.1.2.4.50, JPEG 2000 .4.90 and .4.91, JPEG XL .4.110, .4.111 and .4.112, uncompressed 1.2.840.10008.1.2.1 are)"
                ),
            ));
        }
    };
    let grid = place_frames(instance, &stored, (across, down), (tile_w, tile_h), frames, &mut label)?;
    let pitch = pixel_pitch(instance);
    if let Some(p) = pitch {
        label += &format!(", {:.4} µm/texel", p.x_um);
    }
    let embedded = crate::source::Embedded { pitch, lossy: stated_lossy(instance), ..Default::default() };
    let size = (width, height);
    let tile = (tile_w, tile_h);
    match ts {
        JPEG_BASELINE => {
            let colour = jpeg_colour(instance, &grid, &photometric, samples)?;
            let grid = jpeg::Grid {
                size,
                chunk: tile,
                tiled: true,
                offsets: grid.offsets,
                counts: grid.counts,
                tables: vec![],
            };
            jpeg::assemble(path, grid, colour, label, embedded, Pages::alone(max_memory))
        }
        JPEG_2000_LOSSLESS | JPEG_2000 => {
            let ycbcr = match photometric.as_str() {
                "YBR_ICT" | "YBR_RCT" | "RGB" if samples == 3 => false,
                "YBR_FULL" | "YBR_FULL_422" if samples == 3 => true,
                other => {
                    return Err(TilerError::unsupported(
                        path,
                        format!(
                            "JPEG 2000 frames of Photometric Interpretation {other} are not read (RGB, YBR_ICT, YBR_RCT, YBR_FULL are)"
                        ),
                    ));
                }
            };
            let grid = jp2k::Grid { size, chunk: tile, offsets: grid.offsets, counts: grid.counts };
            jp2k::assemble(path, grid, ycbcr, label, embedded, Pages::alone(max_memory))
        }
        JPEG_XL_LOSSLESS | JPEG_XL_RECOMPRESSION | JPEG_XL => {
            let layout =
                jxl::layout_of(&photometric, samples, bits).map_err(|why| TilerError::unsupported(path, why))?;
            let frames = (grid.offsets, grid.counts);
            jxl::open(path, size, tile, frames, layout, label, embedded, max_memory)
        }
        _ => {
            let grey = match (photometric.as_str(), samples) {
                ("MONOCHROME2", 1) => true,
                ("RGB", 3) => false,
                (other, _) => {
                    return Err(TilerError::unsupported(
                        path,
                        format!(
                            "uncompressed frames of Photometric Interpretation {other} are not read (RGB and MONOCHROME2 are)"
                        ),
                    ));
                }
            };
            native::open(path, size, tile, grid.offsets, grey, label, embedded)
        }
    }
}

fn fits_u32(instance: &Instance, tag: Tag, name: &str) -> Result<u32> {
    let value = instance.required(tag, name)?;
    u32::try_from(value).map_err(|_| {
        TilerError::unsupported(&instance.path, format!("{name} {} is {value}: more than 2^32-1", show_tag(tag)))
    })
}

/// A 64-bit offset table attribute (OV) as numbers.
fn offset_table(instance: &Instance, tag: Tag) -> Result<Option<Vec<u64>>> {
    let Some(element) = instance.object.get(tag) else { return Ok(None) };
    let bytes = element
        .to_bytes()
        .map_err(|e| TilerError::decode(&instance.path, format!("{} cannot be read: {e}", show_tag(tag))))?;
    if bytes.len() % 8 != 0 {
        return Err(TilerError::decode(
            &instance.path,
            format!("{} holds {} bytes, not 8 per frame", show_tag(tag), bytes.len()),
        ));
    }
    Ok(Some(bytes.chunks_exact(8).map(|b| u64::from_le_bytes(b.try_into().unwrap_or_default())).collect()))
}

/// The frames of the grid's cells, row-major: of `TILED_FULL`, the first `across x down`
/// (the first focal plane and optical path); of `TILED_SPARSE`, each cell's first frame by its
/// Plane Position (Slide). Adds to `label` what else the instance holds.
fn place_frames(
    instance: &Instance,
    stored: &Frames,
    (across, down): (u32, u32),
    (tile_w, tile_h): (u32, u32),
    frames: u64,
    label: &mut String,
) -> Result<Frames> {
    let path = &instance.path;
    let cells = across as u64 * down as u64;
    let planes =
        instance.number(tags::TOTAL_PIXEL_MATRIX_FOCAL_PLANES, "Total Pixel Matrix Focal Planes")?.unwrap_or(1);
    let paths = instance.number(tags::NUMBER_OF_OPTICAL_PATHS, "Number of Optical Paths")?.unwrap_or(1);
    if planes > 1 {
        *label += &format!(", the first of {planes} focal planes");
    }
    if paths > 1 {
        *label += &format!(", the first of {paths} optical paths");
    }
    let organisation = instance.text(tags::DIMENSION_ORGANIZATION_TYPE).unwrap_or_default();
    if organisation == "TILED_FULL" {
        if frames < cells {
            return Err(TilerError::decode(
                path,
                format!(
                    "TILED_FULL: Number of Frames (0028,0008) is {frames}, the {across}x{down} frames of the Total Pixel Matrix need {cells}"
                ),
            ));
        }
        *label += ", TILED_FULL";
        let n = cells as usize;
        return Ok(Frames { offsets: stored.offsets[..n].to_vec(), counts: stored.counts[..n].to_vec() });
    }
    // TILED_SPARSE (or not said): each frame's place from its per-frame functional groups.
    let items = instance
        .object
        .get(tags::PER_FRAME_FUNCTIONAL_GROUPS_SEQUENCE)
        .and_then(|e| e.items())
        .ok_or_else(|| {
            TilerError::decode(
                path,
                format!("Dimension Organization Type {organisation:?} without TILED_FULL needs the Per-Frame Functional Groups Sequence (5200,9230), which is missing"),
            )
        })?;
    if items.len() as u64 != frames {
        return Err(TilerError::decode(
            path,
            format!(
                "the Per-Frame Functional Groups Sequence (5200,9230) has {} items for {frames} frames",
                items.len()
            ),
        ));
    }
    let mut grid = Frames { offsets: vec![0; cells as usize], counts: vec![0; cells as usize] };
    let mut filled = vec![false; cells as usize];
    let mut others = 0u64;
    for (k, item) in items.iter().enumerate() {
        let position = item.get(tags::PLANE_POSITION_SLIDE_SEQUENCE).and_then(|e| e.items()).and_then(|i| i.first());
        let at = |tag: Tag, name: &str| -> Result<Option<u64>> {
            match position {
                Some(p) => instance::number_of(path, p, tag, name),
                None => Ok(None),
            }
        };
        let (Some(column), Some(row)) = (
            at(tags::COLUMN_POSITION_IN_TOTAL_IMAGE_PIXEL_MATRIX, "Column Position In Total Image Pixel Matrix")?,
            at(tags::ROW_POSITION_IN_TOTAL_IMAGE_PIXEL_MATRIX, "Row Position In Total Image Pixel Matrix")?,
        ) else {
            return Err(TilerError::decode(
                path,
                format!(
                    "TILED_SPARSE: frame {k} has no Plane Position (Slide) Sequence (0048,021A) with its column and row"
                ),
            ));
        };
        let (x, y) = (column.wrapping_sub(1), row.wrapping_sub(1));
        let cell = (x / tile_w as u64, y / tile_h as u64);
        if x % tile_w as u64 != 0 || y % tile_h as u64 != 0 || cell.0 >= across as u64 || cell.1 >= down as u64 {
            return Err(TilerError::unsupported(
                path,
                format!(
                    "TILED_SPARSE: frame {k} is at column {column}, row {row}: not on the {tile_w}x{tile_h} grid inside the Total Pixel Matrix, which is not read"
                ),
            ));
        }
        let index = (cell.1 * across as u64 + cell.0) as usize;
        if filled[index] {
            others += 1;
            continue;
        }
        filled[index] = true;
        grid.offsets[index] = stored.offsets[k];
        grid.counts[index] = stored.counts[k];
    }
    if let Some(missing) = filled.iter().position(|&f| !f) {
        let (column, row) = (missing as u32 % across, missing as u32 / across);
        return Err(TilerError::unsupported(
            path,
            format!(
                "TILED_SPARSE: no frame covers the tile at column {column}, row {row}: a sparse grid with gaps is not read"
            ),
        ));
    }
    *label += ", TILED_SPARSE";
    if others > 0 {
        *label += &format!(" ({others} frames of other focal planes or optical paths left out)");
    }
    Ok(grid)
}

/// The pixel spacing the Shared Functional Groups' Pixel Measures give, in micrometres: Pixel
/// Spacing is (row spacing, column spacing) in millimetres, the height of a pixel then its width.
fn pixel_pitch(instance: &Instance) -> Option<crate::source::PixelPitch> {
    let shared = instance.object.get(tags::SHARED_FUNCTIONAL_GROUPS_SEQUENCE)?.items()?.first()?;
    let measures = shared.get(tags::PIXEL_MEASURES_SEQUENCE)?.items()?.first()?;
    let spacing = measures.get(tags::PIXEL_SPACING)?.to_multi_float64().ok()?;
    let um = |mm: Option<&f64>| mm.map(|mm| mm * 1000.0).filter(|um| um.is_finite() && *um > 0.0);
    let y_um = um(spacing.first())?;
    let x_um = um(spacing.get(1)).unwrap_or(y_um);
    Some(crate::source::PixelPitch { x_um, y_um, from: "the DICOM Pixel Spacing" })
}

/// The lossy compressions the instance states its pixels went through (Lossy Image
/// Compression `01`, with each step's method and ratio, in order); none where it states none
/// or gives no ratio (the readers of its frames then say what their own coding was).
fn stated_lossy(instance: &Instance) -> Vec<crate::source::LossyStep> {
    if instance.text(tags::LOSSY_IMAGE_COMPRESSION).as_deref() != Some("01") {
        return Vec::new();
    }
    let methods = instance.texts(tags::LOSSY_IMAGE_COMPRESSION_METHOD);
    let ratios = instance.texts(tags::LOSSY_IMAGE_COMPRESSION_RATIO);
    ratios
        .iter()
        .enumerate()
        .map_while(|(i, ratio)| {
            let ratio = ratio.parse::<f64>().ok().filter(|r| r.is_finite() && *r > 0.0)?;
            // A method for each ratio; one method for all where only one is given.
            let method = methods.get(i).or(methods.last()).filter(|m| !m.is_empty())?;
            Some(crate::source::LossyStep { method: method.clone(), ratio })
        })
        .collect()
}

/// How libjpeg is to read the frames' samples: as the first frame's markers say (JFIF or
/// Adobe's transform), else as the Photometric Interpretation says.
fn jpeg_colour(instance: &Instance, grid: &Frames, photometric: &str, samples: u64) -> Result<Colour> {
    let path = &instance.path;
    let refuse = || {
        Err(TilerError::unsupported(
            path,
            format!(
                "JPEG frames of Photometric Interpretation {photometric} with {samples} samples are not read (MONOCHROME2, RGB, YBR_FULL_422 and YBR_FULL are)"
            ),
        ))
    };
    let declared = match (photometric, samples) {
        ("MONOCHROME2", 1) => Colour::Grey,
        ("RGB", 3) => Colour::Rgb,
        ("YBR_FULL_422" | "YBR_FULL", 3) => Colour::YCbCr,
        _ => return refuse(),
    };
    if declared == Colour::Grey {
        return Ok(declared);
    }
    let head = first_bytes(path, grid.offsets[0], grid.counts[0].min(1 << 16))?;
    let header = stored::read_header(&head);
    Ok(match header.map(|h| (h.jfif, h.adobe)) {
        Some((_, Some(0))) => Colour::Rgb,
        Some((_, Some(1))) | Some((true, None)) => Colour::YCbCr,
        _ => declared,
    })
}

fn first_bytes(path: &Path, offset: u64, count: u64) -> Result<Vec<u8>> {
    use std::os::unix::fs::FileExt;
    let file = std::fs::File::open(path).map_err(|e| TilerError::io(path, e))?;
    let mut bytes = vec![0u8; count as usize];
    file.read_exact_at(&mut bytes, offset).map_err(|e| TilerError::io(path, e))?;
    Ok(bytes)
}
