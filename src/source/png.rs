//! PNG: streamed row by row; Adam7-interlaced files arrive pass by pass, so those are decoded
//! whole (within `--max-memory`).

use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use super::icc::{MAX_PROFILE_BYTES, too_large};
use super::{Embedded, ImageHeader, RowSource, check_whole_fits, orient};
use crate::error::{Result, TilerError};
use crate::pixel::{Channels, Depth, PixelLayout};

pub struct PngSource {
    path: PathBuf,
    width: u32,
    height: u32,
    layout: PixelLayout,
    next: u64,
    rows: Rows,
    embedded: Embedded,
}

enum Rows {
    Streamed(Box<png::Reader<BufReader<File>>>),
    /// A de-interlaced image and its row length in bytes.
    Whole(Vec<u8>, usize),
}

pub fn open(path: &Path, max_memory: u64) -> Result<Box<dyn RowSource>> {
    let file = File::open(path).map_err(|e| TilerError::io(path, e))?;
    let mut decoder = png::Decoder::new_with_limits(
        BufReader::with_capacity(1 << 16, file),
        png::Limits { bytes: usize::try_from(max_memory).unwrap_or(usize::MAX) },
    );
    decoder.set_transformations(png::Transformations::EXPAND);
    // The profile is read by `iccp` below, within its own cap: the crate would inflate it
    // within the whole budget, and drop one that is damaged (or fails its CRC) without a word.
    decoder.set_ignore_iccp_chunk(true);
    let mut reader = decoder.read_info().map_err(|e| TilerError::decode(path, format!("not a readable PNG: {e}")))?;
    // After the crate has read the chunks up to the image data: a file it refuses is named
    // by the crate, and the walk below meets only chunks the crate has found well formed.
    let icc = iccp(path)?;
    let (colour, depth) = reader.output_color_type();
    let channels = match colour {
        png::ColorType::Grayscale => Channels::Grey,
        png::ColorType::GrayscaleAlpha => Channels::GreyAlpha,
        png::ColorType::Rgb => Channels::Rgb,
        png::ColorType::Rgba => Channels::Rgba,
        png::ColorType::Indexed => return Err(TilerError::decode(path, "palette PNG was not expanded")),
    };
    let depth = match depth {
        png::BitDepth::Sixteen => Depth::U16,
        _ => Depth::U8,
    };
    let layout = PixelLayout::new(channels, depth);
    let (width, height) = (reader.info().width, reader.info().height);
    // eXIf as the decoder found it before the image data; iCCP as `iccp` read it.
    let embedded = Embedded {
        orientation: reader.info().exif_metadata.as_deref().map(orient::from_exif).unwrap_or_default(),
        icc,
        geo: None,
        pitch: None,
        lossy: Vec::new(),
        channel: None,
    };
    let rows = if reader.info().interlaced {
        check_whole_fits(
            path,
            width as u64,
            height as u64,
            layout,
            max_memory,
            "the PNG is Adam7-interlaced (its rows arrive out of order)",
        )?;
        let size = reader.output_buffer_size().ok_or_else(|| TilerError::decode(path, "image too large"))?;
        let mut buf = vec![0; size];
        let info =
            reader.next_frame(&mut buf).map_err(|e| TilerError::decode(path, format!("corrupt PNG data: {e}")))?;
        Rows::Whole(buf, info.line_size)
    } else {
        Rows::Streamed(Box::new(reader))
    };
    Ok(Box::new(PngSource { path: path.to_path_buf(), width, height, layout, next: 0, rows, embedded }))
}

