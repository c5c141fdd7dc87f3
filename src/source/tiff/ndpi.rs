//! A JPEG TIFF held in one strip whose JPEG is cut by restart markers, as Hamamatsu NDPI keeps
//! each level of a slide: one baseline JPEG tens of thousands of texels wide, its restart
//! interval (DRI) a run of MCUs within one MCU row. Decoding it whole would hold gigabytes;
//! OpenSlide decodes each restart interval as a small JPEG of its own, and so does this.
//!
//! The strip is read once, front to back: the entropy-coded data of a band of MCU rows is
//! split at its restart markers (checked to come in order, RST0..RST7 and round again), and
//! each interval is decoded by libjpeg-turbo as a JPEG of one interval's size: the stream's
//! header with its frame size rewritten to `interval width x MCU height`, the interval's data
//! and an EOI. Those decode independently (a restart resets the DC predictions), in parallel on
//! the rayon pool. Memory: one band of decoded texels and its compressed bytes, checked against
//! `--max-memory` before anything is allocated.
//!
//! Like OpenSlide, the frame's size is not trusted where the TIFF's is beyond what the JPEG
//! header can hold: over 65535 texels NDPI writes 0 or the tile size there, and the TIFF's
//! ImageWidth and ImageLength say the size. The colour is what the stream's markers say (JFIF:
//! YCbCr; Adobe transform 0 or components named R, G, B: RGB), as libjpeg and OpenSlide read
//! it, since NDPI's JPEG carries its own markers.

use std::fs::File;
use std::io::{BufRead, BufReader, Seek, SeekFrom};
use std::ops::Range;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};

use rayon::prelude::*;
use tiff::decoder::{ChunkType, Decoder};
use tiff::tags::Tag;

use super::jpeg::copy_row;
use super::libjpeg::{self, Colour, Extent};
use super::ndpi_dir::Directory;
use super::open_error;
use crate::error::{Result, TilerError};
use crate::pixel::{Channels, Depth, PixelLayout};
use crate::source::{ImageHeader, RowSource};

/// Hamamatsu's private tag, present in NDPI files.
const NDPI_FORMAT_FLAG: u16 = 65420;
/// Marker segments before the scan held at most (APPn, COM, tables): real headers are a few KiB.
const MAX_HEADER: usize = 1 << 20;
/// An interval's compressed bytes may be this many times its decoded texels (plus a little):
/// baseline JPEG of noise at quality 100 stays under twice; more is a missing marker.
const MAX_EXPANSION: usize = 4;

/// What the header before the scan says.
struct Header {
    /// SOI to the end of SOS, the frame's size rewritten to one interval's (by `open`).
    bytes: Vec<u8>,
    /// Where the frame header (SOF0 or SOF1) starts in `bytes`.
    sof_at: usize,
    /// Where the entropy-coded data starts, from the start of the strip.
    data_start: u64,
    colour: Colour,
    /// MCUs in one restart interval (DRI).
    interval: u32,
    mcu_w: u32,
    mcu_h: u32,
    /// The frame's size as stored (0 where NDPI leaves it for a size beyond 65535).
    declared: (u32, u32),
}

pub(super) struct Ndpi {
    path: PathBuf,
    width: u32,
    height: u32,
    header: Header,
    /// Texels across one interval (the last of a row may reach past the image).
    interval_w: u32,
    /// Intervals in one MCU row.
    across: u32,
    /// MCU rows in a band.
    group: u32,
    scanner: Scanner,
    /// The band's intervals, `[MCU row in band * across + interval]`: compressed, and decoded
    /// (texels inside the image only; left empty outside the columns read).
    compressed: Vec<Vec<u8>>,
    decoded: Vec<Vec<u8>>,
    /// Whether `decoded` holds the current columns of the band.
    fresh: bool,
    /// First MCU row of the band held, and how many.
    band_first: u32,
    band_rows: u32,
    /// Compressed bytes a band may hold.
    band_limit: usize,
    columns: Option<Range<u32>>,
    next: u64,
    failed: bool,
    label: String,
    /// How the intervals are found, for the summary line.
    located: String,
    embedded: crate::source::Embedded,
}

