//! A source's tiles as it stores them, for a run to copy into its output instead of decoding
//! them and encoding them again (issue 30, "copy instead of re-encode").
//!
//! A slide scanner's JPEG tiles already are what a viewer's JPEG tile is. Where the output's
//! finest pages line up with them one for one, [`StoredTiles::jpeg`] hands tile (x, y) over as a
//! complete JPEG file: the stored bytes as they are, the TIFF's shared tables spliced in, and a
//! marker that tells every decoder the colour space the TIFF declares. The run still decodes
//! every tile, for the coarser levels; what it saves is the finest level's encoding (three
//! quarters of the tiles) and that level's generation loss: a viewer decodes the scanner's
//! pixels, bit for bit.
//!
//! The source reads a tile's bytes again when the encoder asks for them (one positioned read,
//! from the page cache: they were read moments before to be decoded) rather than carry them
//! through the read-ahead, the pyramid and its stripes and rewinds beside the decoded rows.

pub mod codestream;
pub mod crop;

use std::path::PathBuf;
use std::sync::Arc;

/// How a grid's tiles are coded as stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Coding {
    /// JPEG files: what a viewer's tile is, and what every output that copies tiles takes.
    Jpeg,
    /// JPEG 2000 codestreams, as Aperio stores its SVS tiles: a DICOM series' levels copy them
    /// (`--levels stored`). `ycbcr`: their three components are Y, Cb, Cr without the
    /// codestream's own colour transform (Compression 33003), else R, G, B or that transform's.
    Jpeg2000 { ycbcr: bool },
}

/// What a run may copy: a grid of tiles stored as JPEG (every grid a source offers for its
/// full resolution alone, `RowSource::stored_tiles`) or, among a slide's levels, JPEG 2000.
pub trait StoredTiles: Send + Sync {
    /// Texels of a stored tile across and down.
    fn tile_size(&self) -> (u32, u32);
    /// The quality the tiles were stored at, from their quantisation tables.
    fn quality(&self) -> Option<Quality>;
    /// How the tiles are coded.
    fn coding(&self) -> Coding {
        Coding::Jpeg
    }
    /// Tile (`col`, `row`) of the grid as stored: a complete JPEG file, or a JPEG 2000
    /// codestream as [`coding`](Self::coding) says; `None` where it cannot be copied as it is
    /// (a stream that is not a whole tile, or that a browser cannot decode): that tile is
    /// encoded instead. An error names the file and the tile.
    fn tile(&self, col: u32, row: u32) -> crate::error::Result<Option<Vec<u8>>>;
    /// Tile (`col`, `row`)'s texels inside the image, as the source's rows hold them (8-bit
    /// grey or RGB), decoded at 1/`denominator` of its size (1 or 2: `--fast-shrink`'s half
    /// size, from the DCT coefficients): `ceil(w / d)` x `ceil(h / d)` texels, rows packed.
    /// `None` for grids that cannot (the default). An error names the file and the tile.
    fn decode(&self, _col: u32, _row: u32, _denominator: u32) -> crate::error::Result<Option<Vec<u8>>> {
        Ok(None)
    }
    /// Whether [`decode`](Self::decode) decodes this grid's tiles.
    fn decodes(&self) -> bool {
        false
    }
    /// How the tiles code colour, as the first one does (`None`: grey, unreadable or coded
    /// otherwise): a TIFF or DICOM output, which declares one coding for every tile, takes it
    /// where `--subsampling` is not given, so that the tiles can be copied.
    fn subsampling(&self) -> Option<crate::codec::Subsampling> {
        self.tile(0, 0).ok().flatten().and_then(|file| read_header(&file)).and_then(|h| h.subsampling())
    }
}

/// A slide's levels as it stores them: the full resolution and its reduced copies, largest
/// first, each a grid of JPEG (or JPEG 2000) tiles, for an output that keeps every level as it is (a DICOM
/// series, `--levels stored`: docs/dicom.md).
#[derive(Clone)]
pub struct StoredLevels {
    /// The file they are in, for messages.
    pub path: PathBuf,
    pub levels: Vec<StoredLevel>,
    /// Why the levels stop where they do, where a later reduced level is no grid of tiles
    /// coded as the first level's are (in strips, another compression): then they cannot all
    /// be copied.
    pub unlike: Option<String>,
}

