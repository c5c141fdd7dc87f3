//! JPEG through libjpeg-turbo (the `mozjpeg` crate), read scanline by scanline: libjpeg holds
//! one row of MCUs (8 or 16 image rows) and hands out rows as they are asked for.
//!
//! Progressive JPEGs, and sequential ones whose colour components come in separate scans, can
//! only produce their first row after the last scan, so libjpeg keeps all their DCT
//! coefficients; they are accepted only when those fit under `--max-memory`, and then stream
//! rows out of that buffer like any other JPEG.
//!
//! Errors: libjpeg reports fatal errors through `error_exit`, which must not return; the crate's
//! convention (and ours) is to unwind out of it with `std::panic::resume_unwind` and catch that
//! with `catch_unwind` around every call into libjpeg. Corrupt or truncated data is only a
//! *warning* for libjpeg ("Premature end of JPEG file", "Corrupt JPEG data: ...") after which it
//! goes on with grey or repeated blocks; our error manager turns those warnings into the same
//! unwinding error, so a damaged file is an error naming the row, never silently grey rows.

use std::cell::Cell;
use std::fs::File;
use std::io::{BufRead, BufReader, Read};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};

use mozjpeg::decompress::DecompressStarted;
use mozjpeg::{ColorSpace, Decompress};

use super::icc::Cmyk;
use super::libjpeg::{HIT_EOF, error_manager, panic_message};
use super::{Embedded, ImageHeader, LossyStep, RowSource, orient};
use crate::error::{Result, TilerError};
use crate::pixel::{Channels, Depth, PixelLayout};

pub struct JpegSource {
    path: PathBuf,
    width: u32,
    height: u32,
    layout: PixelLayout,
    next: u64,
    /// `None` once decoding failed: libjpeg's state is undefined after an error.
    decoder: Option<Libjpeg>,
    /// Bytes of DCT coefficients libjpeg holds for a multi-scan (progressive) image.
    whole_coefficients: Option<u64>,
    /// libjpeg has reached the end of the file (harmless unless data turns out to be missing).
    hit_eof: bool,
    /// A CMYK (or YCCK) image: libjpeg's CMYK rows and their conversion to RGB.
    cmyk: Option<(Cmyk, Vec<u8>)>,
    embedded: Embedded,
}

/// A started libjpeg decompressor reading the file.
struct Libjpeg(DecompressStarted<BufReader<File>>);

// SAFETY: the decompressor (libjpeg's state plus the boxed error and source managers it points
// to) is owned solely by this value and is only used through `&mut`, so from one thread at a
// time; libjpeg keeps no thread-local or global state, and our callbacks touch only `cinfo`.
#[expect(unsafe_code)]
unsafe impl Send for Libjpeg {}

/// What the marker segments before the first scan say.
#[derive(Debug, Default)]
struct Header {
    /// The SOFn marker byte (0xC0 baseline, 0xC1 extended, 0xC2 progressive, ...).
    sof: Option<u8>,
    precision: u8,
    components: u8,
    /// Components in the first scan (fewer than `components`: non-interleaved, multi-scan).
    first_scan_components: Option<u8>,
    /// The first APP1 Exif block's orientation.
    orientation: Option<orient::Orientation>,
    /// APP2 ICC_PROFILE chunks: (sequence number, bytes).
    icc_chunks: Vec<(u8, Vec<u8>)>,
    /// An Adobe APP14 marker: CMYK is stored inverted, as Photoshop writes it.
    adobe: bool,
}

impl Header {
    /// The ICC profile: the APP2 chunks joined in their order (a profile missing a chunk
    /// fails when LittleCMS opens it).
    fn icc(&self) -> Option<Vec<u8>> {
        let mut chunks: Vec<&(u8, Vec<u8>)> = self.icc_chunks.iter().collect();
        chunks.sort_by_key(|(seq, _)| *seq);
        (!chunks.is_empty()).then(|| chunks.iter().flat_map(|(_, b)| b.iter().copied()).collect())
    }
}

