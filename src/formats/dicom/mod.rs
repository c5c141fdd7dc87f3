//! DICOM whole-slide images out (`--layout dicom -o DIR`, docs/dicom.md): one VL Whole Slide
//! Microscopy Image instance (a DICOM Part-10 file) per pyramid level, the series a hospital's
//! archive, viewers and OpenSlide 4 read.
//!
//! * `Spec`: what every instance says, fixed and checked before the first tile.
//! * `uid`: the series' UIDs, a hash of the input and the options under a stated root, so that
//!   a re-run writes the same UIDs and the same bytes.
//! * `meta`: the patient, study and equipment attributes a user gives (`--dicom-meta`), never
//!   invented: empty (type 2) where not given.
//! * `dataset`: each level's data set, written by dicom-rs (`dicom-object`): every module the
//!   IOD requires, up to the Pixel Data element.
//! * `frames`: the encapsulated Pixel Data, written by our code after the data set: each
//!   level's frames are staged in a file as they arrive (memory holds 12 bytes a frame, never
//!   a frame) and copied into the instance at the end, row by row, behind the offset table.
//!   dicom-rs would hold every frame of a level in memory to write them itself.
//! * `sink`: `DicomSink`, the pipeline's sink: a staging directory renamed into place.
//!
//! * `copy`: a slide's own levels as the instances (`--levels stored`): every stored JPEG
//!   or JPEG 2000 tile of every level copied as a frame, nothing decoded, where all are what
//!   DICOM holds.
//!
//! After the levels, each of the source's associated images (label, overview, thumbnail:
//! `source::associated`) is an instance of one frame, encoded at `finish`, unless
//! `--no-associated` leaves them out.
//!
//! Frames are `TILED_FULL`: whole tiles of the level's grid in row-major order, the right and
//! bottom ones padded. They are JPEG baseline (1.2.840.10008.1.2.4.50) by default: a
//! JPEG-tiled source's stored tiles that match the level's photometric interpretation are
//! copied byte for byte (`takes_stored_jpeg`); a slide's own levels are copied whole (`copy`),
//! an Aperio slide's JPEG 2000 tiles as JPEG 2000 frames (1.2.840.10008.1.2.4.90 where every
//! level's codestreams are reversible, else .91; its associated images stay JPEG baseline).
//! With `--codec raw` they are native ([`Transfer::Native`], explicit VR little endian,
//! 1.2.840.10008.1.2.1): 8- or 16-bit grey or RGB samples as the pyramid made them, lossless,
//! each frame written in place in its instance (`frames::Native`). With `--codec jxl` they
//! are JPEG XL (Supplement 232; the encoders' JPEG XL tiles, staged as JPEG frames are):
//! [`Transfer::JpegXlLossless`] (1.2.840.10008.1.2.4.110) with `--lossless`, else
//! [`Transfer::JpegXl`] (.112), `RGB` or `MONOCHROME2` as they decode; a JPEG-tiled source's
//! stored tiles that fill level-0 frames come recompressed losslessly, and an instance of
//! only such frames is [`Transfer::JpegXlRecompression`] (.111), stating the JPEGs'
//! photometric interpretation (`sink::instance_coding` decides per instance; the associated
//! images stay JPEG baseline); a slide's own JPEG levels (`copy`) are recompressed tile by
//! tile, every instance .111. Not written: JPEG 2000 frames of our own coding, the Deflated
//! transfer syntax (docs/dicom.md says why).

mod copy;
mod dataset;
mod frames;
pub mod meta;
mod sink;
mod uid;

pub(crate) use copy::{Form, copy_levels, copyable};

pub use meta::DicomMeta;
pub(crate) use sink::DicomSink;
pub use uid::{DEFAULT_ROOT, check_root};

use crate::codec::Subsampling;
use crate::error::{Result, TilerError};
use crate::layout::Layout;
use crate::pixel::{Channels, Depth, PixelLayout};