/// One level of [`StoredLevels`].
#[derive(Clone)]
pub struct StoredLevel {
    pub width: u32,
    pub height: u32,
    /// The file's directory that holds it, counted from 0 (`--page`'s count).
    pub page: usize,
    /// Its tiles, every one of them (the right and bottom ones padded as stored).
    pub tiles: Arc<dyn StoredTiles>,
}

/// An error of level `k` (in page `page`) of [`StoredLevels`], naming the level.
pub(crate) fn in_level(e: crate::error::TilerError, k: usize, page: usize) -> crate::error::TilerError {
    use crate::error::TilerError;
    let name = |message: String| format!("level {k} (page {page}): {message}");
    match e {
        TilerError::Decode { path, message } => TilerError::Decode { path, message: name(message) },
        TilerError::Unsupported { path, message } => TilerError::Unsupported { path, message: name(message) },
        other => other,
    }
}

/// A JPEG quality estimated from a luminance quantisation table.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Quality {
    /// The IJG quality (1-100) whose scaled standard table is nearest the stored one.
    pub estimate: u8,
    /// Whether the stored table is exactly libjpeg's at that quality (libjpeg, libtiff,
    /// libvips, tifffile and most scanners use them); else it is the nearest, by the sum of
    /// absolute differences.
    pub exact: bool,
}

impl std::fmt::Display for Quality {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.exact {
            true => write!(f, "Q{}", self.estimate),
            false => write!(f, "about Q{} (not libjpeg's tables)", self.estimate),
        }
    }
}

/// libjpeg's standard luminance table (ITU T.81 Annex K), in natural (row-major) order.
const STD_LUMINANCE: [u16; 64] = [
    16, 11, 10, 16, 24, 40, 51, 61, 12, 12, 14, 19, 26, 58, 60, 55, 14, 13, 16, 24, 40, 57, 69, 56, 14, 17, 22, 29, 51,
    87, 80, 62, 18, 22, 37, 56, 68, 109, 103, 77, 24, 35, 55, 64, 81, 104, 113, 92, 49, 64, 78, 87, 103, 121, 120, 101,
    72, 92, 95, 98, 112, 100, 103, 99,
];

/// The natural-order index of each zigzag position: a DQT segment lists its values in zigzag order.
const ZIGZAG: [usize; 64] = [
    0, 1, 8, 16, 9, 2, 3, 10, 17, 24, 32, 25, 18, 11, 4, 5, 12, 19, 26, 33, 40, 48, 41, 34, 27, 20, 13, 6, 7, 14, 21,
    28, 35, 42, 49, 56, 57, 50, 43, 36, 29, 22, 15, 23, 30, 37, 44, 51, 58, 59, 52, 45, 38, 31, 39, 46, 53, 60, 61, 54,
    47, 55, 62, 63,
];

/// The quality whose libjpeg luminance table (`jpeg_set_quality`: the standard table scaled by
/// 5000/Q below 50 and 200-2Q above, rounded, clamped to 1..=255) is nearest `table` (natural
/// order). Exact for what libjpeg made; the nearest for other encoders' tables.
pub fn estimate_quality(table: &[u16; 64]) -> Quality {
    let distance = |q: u32| -> u32 {
        let scale = if q < 50 { 5000 / q } else { 200 - 2 * q };
        let scaled = |v: u16| ((v as u32 * scale + 50) / 100).clamp(1, 255);
        STD_LUMINANCE.iter().zip(table).map(|(&s, &t)| scaled(s).abs_diff(t as u32)).sum()
    };
    // Of qualities that give the same table (near 100, where every value is 1 or 2), the highest.
    let (q, d) = (1..=100).map(|q| (q, distance(q))).min_by_key(|&(q, d)| (d, std::cmp::Reverse(q))).unwrap_or((0, 1));
    Quality { estimate: q as u8, exact: d == 0 }
}