/// Opens the current image by restart interval if it is a JPEG in one strip with restart
/// markers in a single interleaved baseline scan; `None` leaves it to the JPEG TIFF reader.
pub(super) fn open(
    path: &Path,
    decoder: &mut Decoder<BufReader<File>>,
    label: &str,
    embedded: &crate::source::Embedded,
    max_memory: u64,
    page: usize,
) -> Result<Option<Box<dyn RowSource>>> {
    let tag_err = |e| open_error(path, e);
    let (width, height) = decoder.dimensions().map_err(tag_err)?;
    if decoder.get_chunk_type() != ChunkType::Strip || width == 0 || height == 0 {
        return Ok(None);
    }
    let offsets = decoder.get_tag_u64_vec(Tag::StripOffsets).map_err(tag_err)?;
    let counts = decoder.get_tag_u64_vec(Tag::StripByteCounts).map_err(tag_err)?;
    let (&[offset], &[count]) = (&offsets[..], &counts[..]) else { return Ok(None) };
    let file = File::open(path).map_err(|e| TilerError::io(path, e))?;
    let file_len = file.metadata().map_err(|e| TilerError::io(path, e))?.len();
    let ndpi = decoder.find_tag(Tag::Unknown(NDPI_FORMAT_FLAG)).map_err(tag_err)?.is_some();
    // NDPI's own reading of the directory: offsets past 4 GiB and the offset table. Where it
    // fails the file is read as the tiff crate reads it (and scanned), unless the file is too
    // large for that to be right.
    let directory = match ndpi.then(|| Directory::read(&file, file_len, page)) {
        Some(Err(m)) if file_len > u32::MAX as u64 => {
            return Err(TilerError::decode(path, format!("its NDPI directory {page}: {m}")));
        }
        Some(read) => read.ok(),
        None => None,
    };
    let (offset, count) = directory.as_ref().and_then(|d| d.strip).unwrap_or((offset, count));
    if offset.checked_add(count).is_none_or(|end| end > file_len) {
        return Err(TilerError::decode(
            path,
            format!(
                "JPEG strip 0 lies past the end of the file ({count} bytes at {offset}, the file has {file_len}): a truncated TIFF?"
            ),
        ));
    }
    let Some(header) =
        read_header(&file, offset, count).map_err(|m| TilerError::decode(path, format!("JPEG strip 0: {m}")))?
    else {
        return Ok(None);
    };
    // The frame's size where it can hold the TIFF's; beyond 65535 it cannot, and the TIFF says.
    for (name, tiff, jpeg) in [("width", width, header.declared.0), ("height", height, header.declared.1)] {
        if tiff <= u16::MAX as u32 && jpeg != 0 && jpeg != tiff {
            return Err(TilerError::decode(
                path,
                format!("JPEG strip 0: the JPEG's {name} is {jpeg}, the TIFF's {tiff}"),
            ));
        }
    }
    let mcus_per_row = width.div_ceil(header.mcu_w);
    if header.interval > mcus_per_row || mcus_per_row % header.interval != 0 {
        return Err(TilerError::unsupported(
            path,
            format!(
                "its JPEG's restart interval ({} MCUs) does not divide an MCU row ({mcus_per_row} MCUs), so the intervals cannot be decoded one by one (OpenSlide refuses it too)",
                header.interval
            ),
        ));
    }
    let interval_w = header.interval * header.mcu_w;
    if interval_w > 65_500 {
        return Err(TilerError::unsupported(
            path,
            format!("its JPEG's restart intervals are {interval_w} texels wide, more than libjpeg decodes (65500)"),
        ));
    }
    // Each interval is decoded as a JPEG of its own: one interval wide, one MCU row high.
    let mut header = header;
    let colour_components = header.colour.components();
    let size_at = header.sof_at + 5;
    header.bytes[size_at..size_at + 2].copy_from_slice(&(header.mcu_h as u16).to_be_bytes());
    header.bytes[size_at + 2..size_at + 4].copy_from_slice(&(interval_w as u16).to_be_bytes());
    let comps = header.colour.components() as u64;
    let row_bytes = width as u64 * comps;
    let mcu_row_bytes = row_bytes * header.mcu_h as u64;
    let interval_bytes = interval_w as u64 * header.mcu_h as u64 * comps;
    let workers = std::thread::available_parallelism().map_or(1, |n| n.get()) as u64;
    // One MCU row decoded, its compressed bytes at their bound, and an interval's stream and
    // scanline per worker.
    let per_worker = interval_bytes * (MAX_EXPANSION as u64 + 1) + header.bytes.len() as u64;
    let need = mcu_row_bytes * (MAX_EXPANSION as u64 + 1) + workers * per_worker;
    if need > max_memory {
        return Err(TilerError::unsupported(
            path,
            format!(
                "one MCU row ({} rows) of the {width}x{height} JPEG, decoded and compressed, needs {} MiB, more than --max-memory ({} MiB); raise --max-memory",
                header.mcu_h,
                need.div_ceil(1 << 20),
                max_memory >> 20
            ),
        ));
    }
    // Enough MCU rows that every core has intervals to decode, within an eighth of --max-memory.
    let across = mcus_per_row / header.interval;
    let rows = height.div_ceil(header.mcu_h) as u64;
    let wanted = (workers * 4).div_ceil(across as u64);
    let fits = (max_memory / 8) / (mcu_row_bytes * (MAX_EXPANSION as u64 + 1));
    let group = wanted.min(fits).min(rows).max(1) as u32;
    let band_limit = usize::try_from(mcu_row_bytes * group as u64 * MAX_EXPANSION as u64).unwrap_or(usize::MAX);
    // Where each interval starts, from the offset table where it is there, consistent and held
    // (12 bytes an interval while read) within an eighth of --max-memory.
    let intervals = across as u64 * rows;
    let table = match &directory {
        Some(_) if intervals * 12 > max_memory / 8 => {
            Err(format!("its offset table ({intervals} entries) is larger than an eighth of --max-memory"))
        }
        Some(d) => d.mcu_starts(&file, file_len, intervals, (header.data_start, count)),
        None => Err("no NDPI directory was read".to_string()),
    };
    let (table, located) = match table {
        Ok(starts) => (Some(Table { starts, strip_at: offset, len: count }), "located by its offset table".to_string()),
        Err(why) => (None, format!("found by scanning ({why})")),
    };
    let mut reader = BufReader::with_capacity(1 << 16, file);
    reader.seek(SeekFrom::Start(offset + header.data_start)).map_err(|e| TilerError::io(path, e))?;
    let scanner = Scanner {
        reader,
        left: count - header.data_start,
        pending_ff: false,
        marker: 0,
        rows_read: 0,
        table,
        index: 0,
    };
    Ok(Some(Box::new(Ndpi {
        path: path.to_path_buf(),
        width,
        height,
        header,
        interval_w,
        across,
        group,
        scanner,
        compressed: Vec::new(),
        decoded: Vec::new(),
        fresh: false,
        band_first: 0,
        band_rows: 0,
        band_limit,
        columns: None,
        next: 0,
        failed: false,
        label: label.to_string(),
        located,
        embedded: crate::source::Embedded {
            lossy: crate::source::LossyStep::of(
                crate::source::LossyStep::JPEG,
                (width, height),
                colour_components,
                count,
            ),
            ..embedded.clone()
        },
    })))
}