/// The default frame side: the tile of most scanners' slides and of the pyramidal TIFF.
pub(crate) const DEFAULT_TILE_SIZE: u32 = 256;

/// The VL Whole Slide Microscopy Image Storage SOP Class.
pub(crate) const SOP_CLASS: &str = "1.2.840.10008.5.1.4.1.1.77.1.6";
/// JPEG Baseline (Process 1): the transfer syntax of JPEG frames.
pub(crate) const JPEG_BASELINE: &str = "1.2.840.10008.1.2.4.50";
/// JPEG 2000 Image Compression (Lossless Only): copied frames of the reversible wavelet.
pub(crate) const JPEG_2000_LOSSLESS: &str = "1.2.840.10008.1.2.4.90";
/// JPEG 2000 Image Compression: copied frames, lossy or not.
pub(crate) const JPEG_2000: &str = "1.2.840.10008.1.2.4.91";
/// Explicit VR Little Endian: the transfer syntax of native (uncompressed) frames.
pub(crate) const EXPLICIT_VR_LITTLE_ENDIAN: &str = "1.2.840.10008.1.2.1";
/// JPEG XL Lossless (PS3.5 A.4.12, Supplement 232): `--codec jxl --lossless` frames.
pub(crate) const JPEG_XL_LOSSLESS: &str = "1.2.840.10008.1.2.4.110";
/// JPEG XL JPEG Recompression: every frame a JPEG recompressed losslessly, from which the
/// JPEG comes back byte for byte.
pub(crate) const JPEG_XL_RECOMPRESSION: &str = "1.2.840.10008.1.2.4.111";
/// JPEG XL: any JPEG XL codestream, lossy or not.
pub(crate) const JPEG_XL: &str = "1.2.840.10008.1.2.4.112";

/// The most bytes a native instance's Pixel Data may hold: its element's 32-bit length, even,
/// short of `FFFFFFFF` (undefined length, which only encapsulated data may have).
pub(crate) const NATIVE_MOST_BYTES: u64 = u32::MAX as u64 - 1;

/// How the frames of every instance of a series are stored: its transfer syntax.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Transfer {
    /// JPEG baseline, one JPEG a frame, encapsulated (8-bit, lossy): the default.
    JpegBaseline,
    /// Native (`--codec raw`): the samples as they are, 8 or 16 bits, interleaved, little
    /// endian, every frame of an instance one after another in its Pixel Data (lossless).
    Native,
    /// JPEG 2000 of the reversible wavelet only, encapsulated: a slide's lossless JPEG 2000
    /// tiles copied (never coded here).
    Jpeg2000Lossless,
    /// JPEG 2000, encapsulated: a slide's JPEG 2000 tiles copied, some of the irreversible
    /// wavelet.
    Jpeg2000,
    /// JPEG XL Lossless (`--codec jxl --lossless`), encapsulated: the pyramid's samples kept,
    /// 8 or 16 bits.
    JpegXlLossless,
    /// JPEG XL JPEG Recompression: an instance whose every frame is a source's stored JPEG
    /// tile recompressed losslessly (never a series' own choice: the sink finds it per
    /// instance).
    JpegXlRecompression,
    /// JPEG XL (`--codec jxl`, lossy), encapsulated; also an instance that mixes
    /// recompressed JPEG tiles (valid JPEG XL codestreams) with frames coded here.
    JpegXl,
}

