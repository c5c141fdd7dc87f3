//! PNG: streamed row by row; Adam7-interlaced files arrive pass by pass, so those are decoded
//! whole (within `--max-memory`).

use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};

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
    let mut reader = decoder.read_info().map_err(|e| TilerError::decode(path, format!("not a readable PNG: {e}")))?;
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
    // iCCP and eXIf as the decoder found them before the image data.
    let embedded = Embedded {
        orientation: reader.info().exif_metadata.as_deref().map(orient::from_exif).unwrap_or_default(),
        icc: reader.info().icc_profile.as_deref().map(<[u8]>::to_vec),
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
