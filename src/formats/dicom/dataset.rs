//! One level's data set: every module the VL Whole Slide Microscopy Image IOD (PS3.3 A.32.8)
//! requires, built as dicom-rs's in-memory object and written by it (preamble, File Meta,
//! data set in explicit VR little endian) up to where the Pixel Data element starts, which
//! `frames` writes.
//!
//! What is not known is not invented: the patient and study attributes are empty (type 2)
//! unless `--dicom-meta` gives them; the equipment's type-1 attributes name this program
//! where the user names no scanner; the slide's identifiers are its name. docs/dicom.md lists
//! every attribute.

use dicom_core::value::{C, DataSetSequence};
use dicom_core::{DataElement, PrimitiveValue, Tag, VR};
use dicom_dictionary_std::tags;
use dicom_object::{FileMetaTableBuilder, InMemDicomObject};

use super::frames::Offsets;
use super::meta::{KEYWORDS, Vr};
use super::uid::{self, Uids};
use super::{Level, Photometric, SOP_CLASS, Spec, Transfer};
use crate::error::{Result, TilerError};
use crate::source::LossyStep;
use crate::source::associated::Kind;

/// The name the files give their writer (the File Meta's Implementation Version Name, and
/// the default Manufacturer and model).
const PROGRAM: &str = "vortex-tiler";

/// What one instance of the series is: a level of the pyramid or an associated image.
pub(super) struct Part {
    /// Instance Number.
    pub number: u32,
    /// What its SOP Instance UID is a hash of.
    pub role: String,
    /// Image Type (and the frames' Frame Type).
    pub image_type: [&'static str; 4],
    /// Its Total Pixel Matrix and frames.
    pub level: Level,
    pub photometric: Photometric,
    /// How its frames are stored: the series' for a level; JPEG baseline for an associated
    /// image unless the series is native.
    pub transfer: Transfer,
    /// Bits a sample: 8, or 16 (a level's native frames of 16-bit samples).
    pub bits: u16,
    /// Pixel Spacing (rows, columns) in mm, where known: the levels' and the thumbnail's
    /// (each covers the scanned image), not a label's or an overview's (photographs).
    pub spacing: Option<(f64, f64)>,
    /// Whether the slide's label shows in the image (a label; an overview, which photographs
    /// the whole glass slide).
    pub label_in_image: bool,
    /// The lossy compressions its pixels went through before this series: the source's.
    pub lossy_before: Vec<LossyStep>,
    /// Whether this series coded frames itself with a loss (JPEG, lossy JPEG XL: a lossy
    /// step of its own), rather than copying (or recompressing losslessly) every one of them
    /// as stored, or coding them losslessly.
    pub coded_here: bool,
}

impl Part {
    /// Level `lod` of `spec`: the full resolution as scanned, the others derived from it by
    /// resampling.
    pub fn level(spec: &Spec, lod: u32) -> Part {
        let image_type = match lod {
            0 => ["ORIGINAL", "PRIMARY", "VOLUME", "NONE"],
            _ => ["DERIVED", "PRIMARY", "VOLUME", "RESAMPLED"],
        };
        let level = spec.level(lod);
        Part {
            number: lod + 1,
            role: format!("instance {lod}"),
            image_type,
            level,
            photometric: spec.photometric,
            transfer: spec.transfer,
            bits: if spec.stored.depth == crate::pixel::Depth::U16 { 16 } else { 8 },
            spacing: Some(spacing(spec, level)),
            label_in_image: false,
            lossy_before: spec.source_lossy.clone(),
            coded_here: true,
        }
    }