/// Reads the marker segments before the scan; `None` where the JPEG cannot be decoded by
/// restart interval (no DRI, progressive or lossless, several scans): those are read whole.
fn read_header(file: &File, offset: u64, count: u64) -> std::result::Result<Option<Header>, String> {
    let read = |at: u64, buf: &mut [u8]| -> std::result::Result<(), String> {
        if at + buf.len() as u64 > count {
            return Err("the strip ends inside the JPEG header".into());
        }
        file.read_exact_at(buf, offset + at).map_err(|e| format!("cannot be read: {e}"))
    };
    let mut soi = [0u8; 2];
    read(0, &mut soi)?;
    if soi != [0xFF, 0xD8] {
        return Err("the data does not start with a JPEG SOI marker".into());
    }
    let mut bytes = soi.to_vec();
    let mut at = 2u64;
    let (mut frame, mut interval) = (None, 0u32);
    loop {
        let mut marker = [0u8; 4];
        read(at, &mut marker)?;
        if marker[0] != 0xFF {
            return Err(format!("no JPEG marker at byte {at} of the header"));
        }
        if marker[1] == 0xFF {
            at += 1; // a fill byte
            continue;
        }
        let len = u16::from_be_bytes([marker[2], marker[3]]) as usize;
        if len < 2 || bytes.len() + 2 + len > MAX_HEADER {
            return Err(format!("a marker segment of {len} bytes at byte {at} of the header"));
        }
        let start = bytes.len();
        bytes.resize(start + 2 + len, 0);
        read(at, &mut bytes[start..])?;
        let body = &bytes[start + 4..];
        match marker[1] {
            0xC0 | 0xC1 => frame = Some((start, parse_frame(body)?)),
            0xC2..=0xCF if !matches!(marker[1], 0xC4 | 0xC8 | 0xCC) => return Ok(None),
            0xDD if body.len() >= 2 => interval = u16::from_be_bytes([body[0], body[1]]) as u32,
            0xD9 => return Err("the JPEG ends before its scan".into()),
            0xDA => {
                let Some((sof_at, frame)) = frame else { return Err("the scan comes before the frame header".into()) };
                let in_scan = body.first().copied().unwrap_or(0) as usize;
                if interval == 0 || in_scan != frame.components.len() {
                    return Ok(None);
                }
                let colour = marked_colour(&bytes, &frame.components)?;
                let (mut mcu_w, mut mcu_h) = (8, 8);
                if frame.components.len() > 1 {
                    mcu_w = 8 * frame.components.iter().map(|c| c.1 >> 4).max().unwrap_or(1) as u32;
                    mcu_h = 8 * frame.components.iter().map(|c| c.1 & 15).max().unwrap_or(1) as u32;
                }
                let (declared, data_start) = (frame.size, at + 2 + len as u64);
                return Ok(Some(Header { bytes, sof_at, data_start, colour, interval, mcu_w, mcu_h, declared }));
            }
            _ => {}
        }
        at += 2 + len as u64;
    }
}