/// What kind of JPEG a frame marker (SOFn, `0xFFC0 + n`) starts, where libjpeg-turbo here does
/// not decode it: lossless, hierarchical or arithmetic-coded, its marker named ("lossless
/// (SOF3)"). `None` for baseline, extended and progressive Huffman-coded frames (SOF0-2).
pub(crate) fn unsupported_frame(sof: u8) -> Option<String> {
    let n = sof.wrapping_sub(0xC0);
    let kind = match sof {
        0xC0..=0xC2 => return None,
        0xC3 => "lossless",
        0xC5..=0xC7 => "hierarchical (differential)",
        0xC9 | 0xCA => "arithmetic-coded",
        0xCB => "arithmetic-coded lossless",
        0xCD..=0xCF => "arithmetic-coded hierarchical",
        _ => "unknown",
    };
    Some(format!("{kind} (SOF{n}, marker 0xFF{sof:02X})"))
}

pub fn open(path: &Path, max_memory: u64) -> Result<Box<dyn RowSource>> {
    let header = read_header(path)?;
    if let Some(sof) = header.sof {
        if let Some(kind) = unsupported_frame(sof) {
            return Err(TilerError::unsupported(
                path,
                format!(
                    "{kind} JPEG is not supported (baseline and progressive Huffman-coded JPEG are); convert it, e.g. to PNG or TIFF"
                ),
            ));
        }
        if header.precision != 8 {
            return Err(TilerError::unsupported(
                path,
                format!(
                    "{}-bit JPEG is not supported (8-bit is); convert it, e.g. to 16-bit PNG or TIFF",
                    header.precision
                ),
            ));
        }
    }
    let progressive = header.sof == Some(0xC2);
    let multi_scan = progressive || header.first_scan_components.is_some_and(|n| n < header.components);
    // Where the markers could not be followed to the first scan, libjpeg will fail on them
    // anyway; be strict about the end of the file there too.
    let strict_eof = multi_scan || header.first_scan_components.is_none();

    let file = File::open(path).map_err(|e| TilerError::io(path, e))?;
    let file_len = file.metadata().map_err(|e| TilerError::io(path, e))?.len();
    HIT_EOF.with(|eof| eof.set(false));
    let started = catch_unwind(AssertUnwindSafe(|| -> Result<_> {
        let decompress = Decompress::builder()
            .with_err(error_manager(strict_eof))
            .from_reader(BufReader::with_capacity(1 << 16, file))
            .map_err(|e| {
                TilerError::decode(path, format!("not a readable JPEG (truncated or damaged header?): {e}"))
            })?;
        let (width, height) = (decompress.width() as u64, decompress.height() as u64);
        let (channels, cmyk) = match decompress.color_space() {
            ColorSpace::JCS_GRAYSCALE => (Channels::Grey, None),
            ColorSpace::JCS_YCbCr | ColorSpace::JCS_RGB => (Channels::Rgb, None),
            // libjpeg turns YCCK into CMYK; the profile (or the default one) into sRGB.
            ColorSpace::JCS_CMYK | ColorSpace::JCS_YCCK => {
                let cmyk = Cmyk::new(path, header.icc().as_deref(), header.adobe, false)?;
                let row = vec![0u8; decompress.width() * 4];
                (Channels::Rgb, Some((cmyk, row)))
            }
            other => {
                let n = decompress.components().len();
                return Err(unsupported_colour(path, &format!("{n}-component ({other:?})")));
            }
        };
        let layout = PixelLayout::new(channels, Depth::U8);
        let whole = if multi_scan {
            let bytes = coefficient_bytes(&decompress);
            if bytes > max_memory {
                let why = if progressive {
                    "the JPEG is progressive"
                } else {
                    "the JPEG stores its colour components in separate scans"
                };
                return Err(TilerError::unsupported(
                    path,
                    format!(
                        "{why}, so all {} MiB of DCT coefficients of the {width}x{height} {layout} image must be held in memory before its first row, more than --max-memory ({} MiB); raise --max-memory or re-save it as baseline JPEG (losslessly: `jpegtran -copy all in.jpg > out.jpg`)",
                        bytes.div_ceil(1 << 20),
                        max_memory >> 20
                    ),
                ));
            }
            Some(bytes)
        } else {
            None
        };
        // Reads every scan of a multi-scan image; fails here on corrupt or truncated data.
        let started = match (channels, &cmyk) {
            (_, Some(_)) => decompress.to_colorspace(ColorSpace::JCS_CMYK),
            (Channels::Grey, None) => decompress.grayscale(),
            _ => decompress.rgb(),
        }
        .map_err(|e| TilerError::decode(path, format!("libjpeg could not start decoding: {e}")))?;
        Ok((started, width, height, layout, whole, cmyk))
    }));
    let (started, width, height, layout, whole_coefficients, cmyk) = match started {
        Ok(result) => result?,
        Err(payload) => {
            let message = panic_message(payload);
            return Err(TilerError::decode(path, format!("corrupt, truncated or unsupported JPEG: {message}")));
        }
    };
    if width == 0 || height == 0 {
        return Err(TilerError::decode(path, format!("the header says {width}x{height}: the image has no pixels")));
    }
    Ok(Box::new(JpegSource {
        path: path.to_path_buf(),
        width: width as u32,
        height: height as u32,
        layout,
        next: 0,
        decoder: Some(Libjpeg(started)),
        whole_coefficients,
        hit_eof: HIT_EOF.with(Cell::get),
        // A CMYK image's profile is used up turning it into sRGB.
        embedded: Embedded {
            orientation: header.orientation.unwrap_or_default(),
            icc: if cmyk.is_some() { None } else { header.icc() },
            geo: None,
            pitch: None,
            lossy: LossyStep::of(LossyStep::JPEG, (width as u32, height as u32), header.components as usize, file_len),
            channel: None,
        },
        cmyk,
    }))
}