    /// Associated image `k` of `spec`, of `photometric` frames of 8-bit samples: one frame,
    /// the whole image (PS3.3 C.8.12.4.1.1: LABEL and OVERVIEW as photographed, THUMBNAIL
    /// resampled).
    /// `lossy_before`: what its page's reader says of it.
    pub fn associated(spec: &Spec, k: usize, photometric: Photometric, lossy_before: Vec<LossyStep>) -> Option<Part> {
        let image = spec.associated.get(k)?;
        let level = Level { width: image.width, height: image.height, tile: (image.width, image.height) };
        let (image_type, label_in_image) = match image.kind {
            Kind::Label => (["ORIGINAL", "PRIMARY", "LABEL", "NONE"], true),
            Kind::Overview => (["ORIGINAL", "PRIMARY", "OVERVIEW", "NONE"], true),
            Kind::Thumbnail => (["DERIVED", "PRIMARY", "THUMBNAIL", "RESAMPLED"], false),
        };
        Some(Part {
            number: spec.level_count() + 1 + k as u32,
            role: format!("associated {k} {}", image.kind.name()),
            image_type,
            level,
            photometric,
            transfer: match spec.transfer {
                Transfer::Native => Transfer::Native,
                _ => Transfer::JpegBaseline,
            },
            bits: 8,
            spacing: (image.kind == Kind::Thumbnail).then(|| spacing(spec, level)),
            label_in_image,
            lossy_before,
            coded_here: true,
        })
    }

    /// Whether its frame's place is stated per frame (TILED_SPARSE) rather than following from
    /// a Pixel Spacing it has not (a label, an overview: photographs of no stated scale).
    fn placed_per_frame(&self) -> bool {
        self.spacing.is_none()
    }

    /// Whether the image is of the scanned area (a level, the thumbnail), which the Imaged
    /// Volume attributes describe.
    fn of_the_volume(&self) -> bool {
        matches!(self.image_type[2], "VOLUME" | "THUMBNAIL")
    }
}

/// The pixel spacing (rows, columns) of an image of `level`'s size covering what level 0
/// covers: level 0's times level 0's size over the image's, per axis.
fn spacing(spec: &Spec, level: Level) -> (f64, f64) {
    let l = spec.level(0);
    (
        f64::from(l.height) * spec.pixel_mm / f64::from(level.height),
        f64::from(l.width) * spec.pixel_mm / f64::from(level.width),
    )
}

/// A decimal string of at most 16 characters (DS), as exact as that allows.
fn ds(v: f64) -> String {
    for decimals in (0..=12).rev() {
        let s = format!("{v:.decimals$}");
        let s = if s.contains('.') { s.trim_end_matches('0').trim_end_matches('.').to_string() } else { s };
        if s.len() <= 16 {
            return s;
        }
    }
    format!("{v:.0}")
}

type Object = InMemDicomObject;

fn put(o: &mut Object, tag: Tag, vr: VR, value: impl Into<PrimitiveValue>) {
    o.put(DataElement::new(tag, vr, value.into()));
}

fn strs(values: &[&str]) -> PrimitiveValue {
    PrimitiveValue::Strs(values.iter().map(|s| s.to_string()).collect::<C<String>>())
}

fn empty(o: &mut Object, tag: Tag, vr: VR) {
    o.put(DataElement::new(tag, vr, PrimitiveValue::Empty));
}

fn sequence(o: &mut Object, tag: Tag, items: Vec<Object>) {
    o.put(DataElement::new(tag, VR::SQ, DataSetSequence::from(items)));
}

fn item(build: impl FnOnce(&mut Object)) -> Object {
    let mut o = Object::new_empty();
    build(&mut o);
    o
}

/// A coded concept (Code Sequence Macro).
fn code(value: &str, scheme: &str, meaning: &str) -> Object {
    item(|o| {
        put(o, tags::CODE_VALUE, VR::SH, value);
        put(o, tags::CODING_SCHEME_DESIGNATOR, VR::SH, scheme);
        put(o, tags::CODE_MEANING, VR::LO, meaning);
    })
}

/// The sRGB profile the colour frames' optical path states (the pipeline's texels are sRGB),
/// with its creation date cleared so that the files are the same on every run.
fn srgb_profile() -> Result<Vec<u8>> {
    let mut icc = lcms2::Profile::new_srgb()
        .icc()
        .map_err(|e| TilerError::Internal(format!("the sRGB profile could not be made: {e}")))?;
    if icc.len() >= 100 {
        // dateTimeNumber (bytes 24..36) and the profile ID (84..100, zero: not computed).
        icc[24..36].fill(0);
        icc[84..100].fill(0);
    }
    Ok(icc)
}

/// What the data sets of a series share.
pub(super) struct Series<'a> {
    spec: &'a Spec,
    uids: Uids,
    icc: Option<Vec<u8>>,
}

