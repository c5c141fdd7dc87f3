//! A slide's own levels as the series' instances (`--levels stored`, the default): every
//! stored tile of every level copied as a frame, nothing decoded: JPEG tiles with their tables
//! made complete as the source hands stored tiles out (`source::stored`), JPEG 2000
//! codestreams (Aperio's SVS tiles) as they are. DICOM allows any downsample factor between
//! the levels, and `TILED_FULL` frames are whole tiles that may reach past the Total Pixel
//! Matrix, as a TIFF's padded edge tiles do: so every tile is a frame as it is.
//!
//! [`copyable`] looks at each level's first tile before anything is written: baseline 8-bit
//! JPEG, or 8-bit JPEG 2000 of three unsubsampled components, and the photometric
//! interpretation its headers say, the same for every level; where one is not, the series is
//! our pyramid and the summary says why. [`copy_levels`] then copies every tile, each checked
//! against its level's first (a tile of another form, a truncated or unreadable one, is an
//! error naming the file, the level and the tile). In a JPEG XL series every JPEG tile is
//! recompressed losslessly on its way ([`Recompress`]): every instance JPEG XL JPEG
//! Recompression.

use super::{DicomSink, Level, Photometric, Transfer};
use crate::error::{Result, TilerError};
use crate::job::Progress;
use crate::source::stored::codestream::Codestream;
use crate::source::stored::{self, Coding, Header, StoredLevels};

/// Why `YBR_FULL` frames are not copied, after the name.
const NO_YBR_FULL: &str = ", which a VL Whole Slide Microscopy Image may not state: its Photometric Interpretation is MONOCHROME2, RGB, YBR_FULL_422, YBR_ICT or YBR_RCT";

/// How the frames of a slide's copied levels are stored, which every one of them must be.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Form {
    pub photometric: Photometric,
    /// JPEG baseline, or JPEG 2000: lossless only where every level's first codestream is of
    /// the reversible wavelet (and then every frame must be).
    pub transfer: Transfer,
}

/// What the instances hold where they copy `levels`: each level's image and frames, and how
/// every frame is stored; `Err(why)` where DICOM cannot hold the levels as stored (said in
/// the summary; the series is then our pyramid). An error where a level's first tile cannot
/// be read.
pub(crate) fn copyable(levels: &StoredLevels) -> Result<std::result::Result<(Vec<Level>, Form), String>> {
    if let Some(why) = &levels.unlike {
        return Ok(Err(why.clone()));
    }
    if levels.levels.len() < 2 {
        return Ok(Err("the slide has no reduced levels".into()));
    }
    let coding = levels.levels[0].tiles.coding();
    let mut out = Vec::with_capacity(levels.levels.len());
    let (mut photometric, mut reversible) = (None, true);
    for (k, level) in levels.levels.iter().enumerate() {
        let name = format!("level {k} (page {})", level.page);
        let frame = level.tiles.tile_size();
        if frame.0.max(frame.1) > u32::from(u16::MAX) {
            return Ok(Err(format!("{name}'s {}x{} tiles are larger than a DICOM frame", frame.0, frame.1)));
        }
        if level.tiles.coding() != coding {
            return Ok(Err(format!("{name}'s tiles are coded otherwise than level 0's")));
        }
        let first = level.tiles.tile(0, 0).map_err(|e| stored::in_level(e, k, level.page))?;
        let this = match first.as_deref().map(|first| frame_form(coding, first, frame)) {
            Some(Ok(this)) => this,
            Some(Err(why)) => return Ok(Err(format!("{name}'s tiles are {why}"))),
            None => return Ok(Err(format!("{name}'s first tile cannot be copied as it is"))),
        };
        match photometric {
            Some(p) if p != this.0 => {
                let (p, this) = (Photometric::name(p), this.0.name());
                return Ok(Err(format!("{name}'s tiles are {this}, level 0's {p}: a series states one")));
            }
            _ => photometric = Some(this.0),
        }
        reversible &= this.1;
        out.push(Level { width: level.width, height: level.height, tile: frame });
    }
    let photometric = photometric.ok_or_else(|| TilerError::Internal("a slide of no levels".into()))?;
    let transfer = match (coding, reversible) {
        (Coding::Jpeg, _) => Transfer::JpegBaseline,
        (Coding::Jpeg2000 { .. }, true) => Transfer::Jpeg2000Lossless,
        (Coding::Jpeg2000 { .. }, false) => Transfer::Jpeg2000,
    };
    Ok(Ok((out, Form { photometric, transfer })))
}

/// The photometric interpretation a stored tile of `coding` and `size` is as a frame, and
/// whether it is lossless (JPEG 2000's reversible wavelet; a JPEG never is), or why it is
/// none a frame may be.
fn frame_form(coding: Coding, tile: &[u8], size: (u32, u32)) -> std::result::Result<(Photometric, bool), String> {
    match coding {
        Coding::Jpeg => match stored::read_header(tile) {
            Some(h) => form(&h).map(|p| (p, false)),
            None => Err(format!("not {}x{} 8-bit Huffman-coded JPEG", size.0, size.1)),
        },
        Coding::Jpeg2000 { ycbcr } => jpeg_2000_form(&Codestream::read(tile)?, ycbcr, size),
    }
}