impl Transfer {
    /// The Transfer Syntax UID.
    pub fn uid(self) -> &'static str {
        match self {
            Transfer::JpegBaseline => JPEG_BASELINE,
            Transfer::Native => EXPLICIT_VR_LITTLE_ENDIAN,
            Transfer::Jpeg2000Lossless => JPEG_2000_LOSSLESS,
            Transfer::Jpeg2000 => JPEG_2000,
            Transfer::JpegXlLossless => JPEG_XL_LOSSLESS,
            Transfer::JpegXlRecompression => JPEG_XL_RECOMPRESSION,
            Transfer::JpegXl => JPEG_XL,
        }
    }

    /// Whether its frames are JPEG XL codestreams.
    pub fn jpeg_xl(self) -> bool {
        matches!(self, Transfer::JpegXlLossless | Transfer::JpegXlRecompression | Transfer::JpegXl)
    }

    /// Whether its frames are encapsulated (one item a frame), not native.
    pub fn encapsulated(self) -> bool {
        self != Transfer::Native
    }

    /// What the frames are, for the summary: `JPEG baseline`, `JPEG 2000 lossless`, `JPEG
    /// 2000`, `JPEG XL lossless`, `JPEG XL recompressed JPEG`, `JPEG XL`, `native 8-bit`,
    /// `native 16-bit`.
    pub fn describe(self, depth: Depth) -> &'static str {
        match (self, depth) {
            (Transfer::JpegBaseline, _) => "JPEG baseline",
            (Transfer::Jpeg2000Lossless, _) => "JPEG 2000 lossless",
            (Transfer::Jpeg2000, _) => "JPEG 2000",
            (Transfer::JpegXlLossless, _) => "JPEG XL lossless",
            (Transfer::JpegXlRecompression, _) => "JPEG XL recompressed JPEG",
            (Transfer::JpegXl, _) => "JPEG XL",
            (Transfer::Native, Depth::U16) => "native 16-bit",
            (Transfer::Native, _) => "native 8-bit",
        }
    }
}

/// How the frames' pixels are stored, as `PhotometricInterpretation` says.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Photometric {
    /// Grey, `MONOCHROME2`.
    Monochrome,
    /// YCbCr with the chroma halved both ways (JPEG 4:2:0), `YBR_FULL_422` as DICOM names
    /// every subsampled JPEG baseline frame.
    YbrFull422,
    /// YCbCr without subsampling (JPEG 4:4:4), `YBR_FULL`: which a whole-slide image may not
    /// state (`Spec::check` refuses it; PS3.3 C.8.12.4.1.5).
    YbrFull,
    /// R, G, B as they are (a JPEG whose Adobe marker says no transform), `RGB`: as Aperio
    /// slides store them, or `--subsampling rgb`; JPEG 2000 without its colour transform.
    Rgb,
    /// JPEG 2000 through its reversible colour transform (RCT), `YBR_RCT`.
    YbrRct,
    /// JPEG 2000 through its irreversible colour transform (ICT), `YBR_ICT`.
    YbrIct,
}

impl Photometric {
    /// The attribute's value.
    pub fn name(self) -> &'static str {
        match self {
            Photometric::Monochrome => "MONOCHROME2",
            Photometric::YbrFull422 => "YBR_FULL_422",
            Photometric::YbrFull => "YBR_FULL",
            Photometric::Rgb => "RGB",
            Photometric::YbrRct => "YBR_RCT",
            Photometric::YbrIct => "YBR_ICT",
        }
    }

    /// The JPEG frames of `channels` at `subsampling`, as the encoders write them.
    pub(crate) fn of(channels: Channels, subsampling: Subsampling) -> Photometric {
        match (channels, subsampling) {
            (Channels::Grey, _) => Photometric::Monochrome,
            (_, Subsampling::S420) => Photometric::YbrFull422,
            (_, Subsampling::S444) => Photometric::YbrFull,
            (_, Subsampling::Rgb) => Photometric::Rgb,
        }
    }

    /// Native frames of `channels`: the samples as they are, grey or RGB (interleaved); also
    /// what JPEG XL frames coded here state (what they decode to).
    pub(crate) fn native(channels: Channels) -> Photometric {
        match channels {
            Channels::Grey => Photometric::Monochrome,
            _ => Photometric::Rgb,
        }
    }

    /// Samples a pixel.
    pub fn samples(self) -> u16 {
        match self {
            Photometric::Monochrome => 1,
            _ => 3,
        }
    }
}

pub use crate::layout::Levels;