/// The ICC profile of `path`'s iCCP chunk (PNG 1.2, 11.3.3.3: a keyword of 1 to 79 bytes, a
/// NUL, compression method 0, a zlib stream), inflated to at most
/// [`MAX_PROFILE_BYTES`]; `None` without one. Only the chunks' lengths and types are read on
/// the way (to the first IDAT, after which an iCCP is not allowed; the first iCCP is the one,
/// as the png crate takes it); the png crate, which reads the rest of the file, is told to
/// skip this chunk: it offers no way to learn that a profile was dropped, nor to inflate one
/// under a cap of its own. A profile that is damaged (its CRC, no keyword, an unknown method,
/// not zlib data) or inflates past the cap is an error: its texels are never taken as sRGB
/// (libvips warns and keeps a profile whose CRC fails, and drops one it cannot inflate).
fn iccp(path: &Path) -> Result<Option<Vec<u8>>> {
    let damaged = |why: String| {
        TilerError::decode(
            path,
            format!(
                "the embedded ICC profile (PNG iCCP chunk) is damaged: {why}; strip it (`exiftool -icc_profile= FILE`) or re-save the image"
            ),
        )
    };
    let mut file = BufReader::with_capacity(1 << 14, File::open(path).map_err(|e| TilerError::io(path, e))?);
    let mut head = [0u8; 8];
    // Not a PNG, or one cut short: the png crate says what is wrong.
    if file.read_exact(&mut head).is_err() || head != *b"\x89PNG\r\n\x1a\n" {
        return Ok(None);
    }
    while file.read_exact(&mut head).is_ok() {
        let length = u32::from_be_bytes([head[0], head[1], head[2], head[3]]) as u64;
        match &head[4..] {
            b"IDAT" | b"IEND" => return Ok(None),
            b"iCCP" => {
                // A zlib stream of a profile of the cap's size, stored: a few bytes more.
                if length > MAX_PROFILE_BYTES + 4096 {
                    return Err(too_large(path, Some(length), "PNG iCCP chunk, compressed"));
                }
                // The chunk's data, then its CRC (of its type and data).
                let mut chunk = Vec::new();
                (&mut file).take(length + 4).read_to_end(&mut chunk).map_err(|e| TilerError::io(path, e))?;
                let Some(at) = chunk.len().checked_sub(4).filter(|&at| at as u64 == length) else {
                    let read = chunk.len();
                    return Err(damaged(format!("the file ends inside the chunk ({read} of {} bytes)", length + 4)));
                };
                let stored = u32::from_be_bytes([chunk[at], chunk[at + 1], chunk[at + 2], chunk[at + 3]]);
                chunk.truncate(at);
                let mut crc = flate2::Crc::new();
                crc.update(b"iCCP");
                crc.update(&chunk);
                if crc.sum() != stored {
                    return Err(damaged(format!("its CRC is {stored:08x}, its bytes' {:08x}", crc.sum())));
                }
                let keyword = chunk.iter().position(|&b| b == 0).filter(|&n| (1..80).contains(&n));
                let Some(keyword) = keyword else {
                    return Err(damaged("no profile name of 1 to 79 bytes".into()));
                };
                match chunk.get(keyword + 1) {
                    Some(0) => {}
                    Some(method) => {
                        return Err(damaged(format!("compression method {method} (only 0, zlib, is defined)")));
                    }
                    None => return Err(damaged("the chunk ends after the profile name".into())),
                }
                let mut profile = Vec::new();
                flate2::read::ZlibDecoder::new(&chunk[keyword + 2..])
                    .take(MAX_PROFILE_BYTES + 1)
                    .read_to_end(&mut profile)
                    .map_err(|e| damaged(format!("not zlib data ({e})")))?;
                if profile.len() as u64 > MAX_PROFILE_BYTES {
                    return Err(too_large(path, None, "PNG iCCP chunk, inflated"));
                }
                return Ok(Some(profile));
            }
            // The chunk's data and CRC.
            _ => {
                file.seek(SeekFrom::Current(length as i64 + 4)).map_err(|e| TilerError::io(path, e))?;
            }
        }
    }
    Ok(None)
}

impl RowSource for PngSource {
    fn header(&self) -> ImageHeader {
        ImageHeader { width: self.width, height: self.height, layout: self.layout }
    }

    fn read_row(&mut self, out: &mut [u8]) -> Result<()> {
        let y = self.next;
        self.next += 1;
        let data = match &mut self.rows {
            Rows::Streamed(reader) => match reader.next_row() {
                Ok(Some(row)) => row.data(),
                Ok(None) => return Err(row_error(&self.path, y, "the image data ends early".into())),
                Err(e) => return Err(row_error(&self.path, y, format!("corrupt or truncated PNG data: {e}"))),
            },
            Rows::Whole(buf, line) => &buf[y as usize * *line..][..*line],
        };
        if data.len() != out.len() {
            return Err(row_error(&self.path, y, format!("row has {} bytes, expected {}", data.len(), out.len())));
        }
        match self.layout.depth {
            Depth::U8 => out.copy_from_slice(data),
            // PNG has 8 and 16 bits only.
            _ => {
                for (o, i) in out.chunks_exact_mut(2).zip(data.chunks_exact(2)) {
                    o.copy_from_slice(&u16::from_be_bytes([i[0], i[1]]).to_ne_bytes());
                }
            }
        }
        Ok(())
    }

    fn embedded(&self) -> Embedded {
        self.embedded.clone()
    }

    /// An interlaced image, decoded whole at open. (A streamed one's decoder keeps about two
    /// rows of its own, not counted.)
    fn buffer_bytes(&self) -> u64 {
        match &self.rows {
            Rows::Streamed(_) => 0,
            Rows::Whole(buf, _) => buf.capacity() as u64,
        }
    }

    fn describe(&self) -> String {
        match self.rows {
            Rows::Streamed(_) => "png, streamed by row".into(),
            Rows::Whole(..) => "png, interlaced: decoded whole".into(),
        }
    }
}

fn row_error(path: &Path, row: u64, message: String) -> TilerError {
    TilerError::DecodeRow { path: path.to_path_buf(), row, message }
}
