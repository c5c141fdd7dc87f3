//! A slide's own levels as the TIFF's (`--levels stored`, the default): every stored JPEG tile
//! of every level copied into the level's IFD, its tables made complete as the source hands
//! stored tiles out (`source::stored`), nothing decoded. A TIFF pyramid may step down by any
//! factor (OpenSlide, libvips, tifffile and bioformats read each level's own size), and its
//! edge tiles are whole, padded tiles, as the slide stores them.
//!
//! [`copyable`] looks at each level's first tile before anything is written: baseline or
//! extended 8-bit JPEG of the tile's size, one coding for every level (grey, YCbCr 4:2:0 or
//! 4:4:4, or RGB), since the file declares it in each level's tags alike; where one is not,
//! the file is our pyramid and the summary says why. `formats::levels::copy` then copies
//! every tile, each checked against that form.

use super::Compression;
use crate::codec::Subsampling;
use crate::error::Result;
use crate::layout::Level;
use crate::pixel::Channels;
use crate::source::stored::{self, Header, StoredLevels};

/// How every copied tile is coded: `None` grey, else RGB's coding.
pub(crate) type Coding = Option<Subsampling>;

/// How `coding` is named in messages.
pub(crate) fn coding_name(coding: Coding) -> String {
    match coding {
        None => "grey".into(),
        Some(Subsampling::Rgb) => "RGB".into(),
        Some(s) => format!("YCbCr {}", s.name()),
    }
}

/// Whether `h` is a tile of `coding` a TIFF JPEG level holds: 8-bit, Huffman-coded
/// sequential (SOF0 or SOF1), of the coding.
pub(crate) fn fits(h: &Header, coding: Coding) -> bool {
    let form = match coding {
        None => h.components == 1,
        Some(s) => h.subsampling() == Some(s),
    };
    matches!(h.frame, 0xC0 | 0xC1) && h.precision == 8 && form
}

/// The file's levels and their tiles' coding where it copies `levels` of a `channels` image,
/// or why it cannot (said in the summary; the file is then our pyramid). An error where a
/// level's first tile cannot be read.
pub(crate) fn copyable(
    levels: &StoredLevels,
    channels: Channels,
) -> Result<std::result::Result<(Vec<Level>, Coding), String>> {
    if let Some(why) = &levels.unlike {
        return Ok(Err(why.clone()));
    }
    if levels.levels.len() < 2 {
        return Ok(Err("the slide has no reduced levels".into()));
    }
    let mut out = Vec::with_capacity(levels.levels.len());
    let mut coding: Option<Coding> = None;
    for (k, level) in levels.levels.iter().enumerate() {
        let name = format!("level {k} (page {})", level.page);
        if level.tiles.coding() != stored::Coding::Jpeg {
            return Ok(Err(format!("{name}'s tiles are JPEG 2000: a TIFF copies JPEG tiles only")));
        }
        let tile = level.tiles.tile_size();
        let first = level.tiles.tile(0, 0).map_err(|e| stored::in_level(e, k, level.page))?;
        let Some(h) = first.as_deref().and_then(stored::read_header) else {
            return Ok(Err(format!("{name}'s first tile is no whole {}x{} JPEG", tile.0, tile.1)));
        };
        let this = match (channels, h.components) {
            (Channels::Grey, 1) => None,
            (Channels::Rgb, 3) => match h.subsampling() {
                Some(s) => Some(s),
                None => return Ok(Err(format!("{name}'s tiles are YCbCr sampled {:?}", h.sampling))),
            },
            (_, n) => return Ok(Err(format!("{name}'s tiles are JPEG of {n} components, the image {channels:?}"))),
        };
        if !fits(&h, this) {
            let sof = h.frame & 0x0F;
            return Ok(Err(format!("{name}'s tiles are {}-bit JPEG of SOF{sof}, not sequential 8-bit", h.precision)));
        }
        match coding {
            Some(c) if c != this => return Ok(Err(format!("{name}'s tiles are coded otherwise than level 0's"))),
            _ => coding = Some(this),
        }
        out.push(Level { width: level.width, height: level.height, tile });
    }
    Ok(Ok((out, coding.flatten())))
}

/// The `Compression` of JPEG tiles of `coding` (grey has no subsampling; any will do).
pub(crate) fn compression(coding: Coding) -> Compression {
    Compression::Jpeg { subsampling: coding.unwrap_or(Subsampling::S420) }
}