/// One instance's image: its Total Pixel Matrix and its frames' size (`tile`), columns by
/// rows; `TILED_FULL`: the right and bottom frames reach past the image.
pub(crate) use crate::layout::Level;

/// Everything the instances say, fixed before the first tile.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Spec {
    /// The pyramid's page grid, border 0: level `k` is `layout.level_extent(k)` in
    /// `layout.grid(k)` frames of `tile_size` a side.
    pub layout: Layout,
    /// The slide's own levels, copied as stored (`copy`), largest first; empty: the levels
    /// of `layout`.
    pub copied: Vec<Level>,
    /// The samples as stored: 8-bit grey or RGB, or 16-bit for native frames.
    pub stored: PixelLayout,
    pub photometric: Photometric,
    /// How every instance's frames are stored, the associated images' too.
    pub transfer: Transfer,
    /// The side of a full-resolution pixel, in millimetres (DICOM's unit).
    pub pixel_mm: f64,
    /// The slide's name: the container and specimen identifiers where `--dicom-meta` gives
    /// none, and the series description.
    pub name: String,
    /// The UID root (`--dicom-uid-root`, else [`DEFAULT_ROOT`]).
    pub uid_root: String,
    /// What the UIDs are a hash of: the input's fingerprint and the options.
    pub identity: String,
    /// When the image was made, as a DICOM date-time `YYYYMMDDHHMMSS` (UTC): the
    /// `AcquisitionDateTime` of `--dicom-meta`, else the input's modification time.
    pub made: String,
    /// The attributes the user gave.
    pub meta: DicomMeta,
    /// The source's associated images, each its own instance after the levels (one frame,
    /// the whole image, decoded and encoded as JPEG at `quality`, or native 8-bit); empty
    /// with `--no-associated`.
    pub associated: Vec<crate::source::associated::Associated>,
    /// The JPEG quality of the associated images' frames (not used by native ones).
    pub quality: u8,
    /// `--jxl-effort` of a JPEG XL series: what a slide's copied JPEG levels are recompressed
    /// at (`copy`); `None` for other frames.
    pub jxl_effort: Option<crate::codec::JxlEffort>,
    /// The most bytes one associated image may take decoded (half of `--max-memory`).
    pub associated_bytes: u64,
    /// The associated images the source has that `--no-associated` left out.
    pub associated_left_out: usize,
    /// The lossy compressions the source's texels went through, oldest first: every level's
    /// instance states them (Lossy Image Compression Method and Ratio) before the series' own
    /// JPEG coding, which an instance of copied frames did not add.
    pub source_lossy: Vec<crate::source::LossyStep>,
}

