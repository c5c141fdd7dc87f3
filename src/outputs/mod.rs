//! What a run writes: one or more outputs, each a [`Format`] at a path, planned together from
//! one source ([`Plan::new`]) and written from one read of it ([`Plan::write`]).
//!
//! Planning checks everything a format cannot hold before a byte is written, with the messages
//! `split` prints, and claims every destination ([`crate::output::claim`]). Writing groups the
//! outputs that cut the same pyramid (the same tile size, border and filter: a pack and Deep
//! Zoom, XYZ and PMTiles, OME-Zarr beside them with `--filter box`): each page of a group is
//! cut once and encoded once for every codec and crop its outputs keep. Groups that differ
//! (OME-Zarr's box filter beside the image outputs' default, another tile size) each make
//! their own pyramid from the same decoded rows (`source::tee`). Every output stays atomic: it is written under a temporary name and
//! renamed into place when complete; a run that fails leaves none of them.
//!
//! The crate's documentation has an example that writes Deep Zoom and a pack in one run.

mod plan;
mod resume;
mod write;

use std::path::{Path, PathBuf};

pub use plan::Plan;
pub use resume::Resumed;
pub use write::{Figures, Wrote};

use crate::formats::ome_zarr::{PixelSize, Version};
use crate::formats::tiff::Flavour;
use crate::formats::viewer::Viewer;
use crate::settings::Requested;

/// A file layout a run can write.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum Format {
    /// This tool's tile directory: tiles named by a filename format plus `info.json`.
    Tiles,
    /// One pack file (docs/pack-format.md).
    Pack,
    /// A directory a viewer opens as it is (Deep Zoom, IIIF level 0, XYZ, Google).
    Viewer(Viewer),
    /// One PMTiles v3 archive of the web-map (XYZ) pyramid.
    Pmtiles,
    /// An OME-Zarr image: a `.ome.zarr` directory or a zipped `.ozx` file.
    OmeZarr,
    /// One pyramidal TIFF file: OME-TIFF or the generic pyramid (docs/tiff.md).
    Tiff(Flavour),
    /// A DICOM whole-slide image series: a directory of one instance a level (docs/dicom.md).
    Dicom,
}

impl Format {
    /// The format's name in messages and `--json` (`--layout`'s names, `pack`, `pmtiles`).
    pub fn name(self) -> &'static str {
        match self {
            Format::Tiles => "vortex",
            Format::Pack => "pack",
            Format::Viewer(viewer) => viewer.name(),
            Format::Pmtiles => "pmtiles",
            Format::OmeZarr => "ome-zarr",
            Format::Tiff(flavour) => flavour.name(),
            Format::Dicom => "dicom",
        }
    }

    /// The format a path's name says, where it says one: `.vtpk` a pack, `.pmtiles` PMTiles,
    /// `.ome.zarr` and `.ozx` OME-Zarr, `.ome.tif(f)` OME-TIFF and `.tif(f)` the generic
    /// TIFF pyramid. A directory's name says none.
    pub fn of_path(path: &Path) -> Option<Format> {
        let name = path.file_name()?.to_string_lossy().to_ascii_lowercase();
        let name = name.trim_end_matches('/');
        if name.ends_with(".vtpk") {
            Some(Format::Pack)
        } else if name.ends_with(".pmtiles") {
            Some(Format::Pmtiles)
        } else if name.ends_with(".ome.zarr") || name.ends_with(".ozx") {
            Some(Format::OmeZarr)
        } else {
            Flavour::of_name(name).map(Format::Tiff)
        }
    }
}

impl std::fmt::Display for Format {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// One output of a run: a format at a path.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Output {
    /// What is written.
    pub format: Format,
    /// Where: a directory for the directory layouts, OME-Zarr and DICOM, a file for the others.
    pub path: PathBuf,
}

impl Output {
    /// `format` at `path`; nothing is checked until [`Plan::new`].
    pub fn new(format: Format, path: impl Into<PathBuf>) -> Output {
        Output { format, path: path.into() }
    }
}

pub use crate::limits::Budget;