fn unsupported_colour(path: &Path, what: &str) -> TilerError {
    TilerError::unsupported(
        path,
        format!("{what} JPEG is not supported (greyscale, YCbCr/RGB and CMYK/YCCK are); convert it to RGB first"),
    )
}

/// Bytes of the whole-image coefficient arrays libjpeg allocates for a multi-scan image: per
/// component, its blocks rounded up to whole MCUs, 64 coefficients of 2 bytes each.
fn coefficient_bytes<R>(decompress: &Decompress<R>) -> u64 {
    decompress
        .components()
        .iter()
        .map(|c| {
            let h = c.h_samp_factor.max(1) as u64;
            let v = c.v_samp_factor.max(1) as u64;
            let across = (c.width_in_blocks as u64).div_ceil(h) * h;
            let down = (c.height_in_blocks as u64).div_ceil(v) * v;
            across * down * 64 * 2
        })
        .sum()
}

/// Scans the marker segments up to the first SOS for the frame type and scan layout. Anything
/// malformed just ends the scan early: libjpeg then reports the problem properly.
fn read_header(path: &Path) -> Result<Header> {
    let file = File::open(path).map_err(|e| TilerError::io(path, e))?;
    let mut reader = BufReader::with_capacity(1 << 14, file);
    let mut header = Header::default();
    let _ = scan_markers(&mut reader, &mut header);
    Ok(header)
}