impl Spec {
    /// Refuses what these instances cannot hold, before anything is written.
    pub fn check(&self) -> Result<()> {
        let l = &self.layout;
        if l.border != 0 {
            return Err(TilerError::Options(format!("--border {}: DICOM frames have no border", l.border)));
        }
        if l.tile_size == 0 || l.tile_size > u32::from(u16::MAX) {
            return Err(TilerError::Options(format!(
                "--tile-size {}: a DICOM frame's Rows and Columns are 16-bit",
                l.tile_size
            )));
        }
        if l.width == 0 || l.height == 0 {
            return Err(TilerError::Geometry(format!("a {}x{} image has no pixels", l.width, l.height)));
        }
        let s = self.stored;
        let grey_or_rgb = matches!(s.channels, Channels::Grey | Channels::Rgb);
        match self.transfer {
            Transfer::JpegBaseline if s.depth != Depth::U8 || !grey_or_rgb => {
                return Err(TilerError::Options(format!(
                    "JPEG baseline DICOM frames are 8-bit grey or RGB, not {s}: --codec raw writes native frames of 8 or 16 bits"
                )));
            }
            Transfer::Native if !matches!(s.depth, Depth::U8 | Depth::U16) || !grey_or_rgb => {
                return Err(TilerError::Options(format!(
                    "native DICOM frames are 8- or 16-bit unsigned grey or RGB, not {s}"
                )));
            }
            Transfer::Native if !self.copied.is_empty() => {
                return Err(TilerError::Internal("a slide's JPEG levels copied into native frames".into()));
            }
            Transfer::Jpeg2000Lossless | Transfer::Jpeg2000 if self.copied.is_empty() || s.depth != Depth::U8 => {
                return Err(TilerError::Internal("JPEG 2000 frames that are no slide's copied levels".into()));
            }
            Transfer::JpegXlLossless | Transfer::JpegXl
                if !matches!(s.depth, Depth::U8 | Depth::U16) || !grey_or_rgb =>
            {
                return Err(TilerError::Options(format!(
                    "JPEG XL DICOM frames are 8- or 16-bit unsigned grey or RGB, not {s}"
                )));
            }
            Transfer::JpegXlLossless | Transfer::JpegXl if !self.copied.is_empty() => {
                return Err(TilerError::Internal("a slide's JPEG levels copied into JPEG XL frames".into()));
            }
            // Found per instance by the sink where every frame is a recompressed JPEG, or a
            // whole series of a slide's JPEG levels, every tile recompressed (`copy`).
            Transfer::JpegXlRecompression if self.copied.is_empty() || s.depth != Depth::U8 => {
                return Err(TilerError::Internal(
                    "a series stated JPEG XL JPEG Recompression that copies no slide's JPEG levels".into(),
                ));
            }
            _ => {}
        }
        if self.photometric == Photometric::YbrFull {
            return Err(TilerError::Options(
                "--subsampling 444: YCbCr JPEG frames at 4:4:4 are YBR_FULL, which a VL Whole Slide Microscopy Image may not state (its Photometric Interpretation is MONOCHROME2, RGB, YBR_FULL_422, YBR_ICT or YBR_RCT): use 420 (the default) or rgb".into(),
            ));
        }
        if matches!(self.transfer, Transfer::Native | Transfer::JpegXlLossless | Transfer::JpegXl)
            && self.photometric != Photometric::native(s.channels)
        {
            return Err(TilerError::Internal(format!(
                "{} {s} frames stated as {}",
                self.transfer.describe(s.depth),
                self.photometric.name()
            )));
        }
        if !(self.pixel_mm.is_finite() && self.pixel_mm > 0.0) {
            return Err(TilerError::Options(format!("a pixel size of {} mm", self.pixel_mm)));
        }
        for lod in 0..self.level_count() {
            let level = self.level(lod);
            let (c, r) = level.grid();
            if level.tile.0 == 0 || level.tile.1 == 0 || level.tile.0.max(level.tile.1) > u32::from(u16::MAX) {
                return Err(TilerError::Options(format!(
                    "level {lod}'s {}x{} frames: a DICOM frame's Rows and Columns are 16-bit",
                    level.tile.0, level.tile.1
                )));
            }
            if level.tiles() > i32::MAX as u64 {
                return Err(TilerError::Options(format!(
                    "level {lod} has {c} x {r} frames: a DICOM instance's Number of Frames is at most {}",
                    i32::MAX
                )));
            }
            let bytes = self.pixel_data_bytes(level, s);
            if self.transfer == Transfer::Native && bytes > NATIVE_MOST_BYTES {
                return Err(TilerError::Options(format!(
                    "level {lod} ({}x{} texels, {c} x {r} frames of {}x{} {s}) would hold {bytes} bytes ({:.1} GiB) of native Pixel Data, past the 4 GiB a DICOM element's 32-bit length reaches (native frames have no offset table to go further): write JPEG frames (leave out --codec raw){}, or a smaller image",
                    level.width,
                    level.height,
                    level.tile.0,
                    level.tile.1,
                    bytes as f64 / f64::from(1u32 << 30),
                    if s.depth == Depth::U16 { ", 8-bit samples (--tile-type u8)" } else { "" }
                )));
            }
        }
        for image in &self.associated {
            if image.width == 0 || image.height == 0 || image.width.max(image.height) > u32::from(u16::MAX) {
                return Err(TilerError::Options(format!(
                    "the {} ({}, {}x{}) is one frame, whose Rows and Columns are 16-bit: --no-associated leaves the associated images out",
                    image.kind.name(),
                    image.origin(),
                    image.width,
                    image.height
                )));
            }
            // Decoded as 8-bit RGB at most: three bytes a texel.
            let bytes = u64::from(image.width) * u64::from(image.height) * 3;
            if self.transfer == Transfer::Native && bytes > NATIVE_MOST_BYTES {
                return Err(TilerError::Options(format!(
                    "the {} ({}, {}x{}) would be {bytes} bytes of native Pixel Data, past the 4 GiB a DICOM element's 32-bit length reaches: --no-associated leaves the associated images out",
                    image.kind.name(),
                    image.origin(),
                    image.width,
                    image.height
                )));
            }
        }
        uid::check_root(&self.uid_root)?;
        Ok(())
    }