/// What the header of a JPEG stream (its segments before the first scan) says.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Header {
    /// The SOF marker's second byte (0xC0 baseline, 0xC1 extended, 0xC2 progressive, ...).
    pub frame: u8,
    pub precision: u8,
    pub width: u16,
    pub height: u16,
    pub components: u8,
    /// Each component's horizontal and vertical sampling factors, as the frame lists them.
    pub sampling: Vec<(u8, u8)>,
    /// Table 0, the luminance table by convention, in natural order.
    pub luma_table: Option<[u16; 64]>,
    pub jfif: bool,
    /// An Adobe APP14 marker's transform (0: RGB or CMYK as is, 1: YCbCr, 2: YCCK).
    pub adobe: Option<u8>,
}

impl Header {
    /// How a three-component stream codes colour: RGB where an Adobe marker says it is not
    /// transformed (every component at full resolution), else YCbCr at 4:2:0 or 4:4:4; `None`
    /// for grey, CMYK or another sampling (4:2:2, 4:1:1).
    pub fn subsampling(&self) -> Option<crate::codec::Subsampling> {
        use crate::codec::Subsampling;
        if self.components != 3 {
            return None;
        }
        let full = self.sampling[..] == [(1, 1); 3];
        match self.adobe {
            Some(0) => full.then_some(Subsampling::Rgb),
            _ if full => Some(Subsampling::S444),
            _ => (self.sampling[..] == [(2, 2), (1, 1), (1, 1)]).then_some(Subsampling::S420),
        }
    }
}

/// A JPEG marker segment: its marker, and its bytes' range in the stream.
type Segment = (u8, std::ops::Range<usize>);

/// The marker segments of `stream` (SOI, then segments) before its first SOS or EOI, each
/// its marker and its bytes' range in `stream` (the marker and length included), and where
/// the scan (or the end) starts. `None` for data that is not such a stream. The one walker of
/// a JPEG's header: [`read_header`] reads it, [`split_tables`] cuts the tables out of it.
fn segments(stream: &[u8]) -> Option<(Vec<Segment>, usize)> {
    if !stream.starts_with(&[0xFF, 0xD8]) {
        return None;
    }
    let (mut out, mut at) = (Vec::new(), 2);
    while at + 4 <= stream.len() {
        if stream[at] != 0xFF {
            return None;
        }
        let marker = stream[at + 1];
        if marker == 0xFF {
            at += 1; // fill byte
            continue;
        }
        if marker == 0xD9 || marker == 0xDA {
            break;
        }
        let len = u16::from_be_bytes([stream[at + 2], stream[at + 3]]) as usize;
        let end = (at + 2).checked_add(len).filter(|&end| end <= stream.len() && len >= 2)?;
        out.push((marker, at..end));
        at = end;
    }
    Some((out, at.min(stream.len())))
}

/// Reads the segments of `stream` (SOI, then marker segments) up to its first SOS, or its end
/// (a JPEGTables stream has no scan). `None` for data that is not such a stream.
pub fn read_header(stream: &[u8]) -> Option<Header> {
    let mut header = Header::default();
    for (marker, range) in segments(stream)?.0 {
        let body = &stream[range.start + 4..range.end];
        match marker {
            _ if is_frame(marker) => {
                let [precision, h0, h1, w0, w1, components, ..] = *body else { return None };
                header.frame = marker;
                header.precision = precision;
                header.height = u16::from_be_bytes([h0, h1]);
                header.width = u16::from_be_bytes([w0, w1]);
                header.components = components;
                // Three bytes a component: its id, its sampling factors (high nibble across), its table.
                let specs = body.get(6..6 + 3 * components as usize)?;
                header.sampling = specs.chunks_exact(3).map(|c| (c[1] >> 4, c[1] & 0x0F)).collect();
            }
            0xDB => read_dqt(body, &mut header)?,
            0xE0 => header.jfif |= body.starts_with(b"JFIF\0"),
            0xEE if body.starts_with(b"Adobe") && body.len() >= 12 => header.adobe = Some(body[11]),
            _ => {}
        }
    }
    Some(header)
}

