//! File formats that hold a whole pyramid in one file another tool reads, each a folder of its
//! own that owns its names, its rules and its writer: [`tiff`] (a pyramidal TIFF: OME-TIFF
//! or the generic pyramid OpenSlide and libvips read).

pub mod tiff;