    /// The file name of associated image `k`'s instance: `label.dcm`, `overview.dcm`,
    /// `thumbnail.dcm`, numbered from the second of a kind on (`label-2.dcm`).
    pub fn associated_file_name(&self, k: usize) -> String {
        let kind = self.associated[k].kind;
        match self.associated[..k].iter().filter(|a| a.kind == kind).count() {
            0 => format!("{}.dcm", kind.name()),
            n => format!("{}-{}.dcm", kind.name(), n + 1),
        }
    }

    /// Instances in the series, one a level.
    pub fn level_count(&self) -> u32 {
        Level::count(&self.copied, &self.layout)
    }

    /// Level `lod`'s image and frames.
    pub fn level(&self, lod: u32) -> Level {
        Level::of(&self.copied, &self.layout, lod)
    }

    /// Bytes of `level`'s frames of `stored` samples, uncompressed: what a native
    /// instance's Pixel Data holds (before its pad to an even length).
    pub fn pixel_data_bytes(&self, level: Level, stored: PixelLayout) -> u64 {
        let frame = u64::from(level.tile.0) * u64::from(level.tile.1) * stored.bytes_per_pixel() as u64;
        level.tiles().saturating_mul(frame)
    }

    /// Memory the sink's frame index holds: 12 bytes a frame.
    pub fn index_bytes(&self) -> u64 {
        let frames: u64 = (0..self.level_count()).map(|lod| self.level(lod).tiles()).sum();
        frames.saturating_mul(12)
    }

    /// The file name of level `lod`'s instance in the series' directory.
    pub fn file_name(lod: u32) -> String {
        format!("level-{lod}.dcm")
    }
}

/// A pixel size in micrometres to DICOM's millimetres.
pub(crate) fn millimetres(micrometres: f64) -> f64 {
    micrometres / 1000.0
}

/// What a series written says of itself, for the summary and `--json`.
#[derive(Clone, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub struct DicomSummary {
    /// Instances written, one a level.
    pub instances: u32,
    /// Frames stored, every level.
    pub frames: u64,
    /// The `PhotometricInterpretation` of the frames.
    pub photometric: &'static str,
    /// The series' Transfer Syntax UID (each level's instance's is in `level_frames`: in a
    /// JPEG XL series one of only recompressed JPEGs is JPEG XL JPEG Recompression).
    pub transfer_syntax: &'static str,
    /// What the frames are: `Transfer::describe` of the series' transfer syntax (`JPEG baseline`,
    /// `JPEG XL`, `native 8-bit`, ...).
    pub frame_coding: &'static str,
    /// The Series Instance UID.
    pub series_uid: String,
    /// Instances whose frames are located by the Extended Offset Table (past 4 GiB), not the
    /// Basic Offset Table.
    pub extended_offsets: u32,
    /// Bytes of the frames, as stored.
    pub frame_bytes: u64,
    /// Bytes of the instances' files, together.
    pub file_bytes: u64,
    /// The levels asked for (`--levels`).
    pub levels: Levels,
    /// Whether the instances are the slide's own levels, every frame copied as stored.
    pub levels_copied: bool,
    /// Why the slide's own levels were not copied where they were asked for (the source is
    /// no pyramid of JPEG tiles, or one DICOM cannot hold as it is).
    pub levels_declined: Option<String>,
    /// The associated images carried, each its own instance (not counted in `instances`
    /// and `frames`).
    pub associated: Vec<AssociatedSummary>,
    /// The associated images the source has that `--no-associated` left out.
    pub associated_left_out: usize,
    /// Each level's instance, largest first: how its frames are stored. Its transfer syntax
    /// is the series' but in a JPEG XL series, where an instance of only recompressed JPEG
    /// tiles is JPEG XL JPEG Recompression.
    pub level_frames: Vec<LevelFrames>,
}