struct Frame {
    /// (width, height) as the frame header says.
    size: (u32, u32),
    /// (id, sampling factors) of each component.
    components: Vec<(u8, u8)>,
}

fn parse_frame(body: &[u8]) -> std::result::Result<Frame, String> {
    let short = || "a short frame header".to_string();
    let (&precision, rest) = body.split_first().ok_or_else(short)?;
    if precision != 8 || rest.len() < 5 {
        return Err(format!("{precision}-bit JPEG samples (8-bit are read)"));
    }
    let height = u16::from_be_bytes([rest[0], rest[1]]) as u32;
    let width = u16::from_be_bytes([rest[2], rest[3]]) as u32;
    let n = rest[4] as usize;
    let specs = rest.get(5..5 + 3 * n).ok_or_else(short)?;
    let components: Vec<(u8, u8)> = specs.chunks_exact(3).map(|c| (c[0], c[1])).collect();
    if !matches!(n, 1 | 3)
        || components.iter().any(|c| !(1..=4).contains(&(c.1 >> 4)) || !(1..=4).contains(&(c.1 & 15)))
    {
        return Err(format!(
            "{n} components or sampling factors libjpeg does not decode (grey and 3-component colour are read)"
        ));
    }
    Ok(Frame { size: (width, height), components })
}

/// The colour space libjpeg infers from a 1- or 3-component stream's markers.
fn marked_colour(header: &[u8], components: &[(u8, u8)]) -> std::result::Result<Colour, String> {
    if components.len() == 1 {
        return Ok(Colour::Grey);
    }
    let (mut jfif, mut adobe) = (false, None);
    let mut at = 2;
    while at + 4 <= header.len() {
        let len = u16::from_be_bytes([header[at + 2], header[at + 3]]) as usize;
        let body = &header[at + 4..(at + 2 + len).min(header.len())];
        match header[at + 1] {
            0xE0 if body.starts_with(b"JFIF\0") => jfif = true,
            0xEE if body.starts_with(b"Adobe") && body.len() >= 12 => adobe = Some(body[11]),
            _ => {}
        }
        at += 2 + len;
    }
    let ids: Vec<u8> = components.iter().map(|c| c.0).collect();
    Ok(match (jfif, adobe) {
        (true, _) => Colour::YCbCr,
        (false, Some(0)) => Colour::Rgb,
        (false, Some(_)) => Colour::YCbCr,
        (false, None) if ids == b"RGB" => Colour::Rgb,
        _ => Colour::YCbCr,
    })
}