/// `stream` cut in two: its quantisation and Huffman tables (its DQT and DHT segments, as they
/// are, in order) and the stream without them (an abbreviated stream, which a TIFF's shared
/// `JPEGTables` completes). `None` for data that is no JPEG stream.
pub fn split_tables(stream: &[u8]) -> Option<(Vec<u8>, Vec<u8>)> {
    let (segments, scan) = segments(stream)?;
    let (mut tables, mut rest) = (Vec::new(), Vec::with_capacity(stream.len()));
    rest.extend_from_slice(&stream[..2]);
    for (marker, range) in segments {
        let to = if matches!(marker, 0xDB | 0xC4) { &mut tables } else { &mut rest };
        to.extend_from_slice(&stream[range]);
    }
    rest.extend_from_slice(&stream[scan..]);
    Some((tables, rest))
}

/// `stream` without the quantisation tables that no component of its frame uses, a DQT
/// segment left with none dropped: the same pixels, the same entropy-coded data. An RGB tile
/// completed by a TIFF's shared `JPEGTables` (as Aperio and libvips write them) carries the
/// chroma table its components never use, which libjxl 0.7 will not recompress ("Non-trivial
/// unused quant table"). Borrowed where every table is used; `None` for data that is no JPEG
/// stream or has no frame header.
pub fn without_unused_tables(stream: &[u8]) -> Option<std::borrow::Cow<'_, [u8]>> {
    use std::borrow::Cow;
    let (segments, scan) = segments(stream)?;
    let body = |range: &std::ops::Range<usize>| &stream[range.start + 4..range.end];
    let frame = segments.iter().find(|(marker, _)| is_frame(*marker)).map(|(_, range)| body(range))?;
    let components = *frame.get(5)? as usize;
    // Three bytes a component: its id, its sampling factors, its table.
    let used: Vec<u8> = frame.get(6..6 + 3 * components)?.chunks_exact(3).map(|c| c[2]).collect();
    let mut out = Vec::with_capacity(stream.len());
    out.extend_from_slice(&stream[..2]);
    for (marker, range) in &segments {
        if *marker != 0xDB {
            out.extend_from_slice(&stream[range.clone()]);
            continue;
        }
        let (mut tables, mut kept) = (body(range), Vec::new());
        while let [pq_tq, ..] = *tables {
            let size = 1 + if pq_tq >> 4 == 1 { 128 } else { 64 };
            let table = tables.get(..size)?;
            if used.contains(&(pq_tq & 0x0F)) {
                kept.extend_from_slice(table);
            }
            tables = &tables[size..];
        }
        if !kept.is_empty() {
            out.extend_from_slice(&[0xFF, 0xDB]);
            out.extend_from_slice(&u16::try_from(kept.len() + 2).ok()?.to_be_bytes());
            out.extend_from_slice(&kept);
        }
    }
    out.extend_from_slice(&stream[scan..]);
    Some(if out.len() == stream.len() { Cow::Borrowed(stream) } else { Cow::Owned(out) })
}

/// Whether `marker` starts a frame (SOF0 to SOF15; C4, C8 and CC are other segments).
fn is_frame(marker: u8) -> bool {
    (0xC0..=0xCF).contains(&marker) && !matches!(marker, 0xC4 | 0xC8 | 0xCC)
}

/// The tables of one DQT segment; table 0 is kept.
fn read_dqt(mut body: &[u8], header: &mut Header) -> Option<()> {
    while let [pq_tq, rest @ ..] = body {
        let wide = pq_tq >> 4 == 1;
        let size = if wide { 128 } else { 64 };
        let values = rest.get(..size)?;
        if pq_tq & 0x0F == 0 {
            let mut table = [0u16; 64];
            for (k, &natural) in ZIGZAG.iter().enumerate() {
                table[natural] =
                    if wide { u16::from_be_bytes([values[2 * k], values[2 * k + 1]]) } else { values[k] as u16 };
            }
            header.luma_table = Some(table);
        }
        body = &rest[size..];
    }
    Some(())
}

/// What a stored tile's samples are, as the file around it (a TIFF's photometric
/// interpretation) declares.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Samples {
    Grey,
    YCbCr,
    Rgb,
}