/// The photometric interpretation a JPEG frame of `header` is, as stored, or why it is none
/// a DICOM JPEG baseline frame may be: baseline (SOF0), 8-bit; one component MONOCHROME2;
/// three with an Adobe marker saying no transform, unsubsampled, RGB; else YCbCr,
/// `YBR_FULL_422` with the chroma halved across (4:2:2) or both ways (4:2:0). (Unsubsampled
/// YCbCr would be `YBR_FULL`, which a whole-slide image may not state: PS3.3 C.8.12.4.1.5.)
pub(super) fn form(h: &Header) -> std::result::Result<Photometric, String> {
    if h.frame != 0xC0 || h.precision != 8 {
        return Err(format!("{}-bit JPEG of SOF{}, not baseline (SOF0) 8-bit", h.precision, h.frame & 0x0F));
    }
    let plain = h.sampling[..] == [(1, 1), (1, 1), (1, 1)];
    let chroma = h.sampling.get(1..) == Some(&[(1, 1), (1, 1)][..]);
    match (h.components, h.adobe) {
        (1, _) => Ok(Photometric::Monochrome),
        (3, Some(0)) if plain => Ok(Photometric::Rgb),
        (3, Some(0)) => Err("RGB JPEG with subsampled components".into()),
        (3, _) if plain => Err(format!("YCbCr JPEG 4:4:4 (YBR_FULL{NO_YBR_FULL})")),
        (3, _) if chroma && matches!(h.sampling[0], (2, 2) | (2, 1)) => Ok(Photometric::YbrFull422),
        (3, _) => Err(format!("YCbCr JPEG sampled {:?}", h.sampling)),
        (n, _) => Err(format!("JPEG of {n} components")),
    }
}

/// The photometric interpretation a JPEG 2000 frame of codestream `c` is (PS3.5 8.2.4), and
/// whether it is of the reversible wavelet, or why it is none a frame may be: an image of the
/// tile's `size`, three unsigned 8-bit components at full resolution; through the
/// codestream's colour transform `YBR_RCT` (reversible) or `YBR_ICT` (irreversible), which a
/// decoder undoes; without it `RGB`. Y, Cb, Cr components without it (`ycbcr`, Aperio's 33003)
/// would be `YBR_FULL`, which a whole-slide image may not state.
fn jpeg_2000_form(c: &Codestream, ycbcr: bool, size: (u32, u32)) -> std::result::Result<(Photometric, bool), String> {
    if (c.width, c.height) != size {
        return Err(format!("{}x{} JPEG 2000 images in {}x{} tiles", c.width, c.height, size.0, size.1));
    }
    let plain = |p: &stored::codestream::Component| p.precision == 8 && !p.signed && (p.dx, p.dy) == (1, 1);
    if c.components.len() != 3 || !c.components.iter().all(plain) {
        let shown: Vec<String> = (c.components.iter())
            .map(|p| format!("{}{}-bit {}x{}", if p.signed { "signed " } else { "" }, p.precision, p.dx, p.dy))
            .collect();
        return Err(format!(
            "JPEG 2000 of components {}, not three unsigned 8-bit ones unsubsampled",
            shown.join(", ")
        ));
    }
    let coding = c.coding.ok_or("JPEG 2000 without a coding style (COD) in its main header")?;
    let photometric = match (coding.transform, ycbcr, coding.reversible) {
        (true, true, _) => {
            return Err(
                "Y, Cb, Cr components (Compression 33003) coded through the codestream's colour transform too".into()
            );
        }
        (true, false, true) => Photometric::YbrRct,
        (true, false, false) => Photometric::YbrIct,
        (false, true, _) => {
            return Err(format!(
                "JPEG 2000 of Y, Cb, Cr components without the codestream's colour transform (Compression 33003: YBR_FULL{NO_YBR_FULL})"
            ));
        }
        (false, false, _) => Photometric::Rgb,
    };
    Ok((photometric, coding.reversible))
}

/// Copies every tile of every level of `levels` into `sink` (a series whose spec's levels
/// [`copyable`] gave) as its frame, in row-major order; says how many. Each tile must be of
/// the series' `form` (a lossless-only series' JPEG 2000 frames of the reversible wavelet),
/// else the run fails naming the file, level and tile.
pub(crate) fn copy_levels(sink: &DicomSink, levels: &StoredLevels, form: Form, progress: &dyn Progress) -> Result<u64> {
    let coding = levels.levels.first().map_or(Coding::Jpeg, |l| l.tiles.coding());
    let lossless = form.transfer == Transfer::Jpeg2000Lossless;
    let fits = |tile: &[u8], size| {
        frame_form(coding, tile, size).is_ok_and(|(p, reversible)| p == form.photometric && (reversible || !lossless))
    };
    let name = match coding {
        Coding::Jpeg => format!("{} JPEG", form.photometric.name()),
        Coding::Jpeg2000 { .. } => format!("{} JPEG 2000", form.photometric.name()),
    };
    match sink.recompressing() {
        Some(effort) => {
            let recompress = Recompress { sink, path: &levels.path, effort };
            crate::formats::levels::copy(&recompress, levels, &name, &fits, progress)
        }
        None => crate::formats::levels::copy(sink, levels, &name, &fits, progress),
    }
}