/// The strip's entropy-coded data, read front to back and cut at its restart markers.
struct Scanner {
    reader: BufReader<File>,
    /// Bytes of the strip not read yet.
    left: u64,
    /// The last byte read was a 0xFF whose marker byte is still to come.
    pending_ff: bool,
    /// The number (0 to 7) of the next restart marker.
    marker: u8,
    /// MCU rows read so far.
    rows_read: u32,
    /// Where the intervals start, where the file's offset table says so.
    table: Option<Table>,
    /// The number of the next interval.
    index: u64,
}

/// The offset table, checked to be in order within the strip: each interval is read where it
/// says, and the restart marker that closes it checked to be there.
struct Table {
    /// Where each interval's data starts, from the start of the strip.
    starts: Vec<u64>,
    /// The strip's offset in the file and its length.
    strip_at: u64,
    len: u64,
}

impl Scanner {
    /// Appends the next interval's data (without its closing marker) to `out`, at most `limit`
    /// bytes; `last`: the image's last interval, which ends with EOI or the strip.
    /// `keep` false: the interval is passed over (with the table, without reading it).
    fn interval(&mut self, out: &mut Vec<u8>, limit: usize, last: bool, keep: bool) -> std::result::Result<(), String> {
        let index = self.index;
        self.index += 1;
        if let Some(table) = &self.table {
            return if keep { table.read(self.reader.get_ref(), index, out, limit, last) } else { Ok(()) };
        }
        loop {
            if out.len() > limit {
                return Err(format!("no restart marker within {limit} bytes: a damaged JPEG"));
            }
            if self.left == 0 {
                return match last {
                    true => Ok(()),
                    false => Err("the strip ends here: a truncated file?".into()),
                };
            }
            let buf = self.reader.fill_buf().map_err(|e| format!("cannot be read: {e}"))?;
            if buf.is_empty() {
                return Err("the file ends inside the strip: a truncated file?".into());
            }
            let buf = &buf[..buf.len().min(self.left as usize)];
            if !self.pending_ff {
                let taken = match buf.iter().position(|&b| b == 0xFF) {
                    Some(ff) => {
                        self.pending_ff = true;
                        out.extend_from_slice(&buf[..ff]);
                        ff + 1
                    }
                    None => {
                        out.extend_from_slice(buf);
                        buf.len()
                    }
                };
                self.consume(taken);
                continue;
            }
            // The byte after a 0xFF: stuffing, fill, or a marker.
            let byte = buf[0];
            self.consume(1);
            self.pending_ff = false;
            match byte {
                0x00 => out.extend_from_slice(&[0xFF, 0x00]),
                0xFF => self.pending_ff = true,
                0xD0..=0xD7 if !last && byte - 0xD0 == self.marker => {
                    self.marker = (self.marker + 1) % 8;
                    return Ok(());
                }
                0xD0..=0xD7 => {
                    let expected = if last { "EOI".to_string() } else { format!("RST{}", self.marker) };
                    return Err(format!("restart marker RST{} found where {expected} was due", byte - 0xD0));
                }
                0xD9 if last => return Ok(()),
                0xD9 => return Err("the JPEG ends (EOI) before its last restart interval".into()),
                other => return Err(format!("marker 0xFF{other:02X} inside the compressed data")),
            }
        }
    }

    fn consume(&mut self, n: usize) {
        self.reader.consume(n);
        self.left -= n as u64;
    }
}