/// How one level's instance stores its frames.
#[derive(Clone, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub struct LevelFrames {
    /// Its Transfer Syntax UID.
    pub transfer_syntax: &'static str,
    /// Its `PhotometricInterpretation`.
    pub photometric: &'static str,
    /// Its frames that are a source's stored tiles, copied or recompressed losslessly.
    pub stored: u64,
}

/// One associated image carried into a series.
#[derive(Clone, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub struct AssociatedSummary {
    /// `label`, `overview` or `thumbnail`.
    pub kind: &'static str,
    /// Texels across, as stored (its one frame's Columns).
    pub width: u32,
    /// Texels down (its one frame's Rows).
    pub height: u32,
    /// Where the source stores it (`page 3`).
    pub origin: String,
    /// Its instance's file name in the series' directory.
    pub file: String,
    /// The `PhotometricInterpretation` of its frame.
    pub photometric: &'static str,
    /// Bytes of its one frame (JPEG, or native samples).
    pub frame_bytes: u64,
}

/// A JPEG series of `lods` levels of a `width x height` 8-bit RGB image in 256-texel frames,
/// YCbCr 4:2:0, with fixed names, UIDs and date: what the unit tests vary.
#[cfg(test)]
pub(super) fn test_spec(width: u64, height: u64, lods: u32) -> Spec {
    let mut layout = crate::layout::Layout::new(width, height, 256, 0).expect("a layout");
    layout.lod_count = lods;
    Spec {
        layout,
        copied: Vec::new(),
        stored: PixelLayout::new(Channels::Rgb, Depth::U8),
        photometric: Photometric::YbrFull422,
        transfer: Transfer::JpegBaseline,
        pixel_mm: 0.0005,
        name: "slide".into(),
        uid_root: DEFAULT_ROOT.into(),
        identity: "test".into(),
        made: "20260102030405".into(),
        meta: Default::default(),
        associated: Vec::new(),
        quality: 85,
        jxl_effort: None,
        associated_bytes: 1 << 20,
        associated_left_out: 0,
        source_lossy: Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A series of one level of 256-texel frames of native `stored` samples.
    fn native(width: u64, height: u64, stored: PixelLayout) -> Spec {
        let mut spec = test_spec(width, height, 1);
        spec.stored = stored;
        spec.photometric = Photometric::native(stored.channels);
        spec.transfer = Transfer::Native;
        spec
    }

    /// A native level's Pixel Data must fit its element's 32-bit length (no offset table
    /// goes past it): 256 x 255 frames of 256 x 256 grey bytes do (4278190080 bytes), 256 x
    /// 256 (2^32) do not, and the refusal names the level, its size and what to change;
    /// 16-bit samples take twice the bytes. JPEG frames are not bounded so.
    #[test]
    fn a_native_level_past_32_bits_is_refused_naming_it() {
        let grey = PixelLayout::new(Channels::Grey, Depth::U8);
        native(65536, 65280, grey).check().unwrap();
        let message = native(65536, 65536, grey).check().unwrap_err().to_string();
        for want in ["level 0", "65536x65536", "4294967296 bytes", "4 GiB", "--codec raw"] {
            assert!(message.contains(want), "{want}: {message}");
        }
        let wide = PixelLayout::new(Channels::Grey, Depth::U16);
        let message = native(65536, 32768, wide).check().unwrap_err().to_string();
        assert!(message.contains("--tile-type u8"), "{message}");
        native(65536, 32512, wide).check().unwrap();
        let rgb16 = PixelLayout::new(Channels::Rgb, Depth::U16);
        // 6 bytes a texel: 104 x 104 frames fit, 105 x 105 do not.
        native(26624, 26624, rgb16).check().unwrap();
        assert!(native(26625, 26625, rgb16).check().is_err(), "6 bytes a texel");
        let jpeg = Spec { transfer: Transfer::JpegBaseline, ..native(65536, 65536, grey) };
        jpeg.check().unwrap();
    }

    /// Native frames hold 8- or 16-bit unsigned grey or RGB, stated as MONOCHROME2 or RGB;
    /// JPEG frames 8-bit only.
    #[test]
    fn native_frames_are_8_or_16_bit_grey_or_rgb() {
        let ok = |c, d| native(600, 300, PixelLayout::new(c, d)).check();
        ok(Channels::Rgb, Depth::U16).unwrap();
        ok(Channels::Grey, Depth::U8).unwrap();
        assert!(ok(Channels::Grey, Depth::F32).is_err());
        assert!(ok(Channels::Rgba, Depth::U8).is_err());
        let ybr = Spec {
            photometric: Photometric::YbrFull422,
            ..native(600, 300, PixelLayout::new(Channels::Rgb, Depth::U8))
        };
        assert!(ybr.check().is_err(), "native frames are RGB as stored");
        let wide = PixelLayout::new(Channels::Grey, Depth::U16);
        let jpeg = Spec { transfer: Transfer::JpegBaseline, ..native(600, 300, wide) };
        assert!(jpeg.check().unwrap_err().to_string().contains("--codec raw"));
    }

    /// JPEG XL frames hold 8- or 16-bit grey or RGB, stated as MONOCHROME2 or RGB (what they
    /// decode to); JPEG XL JPEG Recompression is an instance's, never a whole series' choice.
    #[test]
    fn jpeg_xl_frames_are_8_or_16_bit_grey_or_rgb_as_decoded() {
        let jxl = |transfer, c, d| {
            let stored = PixelLayout::new(c, d);
            Spec { transfer, photometric: Photometric::native(c), ..native(600, 300, stored) }
        };
        jxl(Transfer::JpegXl, Channels::Rgb, Depth::U8).check().unwrap();
        jxl(Transfer::JpegXlLossless, Channels::Grey, Depth::U16).check().unwrap();
        assert!(jxl(Transfer::JpegXl, Channels::Rgba, Depth::U8).check().is_err());
        assert!(jxl(Transfer::JpegXlLossless, Channels::Grey, Depth::F32).check().is_err());
        let ybr = Spec { photometric: Photometric::YbrFull422, ..jxl(Transfer::JpegXl, Channels::Rgb, Depth::U8) };
        assert!(ybr.check().is_err(), "JPEG XL frames decode to RGB");
        assert!(jxl(Transfer::JpegXlRecompression, Channels::Rgb, Depth::U8).check().is_err(), "no copied levels");
        assert_eq!(Transfer::JpegXlRecompression.uid(), "1.2.840.10008.1.2.4.111");
        assert!(Transfer::JpegXl.jpeg_xl() && Transfer::JpegXl.encapsulated() && !Transfer::Jpeg2000.jpeg_xl());
    }

    /// Every name a series gives its instances is one a later run recognises as its own
    /// (`output::ours`).
    #[test]
    fn instance_names_are_recognised() {
        let mut names: Vec<String> = (0..12).map(Spec::file_name).collect();
        names.extend(["label.dcm", "overview.dcm", "thumbnail.dcm", "label-2.dcm"].map(String::from));
        for name in names {
            assert!(crate::output::ours::is_dicom_instance_name(&name), "{name}");
        }
    }
}