/// A series of a slide's JPEG levels in JPEG XL frames (JPEG XL JPEG Recompression): each
/// stored tile copied is recompressed losslessly on its way into the sink (less any
/// quantisation table no component uses, as for every recompression: docs/jxl.md). A tile
/// libjxl cannot rebuild exactly fails the run naming it: no texels of it were decoded to
/// encode instead.
struct Recompress<'a> {
    sink: &'a DicomSink,
    path: &'a std::path::Path,
    effort: crate::codec::JxlEffort,
}

impl crate::sink::TileSink for Recompress<'_> {
    fn write_tile(&self, lod: u32, x: u32, y: u32, _bytes: &[u8]) -> Result<()> {
        Err(TilerError::Internal(format!("level {lod}'s tile ({x}, {y}) came encoded into a series of copied levels")))
    }

    fn write_stored(&self, lod: u32, x: u32, y: u32, jpeg: &[u8]) -> Result<()> {
        let used = stored::without_unused_tables(jpeg).unwrap_or(std::borrow::Cow::Borrowed(jpeg));
        match vortex_jxl::recompress_jpeg(&used, self.effort) {
            Ok(jxl) => self.sink.write_recompressed_copy(lod, (x, y), jpeg.len(), &jxl),
            Err(e @ vortex_jxl::Error::JpegRecompression { .. }) => Err(TilerError::unsupported(
                self.path,
                format!(
                    "level {lod}, the tile at column {x}, row {y}: libjxl cannot recompress this JPEG losslessly ({e}), and a slide's own levels are copied, not decoded: --levels pow2 encodes such tiles from their texels"
                ),
            )),
            Err(e) => Err(TilerError::Internal(format!("recompressing level {lod}'s tile ({x}, {y}): {e}"))),
        }
    }

    fn bytes_written(&self) -> u64 {
        self.sink.bytes_written()
    }
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
        assert!(form(&header(0xC0, 3, &[(1, 1); 3], None)).unwrap_err().contains("may not state"), "YBR_FULL");
        assert_eq!(form(&header(0xC0, 3, &[(1, 1); 3], Some(0))), Ok(Photometric::Rgb));
        assert_eq!(form(&header(0xC0, 1, &[(1, 1)], None)), Ok(Photometric::Monochrome));
        assert!(form(&header(0xC2, 3, &ybr, None)).unwrap_err().contains("not baseline"));
        assert!(form(&header(0xC0, 3, &ybr, Some(0))).is_err(), "subsampled RGB");
        assert!(form(&header(0xC0, 3, &[(1, 2), (1, 1), (1, 1)], None)).is_err(), "4:4:0");
    }

    /// A JPEG 2000 frame's photometric interpretation is its components' and colour
    /// transform's (PS3.5 8.2.4); what a frame cannot be is named.
    #[test]
    fn a_jpeg_2000_frame_s_form_is_read_from_its_main_header() {
        use crate::source::stored::codestream::{Coding as Cod, Component};
        let rgb = Component { precision: 8, signed: false, dx: 1, dy: 1 };
        let stream = |transform, reversible, components: Vec<Component>| Codestream {
            width: 240,
            height: 240,
            origin: (0, 0),
            components,
            coding: Some(Cod { reversible, transform }),
        };
        let form = |c: &Codestream, ycbcr| jpeg_2000_form(c, ycbcr, (240, 240));
        assert_eq!(form(&stream(true, true, vec![rgb; 3]), false), Ok((Photometric::YbrRct, true)));
        assert_eq!(form(&stream(true, false, vec![rgb; 3]), false), Ok((Photometric::YbrIct, false)));
        assert_eq!(form(&stream(false, true, vec![rgb; 3]), false), Ok((Photometric::Rgb, true)));
        assert!(form(&stream(false, false, vec![rgb; 3]), true).unwrap_err().contains("YBR_FULL, which"));
        assert!(form(&stream(true, true, vec![rgb; 3]), true).unwrap_err().contains("33003"));
        let half = Component { dx: 2, dy: 2, ..rgb };
        assert!(form(&stream(false, true, vec![rgb, half, half]), true).unwrap_err().contains("8-bit 2x2"));
        assert!(form(&stream(false, true, vec![rgb]), false).is_err(), "one component");
        let small = Codestream { width: 200, ..stream(false, true, vec![rgb; 3]) };
        assert!(form(&small, false).unwrap_err().contains("200x240 JPEG 2000 images in 240x240 tiles"));
        let uncoded = Codestream { coding: None, ..stream(false, true, vec![rgb; 3]) };
        assert!(form(&uncoded, false).unwrap_err().contains("COD"));
    }
}