fn scan_markers(reader: &mut BufReader<File>, header: &mut Header) -> std::io::Result<()> {
    let mut byte = [0u8; 1];
    let mut read_u8 = |r: &mut BufReader<File>| -> std::io::Result<u8> {
        r.read_exact(&mut byte)?;
        Ok(byte[0])
    };
    if read_u8(reader)? != 0xFF || read_u8(reader)? != 0xD8 {
        return Ok(());
    }
    loop {
        // Markers are 0xFF followed by a code; extra 0xFF bytes are fill.
        if read_u8(reader)? != 0xFF {
            return Ok(());
        }
        let mut marker = read_u8(reader)?;
        while marker == 0xFF {
            marker = read_u8(reader)?;
        }
        match marker {
            0x01 | 0xD0..=0xD7 => continue,
            0xD8 | 0xD9 | 0x00 => return Ok(()),
            _ => {}
        }
        let length = u16::from_be_bytes([read_u8(reader)?, read_u8(reader)?]) as usize;
        if length < 2 {
            return Ok(());
        }
        let body = length - 2;
        match marker {
            0xC0..=0xCF if !matches!(marker, 0xC4 | 0xC8 | 0xCC) => {
                let mut sof = [0u8; 6];
                if body < sof.len() {
                    return Ok(());
                }
                reader.read_exact(&mut sof)?;
                header.sof = Some(marker);
                header.precision = sof[0];
                header.components = sof[5];
                skip(reader, body - sof.len())?;
            }
            0xDA => {
                if body >= 1 {
                    header.first_scan_components = Some(read_u8(reader)?);
                }
                return Ok(());
            }
            // APP1 (Exif), APP2 (ICC_PROFILE), APP14 (Adobe): at most 65533 bytes each.
            0xE1 | 0xE2 | 0xEE => {
                let mut data = vec![0u8; body];
                reader.read_exact(&mut data)?;
                match marker {
                    0xE1 if data.starts_with(b"Exif\0\0") && header.orientation.is_none() => {
                        header.orientation = Some(orient::from_exif(&data));
                    }
                    // A profile has at most 255 chunks (the sequence number is one byte):
                    // more is not a profile, and is not kept (memory stays bounded).
                    0xE2 if data.starts_with(b"ICC_PROFILE\0") && data.len() >= 14 && header.icc_chunks.len() < 255 => {
                        header.icc_chunks.push((data[12], data[14..].to_vec()));
                    }
                    0xEE if data.starts_with(b"Adobe") => header.adobe = true,
                    _ => {}
                }
            }
            _ => skip(reader, body)?,
        }
    }
}

fn skip(reader: &mut BufReader<File>, mut n: usize) -> std::io::Result<()> {
    while n > 0 {
        let available = reader.fill_buf()?.len();
        if available == 0 {
            return Err(std::io::ErrorKind::UnexpectedEof.into());
        }
        let k = available.min(n);
        reader.consume(k);
        n -= k;
    }
    Ok(())
}

impl RowSource for JpegSource {
    fn header(&self) -> ImageHeader {
        ImageHeader { width: self.width, height: self.height, layout: self.layout }
    }

    /// A multi-scan image's DCT coefficients, which libjpeg holds whole from the start. (A
    /// sequential one's row of MCUs is libjpeg's own, not counted.)
    fn buffer_bytes(&self) -> u64 {
        self.whole_coefficients.unwrap_or(0)
    }

    fn read_row(&mut self, out: &mut [u8]) -> Result<()> {
        let y = self.next;
        let row_error = |message: String| TilerError::DecodeRow { path: self.path.clone(), row: y, message };
        let expected = self.width as usize * self.layout.bytes_per_pixel();
        if out.len() != expected {
            return Err(row_error(format!("row buffer has {} bytes, expected {expected}", out.len())));
        }
        let Some(decoder) = self.decoder.as_mut() else {
            return Err(row_error("an earlier row failed to decode".into()));
        };
        HIT_EOF.with(|eof| eof.set(false));
        let into = match &mut self.cmyk {
            Some((_, cmyk_row)) => cmyk_row.as_mut_slice(),
            None => &mut *out,
        };
        let result = catch_unwind(AssertUnwindSafe(|| decoder.0.read_scanlines_into::<u8>(into).map(|_| ())));
        // libjpeg may reach the end of the file a few rows before it runs out of data.
        self.hit_eof |= HIT_EOF.with(Cell::get);
        let message = match result {
            Ok(Ok(())) => {
                if let Some((cmyk, cmyk_row)) = &self.cmyk {
                    cmyk.convert(cmyk_row, out);
                }
                self.next += 1;
                return Ok(());
            }
            Ok(Err(e)) => format!("libjpeg returned no row: {e}"),
            Err(payload) if self.hit_eof => format!("the file ends early (truncated JPEG): {}", panic_message(payload)),
            Err(payload) => format!("damaged JPEG data: {}", panic_message(payload)),
        };
        // The decompressor is not usable after an error; dropping it frees libjpeg's memory.
        self.decoder = None;
        Err(TilerError::DecodeRow { path: self.path.clone(), row: y, message })
    }

    fn embedded(&self) -> Embedded {
        self.embedded.clone()
    }