/// A stored tile's complete stream (`stream`: tables spliced in) as a JPEG file any decoder
/// reads as the TIFF declares it: a JFIF APP0 marker after SOI for YCbCr and grey, an Adobe
/// APP14 marker with transform 0 for RGB (without one, decoders take three components for
/// YCbCr unless their ids are 'R', 'G', 'B'; libtiff's streams have neither marker). `None`
/// where the stream cannot be copied as a `width x height` tile: another size or component
/// count, not 8-bit Huffman-coded (browsers decode no arithmetic coding), or a marker already
/// there that says another colour space.
pub fn as_file(stream: &[u8], samples: Samples, (width, height): (u32, u32)) -> Option<Vec<u8>> {
    let header = read_header(stream)?;
    let components = if samples == Samples::Grey { 1 } else { 3 };
    let huffman = matches!(header.frame, 0xC0..=0xC2);
    if !huffman
        || header.precision != 8
        || (header.width as u32, header.height as u32) != (width, height)
        || header.components != components
    {
        return None;
    }
    let marker: &[u8] = match (samples, header.jfif, header.adobe) {
        (Samples::Rgb, false, Some(0)) | (Samples::YCbCr | Samples::Grey, true, None) => &[],
        (Samples::YCbCr, false, Some(1)) | (Samples::Grey, false, Some(0)) => &[],
        (Samples::Rgb, false, None) => &ADOBE_RGB,
        (Samples::YCbCr | Samples::Grey, false, None) => &JFIF,
        _ => return None,
    };
    let mut file = Vec::with_capacity(stream.len() + marker.len());
    file.extend_from_slice(&stream[..2]);
    file.extend_from_slice(marker);
    file.extend_from_slice(&stream[2..]);
    Some(file)
}

/// JFIF 1.01 APP0, no thumbnail, aspect 1:1: what libjpeg writes.
const JFIF: [u8; 18] = [0xFF, 0xE0, 0, 16, b'J', b'F', b'I', b'F', 0, 1, 1, 0, 0, 1, 0, 1, 0, 0];

