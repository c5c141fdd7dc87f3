//! A slide's own levels as the series' instances (`--levels stored`, the default): every
//! stored JPEG tile of every level copied as a frame, its tables made complete as the source
//! hands stored tiles out (`source::stored`), nothing decoded. DICOM allows any downsample
//! factor between the levels, and `TILED_FULL` frames are whole tiles that may reach past the
//! Total Pixel Matrix, as a TIFF's padded edge tiles do: so every tile is a frame as it is.
//!
//! [`copyable`] looks at each level's first tile before anything is written: baseline 8-bit
//! JPEG, and the photometric interpretation its SOF and Adobe marker say, the same for every
//! level; where one is not, the series is our pyramid and the summary says why. [`copy_levels`]
//! then copies every tile, each checked against its level's first (a tile of another form, a
//! truncated or unreadable one, is an error naming the file, the level and the tile).

use super::{DicomSink, Level, Photometric};
use crate::error::{Result, TilerError};
use crate::job::Progress;
use crate::source::stored::{self, Header, StoredLevels};

/// What the instances hold where they copy `levels`: each level's image and frames, and the
/// photometric interpretation of every frame; `Err(why)` where DICOM cannot hold the levels
/// as stored (said in the summary; the series is then our pyramid). An error where a level's
/// first tile cannot be read.
pub(crate) fn copyable(levels: &StoredLevels) -> Result<std::result::Result<(Vec<Level>, Photometric), String>> {
    if let Some(why) = &levels.unlike {
        return Ok(Err(why.clone()));
    }
    if levels.levels.len() < 2 {
        return Ok(Err("the slide has no reduced levels".into()));
    }
    let mut out = Vec::with_capacity(levels.levels.len());
    let mut photometric = None;
    for (k, level) in levels.levels.iter().enumerate() {
        let name = format!("level {k} (page {})", level.page);
        let frame = level.tiles.tile_size();
        if frame.0.max(frame.1) > u32::from(u16::MAX) {
            return Ok(Err(format!("{name}'s {}x{} tiles are larger than a DICOM frame", frame.0, frame.1)));
        }
        let first = level.tiles.jpeg(0, 0).map_err(|e| stored::in_level(e, k, level.page))?;
        let Some(first) = first.as_deref().and_then(stored::read_header) else {
            return Ok(Err(format!("{name}'s first tile is not a {}x{} 8-bit Huffman-coded JPEG", frame.0, frame.1)));
        };
        let this = match form(&first) {
            Ok(p) => p,
            Err(why) => return Ok(Err(format!("{name}'s tiles are {why}"))),
        };
        match photometric {
            Some(p) if p != this => {
                let (p, this) = (Photometric::name(p), this.name());
                return Ok(Err(format!("{name}'s tiles are {this}, level 0's {p}: a series states one")));
            }
            _ => photometric = Some(this),
        }
        out.push(Level { width: level.width, height: level.height, tile: frame });
    }
    let photometric = photometric.ok_or_else(|| TilerError::Internal("a slide of no levels".into()))?;
    Ok(Ok((out, photometric)))
}

/// The photometric interpretation a JPEG frame of `header` is, as stored, or why it is none
/// a DICOM JPEG baseline frame may be: baseline (SOF0), 8-bit; one component MONOCHROME2;
/// three with an Adobe marker saying no transform, unsubsampled, RGB; else YCbCr, `YBR_FULL`
/// unsubsampled, `YBR_FULL_422` with the chroma halved across (4:2:2) or both ways (4:2:0).
fn form(h: &Header) -> std::result::Result<Photometric, String> {
    if h.frame != 0xC0 || h.precision != 8 {
        return Err(format!("{}-bit JPEG of SOF{}, not baseline (SOF0) 8-bit", h.precision, h.frame & 0x0F));
    }
    let plain = h.sampling[..] == [(1, 1), (1, 1), (1, 1)];
    let chroma = h.sampling.get(1..) == Some(&[(1, 1), (1, 1)][..]);
    match (h.components, h.adobe) {
        (1, _) => Ok(Photometric::Monochrome),
        (3, Some(0)) if plain => Ok(Photometric::Rgb),
        (3, Some(0)) => Err("RGB JPEG with subsampled components".into()),
        (3, _) if plain => Ok(Photometric::YbrFull),
        (3, _) if chroma && matches!(h.sampling[0], (2, 2) | (2, 1)) => Ok(Photometric::YbrFull422),
        (3, _) => Err(format!("YCbCr JPEG sampled {:?}", h.sampling)),
        (n, _) => Err(format!("JPEG of {n} components")),
    }
}

/// Copies every tile of every level of `levels` into `sink` (a series whose spec's levels
/// [`copyable`] gave) as its frame, in row-major order; says how many. Each tile must be of
/// its level's form (`photometric`), else the run fails naming the file, level and tile.
pub(crate) fn copy_levels(
    sink: &DicomSink,
    levels: &StoredLevels,
    photometric: Photometric,
    progress: &dyn Progress,
) -> Result<u64> {
    let fits = |h: &Header| form(h) == Ok(photometric);
    crate::formats::levels::copy(sink, levels, photometric.name(), &fits, progress)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn header(frame: u8, components: u8, sampling: &[(u8, u8)], adobe: Option<u8>) -> Header {
        Header {
            frame,
            precision: 8,
            width: 256,
            height: 256,
            components,
            sampling: sampling.to_vec(),
            adobe,
            ..Header::default()
        }
    }

    /// The photometric interpretation comes from the JPEG's own SOF and Adobe marker.
    #[test]
    fn a_frame_s_form_is_read_from_its_header() {
        let ybr = [(2, 2), (1, 1), (1, 1)];
        assert_eq!(form(&header(0xC0, 3, &ybr, None)), Ok(Photometric::YbrFull422));
        assert_eq!(form(&header(0xC0, 3, &[(2, 1), (1, 1), (1, 1)], Some(1))), Ok(Photometric::YbrFull422));
        assert_eq!(form(&header(0xC0, 3, &[(1, 1); 3], None)), Ok(Photometric::YbrFull));
        assert_eq!(form(&header(0xC0, 3, &[(1, 1); 3], Some(0))), Ok(Photometric::Rgb));
        assert_eq!(form(&header(0xC0, 1, &[(1, 1)], None)), Ok(Photometric::Monochrome));
        assert!(form(&header(0xC2, 3, &ybr, None)).unwrap_err().contains("not baseline"));
        assert!(form(&header(0xC0, 3, &ybr, Some(0))).is_err(), "subsampled RGB");
        assert!(form(&header(0xC0, 3, &[(1, 2), (1, 1), (1, 1)], None)).is_err(), "4:4:0");
    }
}