    fn describe(&self) -> String {
        let how = match self.whole_coefficients {
            None => "jpeg, streamed by scanline (libjpeg-turbo)".into(),
            Some(bytes) => format!(
                "jpeg, multi-scan: {} MiB of coefficients held, then streamed by scanline",
                bytes.div_ceil(1 << 20)
            ),
        };
        match &self.cmyk {
            Some((cmyk, _)) => format!("{how}; {}", cmyk.note),
            None => how,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::source::read_all;
    use jpeg_encoder::{ColorType as Jc, Encoder, SamplingFactor};

    /// Smooth gradients with a few hard edges: realistic enough for JPEG, deterministic.
    fn pattern(width: u32, height: u32, samples: usize) -> Vec<u8> {
        let mut v = Vec::with_capacity((width * height) as usize * samples);
        for y in 0..height {
            for x in 0..width {
                for c in 0..samples as u32 {
                    let base = (x * 255 / width + y * 128 / height + c * 60) % 256;
                    let edge = if (x / 24 + y / 16) % 3 == 0 { 60 } else { 0 };
                    v.push(((base + edge) % 256) as u8);
                }
            }
        }
        v
    }

    struct Options {
        quality: u8,
        sampling: SamplingFactor,
        progressive: bool,
        restart: Option<u16>,
    }

    const PLAIN: Options = Options { quality: 92, sampling: SamplingFactor::F_1_1, progressive: false, restart: None };

    fn write_jpeg(path: &Path, data: &[u8], w: u32, h: u32, colour: Jc, o: &Options) {
        let mut encoder = Encoder::new_file(path, o.quality).unwrap();
        encoder.set_sampling_factor(o.sampling);
        encoder.set_progressive(o.progressive);
        if let Some(r) = o.restart {
            encoder.set_restart_interval(r);
        }
        encoder.encode(data, w as u16, h as u16, colour).unwrap();
    }

    /// Our rows against the `image` crate's decode: IDCTs and upsamplers differ slightly.
    fn assert_close_to_image_crate(path: &Path, ours: &[u8], tolerance: u8) {
        let theirs = match image::open(path).unwrap() {
            image::DynamicImage::ImageLuma8(i) => i.into_raw(),
            image::DynamicImage::ImageRgb8(i) => i.into_raw(),
            other => panic!("unexpected {:?}", other.color()),
        };
        assert_eq!(ours.len(), theirs.len());
        let worst = ours.iter().zip(&theirs).map(|(a, b)| a.abs_diff(*b)).max().unwrap();
        let mean = ours.iter().zip(&theirs).map(|(a, b)| a.abs_diff(*b) as f64).sum::<f64>() / ours.len() as f64;
        assert!(worst <= tolerance, "{}: max difference {worst} > {tolerance}", path.display());
        assert!(mean < 0.25, "{}: mean difference {mean}", path.display());
    }

    #[test]
    fn baseline_rgb_and_grey_match_image_crate() {
        let dir = tempfile::tempdir().unwrap();
        let (w, h) = (173, 91);
        let cases = [
            ("rgb444", Jc::Rgb, 3, PLAIN, 2),
            // Chroma upsampling (subsampled images) differs a little more between libjpeg and
            // zune-jpeg: up to 3 levels here.
            ("rgb420", Jc::Rgb, 3, Options { quality: 80, sampling: SamplingFactor::F_2_2, ..PLAIN }, 4),
            ("rgb422-restart", Jc::Rgb, 3, Options { sampling: SamplingFactor::F_2_1, restart: Some(3), ..PLAIN }, 4),
            ("grey", Jc::Luma, 1, PLAIN, 2),
        ];
        for (name, colour, samples, options, tolerance) in cases {
            let path = dir.path().join(format!("{name}.jpg"));
            write_jpeg(&path, &pattern(w, h, samples), w, h, colour, &options);
            // Through the format dispatch, as the pipeline opens it.
            let mut source = crate::source::open(&path, crate::limits::Budget::new(1 << 30)).unwrap();
            let channels = if samples == 1 { Channels::Grey } else { Channels::Rgb };
            assert_eq!(source.layout(), PixelLayout::new(channels, Depth::U8));
            assert_eq!((source.width(), source.height()), (w, h));
            assert!(source.describe().contains("streamed by scanline"), "{}", source.describe());
            let ours = read_all(source.as_mut()).unwrap();
            assert_close_to_image_crate(&path, &ours, tolerance);
            // Reading past the end is an error, not a panic.
            let mut row = vec![0u8; w as usize * samples];
            assert!(source.read_row(&mut row).is_err());
        }
    }

    #[test]
    fn progressive_is_decoded_within_max_memory_and_refused_above() {
        let dir = tempfile::tempdir().unwrap();
        let (w, h) = (200, 120);
        let path = dir.path().join("progressive.jpg");
        write_jpeg(&path, &pattern(w, h, 3), w, h, Jc::Rgb, &Options { progressive: true, ..PLAIN });
        assert_eq!(read_header(&path).unwrap().sof, Some(0xC2));
        let mut source = open(&path, 1 << 30).unwrap();
        assert!(source.describe().contains("multi-scan"), "{}", source.describe());
        let ours = read_all(source.as_mut()).unwrap();
        assert_close_to_image_crate(&path, &ours, 2);

        // 4:4:4, 200x120 -> 25x15 blocks x 3 components x 128 bytes = 144000 bytes.
        let err = open(&path, 100_000).err().unwrap();
        assert!(matches!(err, TilerError::Unsupported { .. }), "{err}");
        let text = err.to_string();
        assert!(text.contains("progressive") && text.contains("--max-memory") && text.contains("jpegtran"), "{text}");
        assert!(open(&path, 144_000).is_ok());
        assert!(open(&path, 143_999).is_err());
    }

    #[test]
    fn truncated_or_corrupt_data_is_an_error_naming_the_row() {
        let dir = tempfile::tempdir().unwrap();
        let (w, h) = (160, 160);
        let path = dir.path().join("whole.jpg");
        write_jpeg(&path, &pattern(w, h, 3), w, h, Jc::Rgb, &PLAIN);
        let bytes = std::fs::read(&path).unwrap();

        let cut = dir.path().join("cut.jpg");
        std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).unwrap();
        let mut source = open(&cut, 1 << 30).unwrap();
        let err = read_all(source.as_mut()).unwrap_err();
        match &err {
            TilerError::DecodeRow { row, message, .. } => {
                assert!(*row > 0 && *row < h as u64, "{err}");
                assert!(message.contains("ends early"), "{err}");
            }
            other => panic!("unexpected {other}"),
        }
        assert!(err.to_string().contains("cut.jpg"), "{err}");
        // Later rows keep failing instead of returning garbage.
        let mut row = vec![0u8; w as usize * 3];
        assert!(source.read_row(&mut row).is_err());

        // Only the EOI marker missing: every pixel's data is there, so it decodes in full.
        let whole = read_all(open(&path, 1 << 30).unwrap().as_mut()).unwrap();
        for keep in [bytes.len() - 2, bytes.len() - 1] {
            std::fs::write(&cut, &bytes[..keep]).unwrap();
            assert_eq!(read_all(open(&cut, 1 << 30).unwrap().as_mut()).unwrap(), whole, "cut to {keep}");
        }
        // Cut anywhere before that, in the image data or the header: always an error, and one
        // that says the file ends early once the cut is in the image data.
        for options in [PLAIN, Options { sampling: SamplingFactor::F_2_1, restart: Some(2), ..PLAIN }] {
            let (w, h) = (72, 56);
            write_jpeg(&cut, &pattern(w, h, 3), w, h, Jc::Rgb, &options);
            let bytes = std::fs::read(&cut).unwrap();
            let data_start = bytes.windows(2).position(|m| m == [0xFF, 0xDA]).unwrap() + 14;
            for keep in (0..bytes.len() - 2).rev().step_by(11).chain([data_start, 300, 20, 3]) {
                std::fs::write(&cut, &bytes[..keep]).unwrap();
                let err = open(&cut, 1 << 30).and_then(|mut s| read_all(s.as_mut())).err();
                let err = err.unwrap_or_else(|| panic!("file cut to {keep} of {} bytes decoded", bytes.len()));
                assert!(err.to_string().contains("cut.jpg"), "{err}");
                if keep >= data_start {
                    assert!(matches!(err, TilerError::DecodeRow { .. }), "{err}");
                    assert!(err.to_string().contains("ends early"), "cut to {keep}: {err}");
                }
            }
        }

        // A marker in the middle of the entropy-coded data (a byte flipped to 0xFF 0xD9 ...).
        let mut damaged = bytes.clone();
        let middle = damaged.len() / 2;
        damaged[middle] = 0xFF;
        damaged[middle + 1] = 0xD9;
        let path = dir.path().join("damaged.jpg");
        std::fs::write(&path, &damaged).unwrap();
        let mut source = open(&path, 1 << 30).unwrap();
        let err = read_all(source.as_mut()).unwrap_err();
        assert!(matches!(err, TilerError::DecodeRow { .. }), "{err}");
        assert!(err.to_string().contains("Corrupt JPEG data"), "{err}");

        // A truncated progressive file fails while opening (all scans are read up front).
        let path = dir.path().join("progressive-cut.jpg");
        write_jpeg(&path, &pattern(w, h, 3), w, h, Jc::Rgb, &Options { progressive: true, ..PLAIN });
        let bytes = std::fs::read(&path).unwrap();
        std::fs::write(&path, &bytes[..bytes.len() * 2 / 3]).unwrap();
        let err = open(&path, 1 << 30).err().unwrap();
        assert!(err.to_string().contains("Premature end of JPEG file"), "{err}");
        // Cut exactly between two scans: libjpeg itself would output the coarser image.
        let scans: Vec<usize> =
            bytes.windows(2).enumerate().filter(|(_, m)| *m == [0xFF, 0xDA]).map(|(i, _)| i).collect();
        assert!(scans.len() > 2);
        std::fs::write(&path, &bytes[..scans[scans.len() - 1]]).unwrap();
        let err = open(&path, 1 << 30).err().expect("a progressive JPEG missing its last scan must not decode");
        assert!(err.to_string().contains("Premature end of JPEG file"), "{err}");
    }

    #[test]
    fn cmyk_and_ycck_decode_to_rgb() {
        if !Path::new(crate::source::icc::DEFAULT_CMYK_PROFILE).is_file() {
            crate::skip_unless_ci("the CMYK test", "no default CMYK profile (apt-get install libgs-common)");
            return;
        }
        let dir = tempfile::tempdir().unwrap();
        let (w, h) = (32, 24);
        let mut decoded = Vec::new();
        for (name, colour) in [("cmyk", Jc::Cmyk), ("ycck", Jc::CmykAsYcck)] {
            let path = dir.path().join(format!("{name}.jpg"));
            write_jpeg(&path, &pattern(w, h, 4), w, h, colour, &PLAIN);
            let mut source = open(&path, 1 << 30).unwrap();
            assert_eq!(source.layout(), PixelLayout::new(Channels::Rgb, Depth::U8));
            assert!(source.describe().contains("CMYK") && source.describe().contains("sRGB"), "{}", source.describe());
            decoded.push(read_all(source.as_mut()).unwrap());
        }
        // The same CMYK texels stored two ways, quantised in different colour spaces: close on
        // average (a stored-inverted or swapped channel would be off by ~100), apart by tens of
        // levels at the pattern's hard edges, where K's ringing differs.
        let (a, b) = (&decoded[0], &decoded[1]);
        let mean = a.iter().zip(b).map(|(a, b)| a.abs_diff(*b) as f64).sum::<f64>() / a.len() as f64;
        assert!(mean < 3.0, "CMYK and YCCK differ by {mean} on average");
    }

    #[test]
    fn garbage_after_the_magic_is_an_error_not_a_panic() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("junk.jpg");
        std::fs::write(&path, b"\xff\xd8\xff\xe0 this is not really a JPEG at all, just text").unwrap();
        let err = open(&path, 1 << 30).err().unwrap();
        assert!(err.to_string().contains("junk.jpg"), "{err}");

        // A 12-bit frame header.
        let path = dir.path().join("twelve.jpg");
        std::fs::write(&path, b"\xff\xd8\xff\xc1\x00\x0b\x0c\x00\x10\x00\x10\x01\x01\x11\x00\xff\xd9").unwrap();
        let err = open(&path, 1 << 30).err().unwrap();
        assert!(err.to_string().contains("12-bit"), "{err}");
    }
}
