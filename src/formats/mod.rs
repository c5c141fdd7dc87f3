//! The file formats a run writes and reads back, one folder each: what a format names, how its
//! sink writes it and how it is read again as an input (`convert`) or served (`serve`).
//!
//! - [`tiles`]: this tool's tile directory (`info.json` + one file per tile), and the
//!   thesis's named tiles.
//! - [`pack`]: one pack file.
//! - [`viewer`]: the layouts a viewer opens as they are: Deep Zoom, IIIF level 0, XYZ/Google,
//!   from a directory or a zip archive.
//! - [`pmtiles`]: one PMTiles v3 archive.
//! - [`ome_zarr`]: an OME-Zarr image, 0.4 or 0.5, a directory or a `.ozx`.
//! - [`dicom`]: a DICOM whole-slide image series, one instance a level.
//! - [`tiff`]: a pyramidal TIFF in one file: OME-TIFF, or the generic pyramid OpenSlide and
//!   libvips read.
//!
//! - `levels`: a slide's own levels copied into a TIFF or a DICOM series.
//!
//! A new format is one folder here and one arm of [`crate::outputs::Format`].

pub mod dicom;
pub mod levels;
pub mod ome_zarr;
pub mod pack;
pub mod pmtiles;
pub mod tiff;
pub mod tiles;
pub mod viewer;
