//! Binary PGM (P5) and PPM (P6), read row by row through a buffer. Not memory-mapped: a
//! mapped file that another process truncates during the run kills the reader with SIGBUS,
//! where a read simply comes up short and is reported as an error naming the row.

use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use super::{ImageHeader, RowSource, image_bytes};
use crate::error::{Result, TilerError};
use crate::pixel::{Channels, Depth, PixelLayout};

pub struct PnmSource {
    path: PathBuf,
    reader: BufReader<File>,
    /// The file's samples of one row, before scaling to the full range.
    raw: Vec<u8>,
    width: u32,
    height: u32,
    maxval: u32,
    layout: PixelLayout,
    next: u64,
    /// Where the pixel data starts in the file.
    data_start: u64,
    /// Texel columns each row is read from, when a stripe asked for fewer than all.
    columns: Option<std::ops::Range<u32>>,
}

/// The most header bytes read (comments included) before the pixel data must start.
const MAX_HEADER: u64 = 64 << 10;
/// Read in blocks of this size, so that rows of any width cost few system calls.
const READ_BUFFER: usize = 1 << 20;

pub fn open(path: &Path) -> Result<Box<dyn RowSource>> {
    let mut file = File::open(path).map_err(|e| TilerError::io(path, e))?;
    let file_len = file.metadata().map_err(|e| TilerError::io(path, e))?.len();
    let mut head = Vec::new();
    (&mut file).take(MAX_HEADER).read_to_end(&mut head).map_err(|e| TilerError::io(path, e))?;
    let (channels, width, height, maxval, data_start) = parse_header(&head).map_err(|m| TilerError::decode(path, m))?;
    if width == 0 || height == 0 {
        return Err(TilerError::decode(path, format!("the header says {width}x{height}: the image has no pixels")));
    }
    let depth = if maxval < 256 { Depth::U8 } else { Depth::U16 };
    let layout = PixelLayout::new(channels, depth);
    let need =
        image_bytes(width, height, layout).ok_or_else(|| TilerError::decode(path, "the header's size overflows"))?;
    let have = file_len.saturating_sub(data_start as u64);
    if have < need {
        return Err(TilerError::decode(
            path,
            format!("truncated: the header says {width}x{height} ({need} bytes of pixels) but the file holds {have}"),
        ));
    }
    let (width, height) = (u32::try_from(width).unwrap_or(u32::MAX), u32::try_from(height).unwrap_or(u32::MAX));
    file.seek(SeekFrom::Start(data_start as u64)).map_err(|e| TilerError::io(path, e))?;
    Ok(Box::new(PnmSource {
        path: path.to_path_buf(),
        reader: BufReader::with_capacity(READ_BUFFER, file),
        raw: Vec::new(),
        width,
        height,
        maxval,
        layout,
        next: 0,
        data_start: data_start as u64,
        columns: None,
    }))
}

/// Returns (channels, width, height, maxval, offset of the pixel data).
fn parse_header(bytes: &[u8]) -> std::result::Result<(Channels, u64, u64, u32, usize), String> {
    let channels = match bytes.get(..2) {
        Some(b"P5") => Channels::Grey,
        Some(b"P6") => Channels::Rgb,
        _ => return Err("not a binary PGM/PPM (P5/P6)".into()),
    };
    let mut pos = 2;
    let mut fields = [0u64; 3];
    for (i, field) in fields.iter_mut().enumerate() {
        loop {
            match bytes.get(pos) {
                Some(b'#') => {
                    while !matches!(bytes.get(pos), Some(b'\n') | None) {
                        pos += 1;
                    }
                }
                Some(c) if c.is_ascii_whitespace() => pos += 1,
                _ => break,
            }
        }
        let start = pos;
        while bytes.get(pos).is_some_and(u8::is_ascii_digit) {
            pos += 1;
        }
        let name = ["width", "height", "maxval"][i];
        let text = std::str::from_utf8(&bytes[start..pos]).unwrap_or("");
        *field = text.parse().map_err(|_| format!("header field {name} is missing or not a number"))?;
    }
    if !bytes.get(pos).is_some_and(u8::is_ascii_whitespace) {
        return Err("header is not followed by a single whitespace byte".into());
    }
    let maxval = fields[2];
    if maxval == 0 || maxval > 65535 {
        return Err(format!("header field maxval is {maxval}; it must be 1..=65535"));
    }
    Ok((channels, fields[0], fields[1], maxval as u32, pos + 1))
}