impl<'a> Series<'a> {
    pub fn new(spec: &'a Spec) -> Result<Series<'a>> {
        // Colour instances state the sRGB profile (a grey series' associated images may be).
        let icc = match spec.photometric == Photometric::Monochrome && spec.associated.is_empty() {
            true => None,
            false => Some(srgb_profile()?),
        };
        Ok(Series { spec, uids: Uids::new(&spec.uid_root, &spec.identity), icc })
    }

    /// The Series Instance UID.
    pub fn series_uid(&self) -> String {
        self.uids.of("series")
    }

    /// The File Meta and data set of instance `part`, up to the Pixel Data element: the
    /// Extended Offset Table where `offsets` do not fit the Basic one. `frame_bytes`: its
    /// frames as stored, for the compression ratio.
    pub fn header(&self, part: &Part, offsets: &Offsets, frame_bytes: u64) -> Result<Vec<u8>> {
        let lod = part.number;
        let object = self.dataset(part, offsets, frame_bytes);
        let meta = FileMetaTableBuilder::new()
            .transfer_syntax(part.transfer.uid())
            .implementation_class_uid(uid::implementation())
            .implementation_version_name(PROGRAM.to_ascii_uppercase().replace('-', "_"));
        let file = object.with_meta(meta).map_err(|e| TilerError::Internal(format!("DICOM file meta: {e}")))?;
        let mut bytes = Vec::new();
        file.write_all(&mut bytes)
            .map_err(|e| TilerError::Internal(format!("DICOM data set of instance {lod}: {e}")))?;
        Ok(bytes)
    }

    fn dataset(&self, part: &Part, offsets: &Offsets, frame_bytes: u64) -> Object {
        let s = self.spec;
        // Level 0's image: the imaged volume.
        let l = s.level(0);
        let level = part.level;
        let meta = &s.meta;
        let (width, height) = (level.width, level.height);
        let (columns, rows) = level.grid();
        let frames = u64::from(columns) * u64::from(rows);
        let mut o = Object::new_empty();
        let given = |keyword: &str| meta.get(keyword).map(str::to_string);
        let date = &s.made[..8];
        let time = &s.made[8..];

        // SOP Common.
        put(&mut o, tags::SPECIFIC_CHARACTER_SET, VR::CS, "ISO_IR 192");
        put(&mut o, tags::SOP_CLASS_UID, VR::UI, SOP_CLASS);
        put(&mut o, tags::SOP_INSTANCE_UID, VR::UI, self.uids.of(&part.role));
        // Patient, General Study, General Series, General Equipment: what the user gave, else
        // empty (type 2).
        for &(keyword, (group, element), vr) in KEYWORDS {
            let tag = Tag(group, element);
            let vr = vr_of(vr);
            match (keyword, given(keyword)) {
                // Written below, in their modules.
                ("StudyInstanceUID" | "ContainerIdentifier" | "SpecimenIdentifier" | "AcquisitionDateTime", _) => {}
                ("Manufacturer" | "ManufacturerModelName", None) => put(&mut o, tag, vr, PROGRAM),
                ("DeviceSerialNumber", None) => put(&mut o, tag, vr, "0"),
                ("SoftwareVersions", None) => put(&mut o, tag, vr, env!("CARGO_PKG_VERSION")),
                ("SeriesDescription", None) => put(&mut o, tag, vr, s.name.as_str()),
                ("SeriesNumber", None) => put(&mut o, tag, vr, "1"),
                (_, Some(value)) => put(&mut o, tag, vr, value),
                (
                    "PatientName"
                    | "PatientID"
                    | "PatientBirthDate"
                    | "PatientSex"
                    | "StudyID"
                    | "StudyDate"
                    | "StudyTime"
                    | "AccessionNumber"
                    | "ReferringPhysicianName",
                    None,
                ) => empty(&mut o, tag, vr),
                (_, None) => {}
            }
        }
        let study = given("StudyInstanceUID").unwrap_or_else(|| self.uids.of("study"));
        put(&mut o, tags::STUDY_INSTANCE_UID, VR::UI, study);
        put(&mut o, tags::SERIES_INSTANCE_UID, VR::UI, self.series_uid());
        put(&mut o, tags::MODALITY, VR::CS, "SM");
        // Frame of Reference: the slide.
        put(&mut o, tags::FRAME_OF_REFERENCE_UID, VR::UI, self.uids.of("frame of reference"));
        put(&mut o, tags::POSITION_REFERENCE_INDICATOR, VR::LO, "SLIDE_CORNER");
        // General Image, Multi-frame Functional Groups.
        put(&mut o, tags::INSTANCE_NUMBER, VR::IS, part.number.to_string());
        put(&mut o, tags::CONTENT_DATE, VR::DA, date);
        put(&mut o, tags::CONTENT_TIME, VR::TM, time);
        put(&mut o, tags::ACQUISITION_DATE_TIME, VR::DT, given("AcquisitionDateTime").unwrap_or(s.made.clone()));
        put(&mut o, tags::NUMBER_OF_FRAMES, VR::IS, frames.to_string());
        // A label is text; an overview photographs it: either may name the patient.
        put(&mut o, tags::BURNED_IN_ANNOTATION, VR::CS, if part.label_in_image { "YES" } else { "NO" });
        put(&mut o, tags::VOLUMETRIC_PROPERTIES, VR::CS, "VOLUME");
        // Whole Slide Microscopy Image.
        put(&mut o, tags::IMAGE_TYPE, VR::CS, strs(&part.image_type));
        // Type 1C: required of the images of the scanned area, not of photographs.
        if part.of_the_volume() {
            let (volume_w, volume_h) = (f64::from(l.width) * s.pixel_mm, f64::from(l.height) * s.pixel_mm);
            put(&mut o, tags::IMAGED_VOLUME_WIDTH, VR::FL, volume_w as f32);
            put(&mut o, tags::IMAGED_VOLUME_HEIGHT, VR::FL, volume_h as f32);
            put(&mut o, tags::IMAGED_VOLUME_DEPTH, VR::FL, 1.0f32);
        }
        put(&mut o, tags::TOTAL_PIXEL_MATRIX_COLUMNS, VR::UL, width);
        put(&mut o, tags::TOTAL_PIXEL_MATRIX_ROWS, VR::UL, height);
        put(&mut o, tags::TOTAL_PIXEL_MATRIX_FOCAL_PLANES, VR::UL, 1u32);
        sequence(
            &mut o,
            tags::TOTAL_PIXEL_MATRIX_ORIGIN_SEQUENCE,
            vec![item(|i| {
                put(i, tags::X_OFFSET_IN_SLIDE_COORDINATE_SYSTEM, VR::DS, "0");
                put(i, tags::Y_OFFSET_IN_SLIDE_COORDINATE_SYSTEM, VR::DS, "0");
            })],
        );
        put(&mut o, tags::IMAGE_ORIENTATION_SLIDE, VR::DS, strs(&["0", "-1", "0", "-1", "0", "0"]));
        // Slide Label (a label's): what it reads is not known here (type 2, empty).
        if part.image_type[2] == "LABEL" {
            empty(&mut o, tags::LABEL_TEXT, VR::UT);
            empty(&mut o, tags::BARCODE_VALUE, VR::LT);
        }
        put(&mut o, tags::SPECIMEN_LABEL_IN_IMAGE, VR::CS, if part.label_in_image { "YES" } else { "NO" });
        put(&mut o, tags::FOCUS_METHOD, VR::CS, "AUTO");
        put(&mut o, tags::EXTENDED_DEPTH_OF_FIELD, VR::CS, "NO");
        // A frame's place in TILED_FULL follows from its index and the Pixel Spacing (readers
        // such as highdicom derive every frame's slide position so); an image without one (a
        // label, an overview) states its single frame's place instead, TILED_SPARSE.
        let organisation_type = if part.placed_per_frame() { "TILED_SPARSE" } else { "TILED_FULL" };
        put(&mut o, tags::DIMENSION_ORGANIZATION_TYPE, VR::CS, organisation_type);
        // Image Pixel.
        let p = part.photometric;
        put(&mut o, tags::SAMPLES_PER_PIXEL, VR::US, p.samples());
        put(&mut o, tags::PHOTOMETRIC_INTERPRETATION, VR::CS, p.name());
        if p.samples() > 1 {
            put(&mut o, tags::PLANAR_CONFIGURATION, VR::US, 0u16);
        }
        // `Spec::check` keeps the frame's sides within 16 bits.
        put(&mut o, tags::ROWS, VR::US, level.tile.1 as u16);
        put(&mut o, tags::COLUMNS, VR::US, level.tile.0 as u16);
        put(&mut o, tags::BITS_ALLOCATED, VR::US, part.bits);
        put(&mut o, tags::BITS_STORED, VR::US, part.bits);
        put(&mut o, tags::HIGH_BIT, VR::US, part.bits - 1);
        put(&mut o, tags::PIXEL_REPRESENTATION, VR::US, 0u16);
        if p == Photometric::Monochrome {
            put(&mut o, tags::PRESENTATION_LUT_SHAPE, VR::CS, "IDENTITY");
            put(&mut o, tags::RESCALE_INTERCEPT, VR::DS, "0");
            put(&mut o, tags::RESCALE_SLOPE, VR::DS, "1");
        }
        // The pixels' lossy history (PS3.3 C.7.6.1.1.5): the source's steps, then this
        // series' JPEG coding where it coded the frames; "00" (and no ratio or method, type
        // 1C) only where none was ever lossy, as far as the source says.
        let mut steps = part.lossy_before.clone();
        let method = match part.transfer {
            Transfer::JpegBaseline => Some(LossyStep::JPEG),
            Transfer::JpegXl => Some(LossyStep::JPEG_XL),
            _ => None,
        };
        if let Some(method) = method.filter(|_| part.coded_here) {
            let sample_bytes = u64::from(part.bits.div_ceil(8));
            let raw = u64::from(level.tile.0) * u64::from(level.tile.1) * u64::from(p.samples()) * sample_bytes;
            let ratio = (frames * raw) as f64 / frame_bytes.max(1) as f64;
            steps.push(LossyStep { method: method.to_string(), ratio });
        }
        if steps.is_empty() {
            put(&mut o, tags::LOSSY_IMAGE_COMPRESSION, VR::CS, "00");
        } else {
            put(&mut o, tags::LOSSY_IMAGE_COMPRESSION, VR::CS, "01");
            let ratios: Vec<String> = steps.iter().map(|step| ds(step.ratio)).collect();
            let ratios: Vec<&str> = ratios.iter().map(String::as_str).collect();
            let methods: Vec<&str> = steps.iter().map(|step| step.method.as_str()).collect();
            put(&mut o, tags::LOSSY_IMAGE_COMPRESSION_RATIO, VR::DS, strs(&ratios));
            put(&mut o, tags::LOSSY_IMAGE_COMPRESSION_METHOD, VR::CS, strs(&methods));
        }
        // Multi-frame Dimension: the frames' places follow from TILED_FULL.
        let organisation = self.uids.of("dimension organisation");
        sequence(
            &mut o,
            tags::DIMENSION_ORGANIZATION_SEQUENCE,
            vec![item(|i| put(i, tags::DIMENSION_ORGANIZATION_UID, VR::UI, organisation.clone()))],
        );
        let index = |pointer: Tag| {
            item(|i| {
                put(i, tags::DIMENSION_ORGANIZATION_UID, VR::UI, organisation.clone());
                put(i, tags::DIMENSION_INDEX_POINTER, VR::AT, pointer);
                let group = tags::PLANE_POSITION_SLIDE_SEQUENCE;
                put(i, tags::FUNCTIONAL_GROUP_POINTER, VR::AT, group);
            })
        };
        sequence(
            &mut o,
            tags::DIMENSION_INDEX_SEQUENCE,
            vec![
                index(tags::COLUMN_POSITION_IN_TOTAL_IMAGE_PIXEL_MATRIX),
                index(tags::ROW_POSITION_IN_TOTAL_IMAGE_PIXEL_MATRIX),
            ],
        );
        // Specimen: the slide, named by the user or by its name.
        let container = given("ContainerIdentifier").unwrap_or_else(|| s.name.clone());
        put(&mut o, tags::CONTAINER_IDENTIFIER, VR::LO, container);
        sequence(&mut o, tags::ISSUER_OF_THE_CONTAINER_IDENTIFIER_SEQUENCE, vec![]);
        sequence(&mut o, tags::CONTAINER_TYPE_CODE_SEQUENCE, vec![code("433466003", "SCT", "Microscope slide")]);
        let specimen = given("SpecimenIdentifier").unwrap_or_else(|| s.name.clone());
        let specimen_uid = self.uids.of("specimen");
        sequence(
            &mut o,
            tags::SPECIMEN_DESCRIPTION_SEQUENCE,
            vec![item(|i| {
                put(i, tags::SPECIMEN_IDENTIFIER, VR::LO, specimen);
                put(i, tags::SPECIMEN_UID, VR::UI, specimen_uid);
                sequence(i, tags::ISSUER_OF_THE_SPECIMEN_IDENTIFIER_SEQUENCE, vec![]);
                sequence(i, tags::SPECIMEN_PREPARATION_SEQUENCE, vec![]);
            })],
        );
        // Acquisition Context: none known.
        sequence(&mut o, tags::ACQUISITION_CONTEXT_SEQUENCE, vec![]);
        // Optical Path: one, brightfield, full spectrum.
        put(&mut o, tags::NUMBER_OF_OPTICAL_PATHS, VR::UL, 1u32);
        let icc = self.icc.clone().filter(|_| p != Photometric::Monochrome);
        sequence(
            &mut o,
            tags::OPTICAL_PATH_SEQUENCE,
            vec![item(|i| {
                put(i, tags::OPTICAL_PATH_IDENTIFIER, VR::SH, "1");
                sequence(
                    i,
                    tags::ILLUMINATION_TYPE_CODE_SEQUENCE,
                    vec![code("111744", "DCM", "Brightfield illumination")],
                );
                sequence(i, tags::ILLUMINATION_COLOR_CODE_SEQUENCE, vec![code("414298005", "SCT", "Full Spectrum")]);
                if let Some(icc) = icc {
                    put(i, tags::ICC_PROFILE, VR::OB, PrimitiveValue::U8(icc.into()));
                    put(i, tags::COLOR_SPACE, VR::CS, "SRGB");
                }
            })],
        );
        // Shared Functional Groups: pixel measures, optical path, frame type.
        let frame_type = part.image_type;
        sequence(
            &mut o,
            tags::SHARED_FUNCTIONAL_GROUPS_SEQUENCE,
            vec![item(|g| {
                sequence(
                    g,
                    tags::PIXEL_MEASURES_SEQUENCE,
                    vec![item(|i| {
                        if let Some(spacing) = part.spacing {
                            put(i, tags::PIXEL_SPACING, VR::DS, strs(&[&ds(spacing.0), &ds(spacing.1)]));
                        }
                        // Unknown: the nominal 1 um of Imaged Volume Depth, in mm.
                        put(i, tags::SLICE_THICKNESS, VR::DS, "0.001");
                    })],
                );
                sequence(
                    g,
                    tags::OPTICAL_PATH_IDENTIFICATION_SEQUENCE,
                    vec![item(|i| put(i, tags::OPTICAL_PATH_IDENTIFIER, VR::SH, "1"))],
                );
                sequence(
                    g,
                    tags::WHOLE_SLIDE_MICROSCOPY_IMAGE_FRAME_TYPE_SEQUENCE,
                    vec![item(|i| put(i, tags::FRAME_TYPE, VR::CS, strs(&frame_type)))],
                );
            })],
        );
        // Per frame (TILED_SPARSE, one frame): its dimension index values (column, row, as the
        // Dimension Index Sequence lists them) and its place, the whole image's: the Total
        // Pixel Matrix's first texel, at the origin the Total Pixel Matrix Origin states, in
        // the one focal plane (Z 0).
        if part.placed_per_frame() {
            sequence(
                &mut o,
                tags::PER_FRAME_FUNCTIONAL_GROUPS_SEQUENCE,
                vec![item(|g| {
                    sequence(
                        g,
                        tags::FRAME_CONTENT_SEQUENCE,
                        vec![item(|i| {
                            put(i, tags::DIMENSION_INDEX_VALUES, VR::UL, PrimitiveValue::U32([1, 1].into()))
                        })],
                    );
                    sequence(
                        g,
                        tags::PLANE_POSITION_SLIDE_SEQUENCE,
                        vec![item(|i| {
                            put(i, tags::COLUMN_POSITION_IN_TOTAL_IMAGE_PIXEL_MATRIX, VR::SL, 1i32);
                            put(i, tags::ROW_POSITION_IN_TOTAL_IMAGE_PIXEL_MATRIX, VR::SL, 1i32);
                            put(i, tags::X_OFFSET_IN_SLIDE_COORDINATE_SYSTEM, VR::DS, "0");
                            put(i, tags::Y_OFFSET_IN_SLIDE_COORDINATE_SYSTEM, VR::DS, "0");
                            put(i, tags::Z_OFFSET_IN_SLIDE_COORDINATE_SYSTEM, VR::DS, "0");
                        })],
                    );
                })],
            );
        }
        // Where the frames lie, past the Basic Offset Table's reach.
        if !offsets.fit_basic() {
            put(
                &mut o,
                tags::EXTENDED_OFFSET_TABLE,
                VR::OV,
                PrimitiveValue::U64(offsets.offsets.iter().copied().collect()),
            );
            let lengths = offsets.lengths.iter().copied().collect();
            put(&mut o, tags::EXTENDED_OFFSET_TABLE_LENGTHS, VR::OV, PrimitiveValue::U64(lengths));
        }
        o
    }
}

fn vr_of(vr: Vr) -> VR {
    match vr {
        Vr::Pn => VR::PN,
        Vr::Lo => VR::LO,
        Vr::Sh => VR::SH,
        Vr::Cs => VR::CS,
        Vr::Da => VR::DA,
        Vr::Tm => VR::TM,
        Vr::Dt => VR::DT,
        Vr::Ui => VR::UI,
        Vr::Is => VR::IS,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec() -> Spec {
        super::super::test_spec(600, 300, 2)
    }

    /// Where the frames' offsets fit 32 bits the data set has no Extended Offset Table;
    /// past them it has both its elements, OV, just before where Pixel Data goes; the header
    /// is the same for the same spec (the sRGB profile's date cleared).
    #[test]
    fn the_extended_offset_table_comes_where_offsets_pass_32_bits() {
        let spec = spec();
        spec.check().unwrap();
        let series = Series::new(&spec).unwrap();
        let near = Offsets { offsets: vec![0, 10, 20], lengths: vec![2, 2, 2] };
        let far = Offsets { offsets: vec![0, 1 << 31, 1 << 33], lengths: vec![2, 2, 2] };
        let part = Part::level(&spec, 0);
        let basic = series.header(&part, &near, 6).unwrap();
        assert_eq!(basic, Series::new(&spec).unwrap().header(&part, &near, 6).unwrap(), "the same bytes");
        assert_eq!(&basic[128..132], b"DICM");
        let eot = [0xE0, 0x7F, 0x01, 0x00, b'O', b'V'];
        let find = |bytes: &[u8], what: &[u8]| bytes.windows(what.len()).position(|w| w == what);
        assert_eq!(find(&basic, &eot), None);
        let extended = series.header(&part, &far, 6).unwrap();
        let at = find(&extended, &eot).expect("the Extended Offset Table");
        let lengths = find(&extended, &[0xE0, 0x7F, 0x02, 0x00, b'O', b'V']).expect("its lengths");
        // OV: 2 reserved bytes, a 32-bit length, then the 64-bit offsets.
        let value = &extended[at + 12..at + 12 + 24];
        assert_eq!(value[8..16], (1u64 << 31).to_le_bytes());
        assert_eq!(lengths, at + 12 + 24, "the lengths follow the offsets");
        assert_eq!(extended.len(), lengths + 12 + 24, "and end the data set, before Pixel Data");
    }

    /// Lossy Image Compression and its ratios and methods: the source's steps in order, then
    /// the series' JPEG baseline coding where it coded the frames (the ratio of the frames' texels to
    /// their bytes); `00` and neither list where no step was lossy.
    #[test]
    fn the_lossy_history_is_the_source_s_steps_then_the_series_own() {
        let text = |o: &Object, tag| o.element(tag).ok().map(|e| e.to_str().unwrap().to_string());
        // Level 0: 3 x 2 frames of 256 x 256 RGB texels in an eighth of their bytes.
        let offsets = Offsets { offsets: (0..6).collect(), lengths: vec![1; 6] };
        let frame_bytes = 6 * 256 * 256 * 3 / 8;
        let j2k = LossyStep { method: LossyStep::JPEG_2000.to_string(), ratio: 20.0 };
        let cases = [
            (Transfer::JpegBaseline, vec![], true, Some(("8", "ISO_10918_1"))),
            (Transfer::JpegBaseline, vec![j2k.clone()], false, Some(("20", "ISO_15444_1"))),
            (Transfer::JpegBaseline, vec![j2k.clone()], true, Some(("20\\8", "ISO_15444_1\\ISO_10918_1"))),
            // Copied JPEG 2000 frames are the source's coding, never the series' own.
            (Transfer::Jpeg2000, vec![j2k.clone()], true, Some(("20", "ISO_15444_1"))),
            (Transfer::Native, vec![j2k.clone()], true, Some(("20", "ISO_15444_1"))),
            (Transfer::Native, vec![], true, None),
            // Lossy JPEG XL frames coded here are a step of ISO/IEC 18181-1; lossless ones,
            // and JPEGs recompressed losslessly, none.
            (Transfer::JpegXl, vec![], true, Some(("8", "ISO_18181_1"))),
            (Transfer::JpegXl, vec![j2k.clone()], true, Some(("20\\8", "ISO_15444_1\\ISO_18181_1"))),
            (Transfer::JpegXl, vec![], false, None),
            (Transfer::JpegXlLossless, vec![], true, None),
            (Transfer::JpegXlRecompression, vec![j2k], false, Some(("20", "ISO_15444_1"))),
        ];
        for (transfer, before, coded_here, want) in cases {
            let spec = Spec { transfer, ..spec() };
            let series = Series::new(&spec).unwrap();
            let part = Part { lossy_before: before.clone(), coded_here, transfer, ..Part::level(&spec, 0) };
            let o = series.dataset(&part, &offsets, frame_bytes);
            let said = (
                text(&o, tags::LOSSY_IMAGE_COMPRESSION),
                text(&o, tags::LOSSY_IMAGE_COMPRESSION_RATIO),
                text(&o, tags::LOSSY_IMAGE_COMPRESSION_METHOD),
            );
            let want = match want {
                Some((ratios, methods)) => (Some("01".into()), Some(ratios.into()), Some(methods.into())),
                None => (Some("00".into()), None, None),
            };
            assert_eq!(said, want, "{transfer:?}, {before:?} before, coded here: {coded_here}");
        }
    }

    #[test]
    fn decimal_strings_fit_sixteen_characters() {
        assert_eq!(ds(0.00025), "0.00025");
        assert_eq!(ds(12.5), "12.5");
        assert_eq!(ds(3.0), "3");
        assert!(ds(1.0 / 3.0).len() <= 16);
        assert!(ds(123456.0 / 7.0).len() <= 16);
    }
}