/// Adobe APP14, version 100, flags 0, transform 0 (the components are R, G, B as they are).
const ADOBE_RGB: [u8; 16] = [0xFF, 0xEE, 0, 14, b'A', b'd', b'o', b'b', b'e', 0, 100, 0, 0, 0, 0, 0];

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codec::{Codec, Subsampling, TileEncoder};
    use crate::pixel::{Channels, Depth, PixelLayout};

    /// A JPEG cut into its tables and the rest: the tables are its DQT and DHT segments, the
    /// rest holds none and no scan byte is lost; the tables spliced back after SOI decode to
    /// the same texels as the whole stream.
    #[test]
    fn a_jpeg_s_tables_are_cut_out_and_put_back() {
        let texels: Vec<u8> = (0..32 * 16 * 3).map(|i| (i * 7 % 251) as u8).collect();
        let jpeg =
            crate::codec::encode_jpeg(&texels, (32, 16), Channels::Rgb, 80, Subsampling::S420, Vec::new()).unwrap();
        let (tables, rest) = split_tables(&jpeg).unwrap();
        let markers = |stream: &[u8]| -> Vec<u8> { segments(stream).unwrap().0.iter().map(|s| s.0).collect() };
        let in_tables: Vec<u8> = markers(&[&[0xFF, 0xD8], &tables[..]].concat());
        assert!(in_tables.contains(&0xDB) && in_tables.contains(&0xC4), "{in_tables:x?}");
        assert!(in_tables.iter().all(|m| matches!(m, 0xDB | 0xC4)), "{in_tables:x?}");
        assert!(!markers(&rest).iter().any(|m| matches!(m, 0xDB | 0xC4)));
        assert_eq!(tables.len() + rest.len(), jpeg.len());
        assert_eq!(read_header(&rest).unwrap().luma_table, None, "no DQT left");
        let whole = [&rest[..2], &tables[..], &rest[2..]].concat();
        let decode = |bytes: &[u8]| image::load_from_memory(bytes).unwrap().to_rgb8().into_raw();
        assert_eq!(decode(&whole), decode(&jpeg));
        assert_eq!(split_tables(b"not a jpeg"), None);
    }

    /// A table no component uses goes, alone in its DQT segment or beside a used one; the
    /// rest of the stream stays byte for byte, and a stream of used tables is not copied.
    #[test]
    fn unused_quantisation_tables_are_dropped_and_nothing_else() {
        let texels: Vec<u8> = (0..16 * 16 * 3).map(|i| (i * 5 % 251) as u8).collect();
        // RGB: all three components quantised by table 0.
        let rgb =
            crate::codec::encode_jpeg(&texels, (16, 16), Channels::Rgb, 85, Subsampling::Rgb, Vec::new()).unwrap();
        let dqt = segments(&rgb).unwrap().0.into_iter().find(|s| s.0 == 0xDB).unwrap().1;
        assert_eq!(rgb[dqt.start + 4], 0, "table 0 alone");
        let unused = [&[1u8][..], &[9u8; 64]].concat();
        let alone = [&rgb[..2], &[0xFF, 0xDB, 0, 67], &unused[..], &rgb[2..]].concat();
        let body = [&rgb[dqt.start + 4..dqt.end], &unused[..]].concat();
        let len = (body.len() as u16 + 2).to_be_bytes();
        let beside = [&rgb[..dqt.start], &[0xFF, 0xDB, len[0], len[1]], &body[..], &rgb[dqt.end..]].concat();
        for stream in [&alone, &beside] {
            assert!(without_unused_tables(stream).unwrap()[..] == rgb[..]);
        }
        assert!(matches!(without_unused_tables(&rgb), Some(std::borrow::Cow::Borrowed(_))));
        // 4:2:0 YCbCr uses both of its tables.
        let ycc =
            crate::codec::encode_jpeg(&texels, (16, 16), Channels::Rgb, 85, Subsampling::S420, Vec::new()).unwrap();
        assert!(matches!(without_unused_tables(&ycc), Some(std::borrow::Cow::Borrowed(_))));
        assert_eq!(without_unused_tables(b"not a jpeg"), None);
    }

    /// Each coding is what the stream's frame and Adobe marker say, as a TIFF's or DICOM's
    /// tags must declare it; grey has none.
    #[test]
    fn a_jpeg_is_coded_as_its_subsampling_says() {
        let rgb = PixelLayout::new(Channels::Rgb, Depth::U8);
        let texels: Vec<u8> = (0..16 * 16 * 3).map(|i| (i * 7 % 251) as u8).collect();
        for subsampling in Subsampling::ALL {
            let encoder = TileEncoder::new(Codec::Jpeg { quality: 90, subsampling }, rgb, false, None, 16, Vec::new());
            let mut out = Vec::new();
            encoder.unwrap().encode(&texels, &mut out).unwrap();
            let header = read_header(&out).unwrap();
            assert_eq!(header.subsampling(), Some(subsampling), "{header:?}");
        }
        let grey = PixelLayout::new(Channels::Grey, Depth::U8);
        let codec = Codec::Jpeg { quality: 90, subsampling: Subsampling::Rgb };
        let mut out = Vec::new();
        TileEncoder::new(codec, grey, false, None, 16, Vec::new()).unwrap().encode(&texels[..256], &mut out).unwrap();
        assert_eq!(read_header(&out).unwrap().subsampling(), None);
    }

    /// libjpeg's table for `q`, as jpeg_set_quality makes it.
    fn ijg(q: u32) -> [u16; 64] {
        let scale = if q < 50 { 5000 / q } else { 200 - 2 * q };
        STD_LUMINANCE.map(|v| ((v as u32 * scale + 50) / 100).clamp(1, 255) as u16)
    }

    #[test]
    fn libjpeg_tables_give_their_quality_back() {
        for q in [10, 50, 75, 85, 90, 95] {
            assert_eq!(estimate_quality(&ijg(q)), Quality { estimate: q as u8, exact: true });
        }
        let mut other = ijg(90);
        other[5] += 3;
        assert_eq!(estimate_quality(&other), Quality { estimate: 90, exact: false });
    }

    #[test]
    fn a_dqt_segment_is_read_in_zigzag_order() {
        let table = ijg(80);
        let mut dqt = vec![0xFF, 0xD8, 0xFF, 0xDB, 0, 67, 0];
        dqt.extend(ZIGZAG.iter().map(|&n| table[n] as u8));
        assert_eq!(read_header(&dqt).unwrap().luma_table, Some(table));
        assert!(read_header(&dqt[..dqt.len() - 1]).is_none(), "a segment past the end");
    }
}