impl RowSource for PnmSource {
    fn header(&self) -> ImageHeader {
        ImageHeader { width: self.width, height: self.height, layout: self.layout }
    }

    fn read_row(&mut self, out: &mut [u8]) -> Result<()> {
        let row = self.next;
        let ends_early = |e: std::io::Error| TilerError::DecodeRow {
            path: self.path.clone(),
            row,
            message: if e.kind() == std::io::ErrorKind::UnexpectedEof {
                "the file ends early (was it truncated while being read?)".into()
            } else {
                e.to_string()
            },
        };
        if let Some(columns) = &self.columns {
            // A stripe's part of the row, read where it lies (the buffer would read the rest).
            let bpp = self.layout.bytes_per_pixel() as u64;
            let at = self.data_start + (row * self.width as u64 + columns.start as u64) * bpp;
            let file = self.reader.get_mut();
            self.raw.resize(out.len(), 0);
            file.seek(SeekFrom::Start(at)).and_then(|_| file.read_exact(&mut self.raw)).map_err(ends_early)?;
        } else if self.layout.depth == Depth::U8 && self.maxval == 255 {
            self.reader.read_exact(out).map_err(ends_early)?;
            self.next += 1;
            return Ok(());
        } else {
            self.raw.resize(out.len(), 0);
            self.reader.read_exact(&mut self.raw).map_err(ends_early)?;
        }
        self.next += 1;
        let data = &self.raw;
        match (self.layout.depth, self.maxval) {
            (Depth::U8, m) => {
                for (o, v) in out.iter_mut().zip(data) {
                    *o = ((*v as u32).min(m) * 255 * 2 + m).div_euclid(2 * m) as u8;
                }
            }
            // PNM has 8 and 16 bits only.
            (_, m) => {
                for (o, i) in out.chunks_exact_mut(2).zip(data.chunks_exact(2)) {
                    let v = (u16::from_be_bytes([i[0], i[1]]) as u32).min(m);
                    let v = if m == 65535 { v } else { ((v as u64 * 65535 * 2 + m as u64) / (2 * m as u64)) as u32 };
                    o.copy_from_slice(&(v as u16).to_ne_bytes());
                }
            }
        }
        Ok(())
    }

    fn describe(&self) -> String {
        "pnm, read by row".into()
    }

    fn read_columns(&mut self, columns: std::ops::Range<u32>) -> bool {
        let whole = columns == (0..self.width);
        self.columns = Some(columns).filter(|_| !whole);
        if whole {
            // Buffered reading goes on from the next row.
            let at = self.data_start + self.next * self.width as u64 * self.layout.bytes_per_pixel() as u64;
            return self.reader.seek(SeekFrom::Start(at)).is_ok();
        }
        true
    }

    fn skip_rows(&mut self, rows: u32) -> Result<()> {
        self.next += rows as u64;
        let row_bytes = self.width as u64 * self.layout.bytes_per_pixel() as u64;
        let at = self.data_start + self.next * row_bytes;
        self.reader.seek(SeekFrom::Start(at)).map_err(|e| TilerError::io(&self.path, e))?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_with_comments() {
        let h = b"P6\n# made by hand\n3 2\n255\nrest";
        assert_eq!(parse_header(h).unwrap(), (Channels::Rgb, 3, 2, 255, 26));
        assert!(parse_header(b"P6 3 2 70000 ").is_err());
        assert!(parse_header(b"P6 3 x 255 ").is_err());
        assert!(parse_header(b"P3 3 2 255 ").is_err());
    }
}