impl Table {
    /// Reads interval `index` into `out`, checking that the marker which should close it (RSTn,
    /// or EOI closing the last) is where the next interval's start says.
    fn read(
        &self,
        file: &File,
        index: u64,
        out: &mut Vec<u8>,
        limit: usize,
        last: bool,
    ) -> std::result::Result<(), String> {
        let start = self.starts[index as usize];
        let end = if last { self.len } else { self.starts[index as usize + 1] };
        let len = (end - start) as usize;
        if len > limit + 2 {
            return Err(format!(
                "the offset table (tag 65426) gives it {len} bytes, more than its bound ({limit}): a damaged table?"
            ));
        }
        out.resize(len, 0);
        file.read_exact_at(out, self.strip_at + start).map_err(|e| format!("cannot be read: {e}"))?;
        let closing = if last { 0xD9 } else { 0xD0 + (index % 8) as u8 };
        match out[len.saturating_sub(2)..] {
            [0xFF, found] if found == closing => out.truncate(len - 2),
            // The strip may end without EOI, as the scan allows.
            _ if last => {}
            [0xFF, found @ 0xD0..=0xD7] => {
                return Err(format!(
                    "RST{} found where RST{} was due, at the end the offset table (tag 65426) gives it: the table disagrees with the markers",
                    found - 0xD0,
                    closing - 0xD0
                ));
            }
            _ => {
                return Err(format!(
                    "no RST{} marker at byte {} of the strip, where the offset table (tag 65426) ends it: the table disagrees with the markers",
                    closing - 0xD0,
                    end - 2
                ));
            }
        }
        Ok(())
    }
}

impl Ndpi {
    fn mcu_rows(&self) -> u32 {
        self.height.div_ceil(self.header.mcu_h)
    }

    /// Reads (skipping those before it) the band of MCU rows holding image row `y`.
    fn read_band(&mut self, y: u64) -> std::result::Result<(), String> {
        let band_h = self.header.mcu_h as u64 * self.group as u64;
        let first = (y / band_h * band_h / self.header.mcu_h as u64) as u32;
        if first < self.scanner.rows_read {
            return Err("rows were asked for again after later ones: the strip is read once".into());
        }
        let rows = (self.mcu_rows() - first).min(self.group);
        let across = self.across as usize;
        let interval_limit =
            self.interval_w as usize * self.header.mcu_h as usize * self.header.colour.components() * MAX_EXPANSION
                + 4096;
        self.compressed.resize_with(rows as usize * across, Vec::new);
        let mut scratch = Vec::new();
        let mut held = 0usize;
        for mcu_row in self.scanner.rows_read..first + rows {
            let kept = mcu_row >= first;
            for col in 0..self.across {
                let last = mcu_row + 1 == self.mcu_rows() && col + 1 == self.across;
                let out = match kept {
                    true => &mut self.compressed[(mcu_row - first) as usize * across + col as usize],
                    false => &mut scratch,
                };
                out.clear();
                let name = || interval_name(self.across, mcu_row, col);
                self.scanner.interval(out, interval_limit, last, kept).map_err(|m| format!("{}: {m}", name()))?;
                held += if kept { out.len() } else { 0 };
                if held > self.band_limit {
                    return Err(format!(
                        "{}: the band's compressed data passes {} bytes, its bound: a damaged JPEG?",
                        name(),
                        self.band_limit
                    ));
                }
            }
            self.scanner.rows_read = mcu_row + 1;
        }
        (self.band_first, self.band_rows, self.fresh) = (first, rows, false);
        Ok(())
    }

    /// Decodes the band's intervals under the columns read, in parallel.
    fn decode_band(&mut self) -> std::result::Result<(), String> {
        let cols = match &self.columns {
            Some(c) => c.start / self.interval_w..c.end.div_ceil(self.interval_w),
            None => 0..self.across,
        };
        self.decoded.resize_with(self.compressed.len(), Vec::new);
        let mut decoded = std::mem::take(&mut self.decoded);
        let this = &*self;
        let result = decoded.par_iter_mut().enumerate().try_for_each(|(i, texels)| {
            let (r, c) = (i as u32 / this.across, i as u32 % this.across);
            if !cols.contains(&c) {
                texels.clear();
                return Ok(());
            }
            this.decode_interval(this.band_first + r, c, &this.compressed[i], texels)
        });
        self.decoded = decoded;
        result?;
        self.fresh = true;
        Ok(())
    }

