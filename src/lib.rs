//! The library behind `vortex-tiler`: cut an image of any size into the pages of a virtual
//! texture, with every power-of-two LOD, in memory bounded by the image's width.
//!
//! The modules follow the data: [`source`] delivers rows, [`band`] holds the rows a row of
//! pages needs, [`pyramid`] cascades exact sums to the coarser LODs, [`cut`] assembles pages
//! with their borders, [`codec`] encodes them and [`sink`] stores them; [`split`] runs that
//! pipeline; [`filter`] and [`resample`] are the LOD filters. [`layout`] is the page grid's
//! geometry, [`settings`] and [`info`] turn flags and `info.json` into options and back. See
//! `docs/architecture.md`.

pub mod background;
pub mod band;
pub mod codec;
pub mod cut;
pub mod error;
pub mod filename;
pub mod filter;
pub mod info;
pub mod layout;
pub mod limits;
pub mod output;
pub mod pack_sink;
pub mod pixel;
pub mod pyramid;
pub mod repack;
pub mod resample;
pub mod settings;
pub mod sink;
pub mod source;
pub mod split;
pub mod tiled;