/// What a run's outputs are asked, `split`'s flags: each output reads the settings its format
/// has and leaves the others to the run's other outputs; a setting no output of the run reads
/// is refused, naming its flag, as a one-output run refuses it.
#[derive(Clone, Debug, Default)]
pub struct Settings {
    /// Tile size, border, codec and its settings, pyramid filter, background, tile type,
    /// filename format; `max_memory` is the run's [`Budget`] and is ignored here.
    pub tiles: Requested,
    /// Deep Zoom's overlap (`--overlap`).
    pub overlap: Option<u32>,
    /// The pyramid's name: Deep Zoom's `NAME.dzi`, TileJSON's and PMTiles' `name`, OME-Zarr's
    /// `multiscales` name [default: the input's file stem].
    pub name: Option<String>,
    /// IIIF: the absolute URL the image is served at (`--iiif-id`).
    pub iiif_id: Option<String>,
    /// OME-Zarr's own settings; its `pixel_size` is a TIFF's too.
    pub ome_zarr: OmeZarrSettings,
    /// A TIFF's own settings.
    pub tiff: TiffSettings,
    /// A DICOM series' own settings.
    pub dicom: DicomSettings,
    /// Which levels a TIFF or a DICOM series holds (`--levels`) [default: the slide's own, as
    /// stored, where it has some].
    pub levels: Option<crate::layout::Levels>,
    /// Leave the source's associated images (label, macro, thumbnail) out of a generic TIFF,
    /// an OME-TIFF and a DICOM series (`--no-associated`) [default: carried, each an IFD, an
    /// OME image or an instance of its own].
    pub no_associated: bool,
    /// How a pack's bytes are laid out.
    pub pack: vortex_pack::WriteOptions,
    /// The source's ICC profile, where the texels keep its colours (`--keep-icc`): in a tile
    /// directory's JPEG and PNG tiles and in `info.json`; other formats refuse it.
    pub keep_icc: Option<Vec<u8>>,
    /// The source's georeferencing (a GeoTIFF's tags): TIFF outputs write it into their full
    /// resolution; the others carry none and ignore it.
    pub geo: Option<crate::source::GeoTags>,
    /// The physical size of a source pixel where its file states it: an OME-Zarr, a TIFF or a
    /// DICOM series records it when `ome_zarr.pixel_size` is not given.
    pub pitch: Option<crate::source::PixelPitch>,
    /// The lossy compressions the source's texels went through (`Embedded::lossy`): a DICOM
    /// series lists them before its own JPEG coding.
    pub lossy: Vec<crate::source::LossyStep>,
    /// The one channel the source's file names (`Embedded::channel`): an OME-TIFF of one
    /// plane names its channel so.
    pub channel: Option<crate::source::ChannelLabel>,
    /// How the source's stored JPEG tiles code colour (its first tile's, as
    /// `StoredTiles::subsampling` reads it): a TIFF or DICOM output's JPEG tiles are coded so
    /// where `--subsampling` is not given, so that the stored tiles can be copied into it.
    pub stored_subsampling: Option<crate::codec::Subsampling>,
    /// Replace a foreign regular file at a file output (`--force`).
    pub force: bool,
}

/// What only OME-Zarr outputs read (`None`: not given).
#[derive(Clone, Debug, Default)]
pub struct OmeZarrSettings {
    /// 0.4 or 0.5 [default: 0.5, or a label image's image's].
    pub version: Option<Version>,
    /// Chunks per shard side (0.5).
    pub shard_chunks: Option<u32>,
    /// The physical side of a source pixel.
    pub pixel_size: Option<PixelSize>,
}

/// What only DICOM outputs read (docs/dicom.md).
#[derive(Clone, Debug, Default)]
pub struct DicomSettings {
    /// The root the series' UIDs are made under (`--dicom-uid-root`) [default: 2.25, UUIDs].
    pub uid_root: Option<String>,
    /// The patient, study and equipment attributes given (`--dicom-meta`).
    pub meta: Option<crate::formats::dicom::DicomMeta>,
}

/// What only TIFF outputs read.
#[derive(Clone, Copy, Debug, Default)]
pub struct TiffSettings {
    /// Classic TIFF where the file stays under 4 GiB, else BigTIFF; or always BigTIFF.
    pub bigtiff: crate::formats::tiff::BigTiff,
}