    fn decode_interval(
        &self,
        mcu_row: u32,
        col: u32,
        data: &[u8],
        texels: &mut Vec<u8>,
    ) -> std::result::Result<(), String> {
        let header = &self.header;
        let mut stream = Vec::with_capacity(header.bytes.len() + data.len() + 2);
        stream.extend_from_slice(&header.bytes);
        stream.extend_from_slice(data);
        stream.extend_from_slice(&[0xFF, 0xD9]);
        let x0 = col * self.interval_w;
        let y0 = mcu_row as u64 * header.mcu_h as u64;
        let extent = Extent {
            columns: self.interval_w.min(self.width - x0) as usize,
            rows: (header.mcu_h as u64).min(self.height as u64 - y0) as usize,
            max_columns: self.interval_w as usize,
            max_rows: header.mcu_h as usize,
        };
        texels.resize(extent.columns * extent.rows * header.colour.components(), 0);
        libjpeg::decode(&stream, header.colour, extent, texels)
            .map_err(|m| format!("{}: {m}", interval_name(self.across, mcu_row, col)))
    }
}

/// How an interval is named in errors: its number in the stream and where it lies.
fn interval_name(across: u32, mcu_row: u32, col: u32) -> String {
    let index = mcu_row as u64 * across as u64 + col as u64;
    format!("JPEG restart interval {index} (column {col} of MCU row {mcu_row})")
}

impl RowSource for Ndpi {
    fn header(&self) -> ImageHeader {
        let channels = if self.header.colour == Colour::Grey { Channels::Grey } else { Channels::Rgb };
        ImageHeader { width: self.width, height: self.height, layout: PixelLayout::new(channels, Depth::U8) }
    }

    fn embedded(&self) -> crate::source::Embedded {
        self.embedded.clone()
    }

    fn read_row(&mut self, out: &mut [u8]) -> Result<()> {
        let y = self.next;
        let fail = |message: String| TilerError::DecodeRow { path: self.path.clone(), row: y, message };
        let columns = self.columns.clone().unwrap_or(0..self.width);
        let pixel = self.header.colour.components();
        super::check_row(y, self.height, &columns, pixel, out.len()).map_err(fail)?;
        if self.failed {
            return Err(fail("an earlier restart interval failed to decode".into()));
        }
        let mcu_h = self.header.mcu_h as u64;
        let held = self.band_first as u64 * mcu_h..(self.band_first + self.band_rows) as u64 * mcu_h;
        let loaded = if held.contains(&y) { Ok(()) } else { self.read_band(y) };
        if let Err(message) = loaded.and_then(|()| if self.fresh { Ok(()) } else { self.decode_band() }) {
            self.failed = true;
            return Err(TilerError::DecodeRow { path: self.path.clone(), row: y, message });
        }
        let within = y - self.band_first as u64 * mcu_h;
        let (band_row, interval_y) = ((within / mcu_h) as usize, (within % mcu_h) as usize);
        let intervals = &self.decoded[band_row * self.across as usize..];
        copy_row(intervals, self.interval_w, self.width, pixel, interval_y, columns, out);
        self.next += 1;
        Ok(())
    }

    /// Skipped rows' intervals are passed over when the next row is read, found but not decoded.
    fn skip_rows(&mut self, rows: u32) -> Result<()> {
        self.next += rows as u64;
        Ok(())
    }

    /// Only the intervals under the columns are decoded (all are read: the strip is one stream).
    fn read_columns(&mut self, columns: Range<u32>) -> bool {
        let columns = (columns != (0..self.width)).then_some(columns);
        if columns != self.columns {
            // The band held is decoded again, from its compressed bytes, for the new columns.
            (self.columns, self.fresh) = (columns, false);
        }
        true
    }

    fn describe(&self) -> String {
        let colour = match self.header.colour {
            Colour::Grey => "grey",
            Colour::YCbCr => "YCbCr",
            Colour::Rgb => "RGB",
        };
        format!(
            "{}, jpeg ({colour}, libjpeg-turbo), streamed by restart interval ({}x{} intervals, {} to an MCU row, {}, decoded in parallel)",
            self.label, self.interval_w, self.header.mcu_h, self.across, self.located
        )
    }
}
