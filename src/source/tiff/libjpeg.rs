//! One JPEG stream held in memory (a TIFF tile or strip, its shared tables spliced in),
//! decoded through libjpeg-turbo with the colour space the TIFF declares.
//!
//! The `mozjpeg` crate's decompressor guesses the colour space from markers and component
//! ids, as libjpeg does for a standalone file; inside a TIFF the PhotometricInterpretation
//! says it instead (libtiff writes no JFIF or Adobe marker, and an RGB tile's components may
//! carry any ids), so this calls libjpeg directly to set `jpeg_color_space` before decoding,
//! as libtiff does. Errors unwind out of libjpeg through the error manager of
//! [`crate::source::jpeg`], corrupt-data warnings included, and are caught here.

use std::panic::{AssertUnwindSafe, catch_unwind};

use mozjpeg_sys::{J_COLOR_SPACE, jpeg_decompress_struct};

use crate::source::jpeg::unsupported_frame;
use crate::source::libjpeg::{error_manager, panic_message};

/// What a TIFF's JPEG tiles hold, by its PhotometricInterpretation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Colour {
    /// One component (BlackIsZero).
    Grey,
    /// Luma and chroma (YCbCr), converted to RGB as they are decoded (libtiff's JPEGCOLORMODE_RGB).
    YCbCr,
    /// Red, green and blue, as they are.
    Rgb,
}

impl Colour {
    pub(crate) fn components(self) -> usize {
        match self {
            Colour::Grey => 1,
            Colour::YCbCr | Colour::Rgb => 3,
        }
    }
}

/// The size a chunk's stream may declare: at least the texels it must deliver, at most the
/// chunk as the TIFF lays it out (tiles are padded to the full tile size; the last strip is
/// as tall as the rows left). Bounding it bounds what libjpeg allocates for a hostile header.
#[derive(Clone, Copy, Debug)]
pub(super) struct Extent {
    pub columns: usize,
    pub rows: usize,
    pub max_columns: usize,
    pub max_rows: usize,
}

/// Decodes the first `extent.rows` rows of `stream`, the first `extent.columns` texels of each,
/// into `out` (rows packed, `components` bytes per texel).
pub(super) fn decode(stream: &[u8], colour: Colour, extent: Extent, out: &mut [u8]) -> Result<(), String> {
    decode_scaled(stream, colour, extent, 1, out)
}

/// [`decode`] at 1/`denominator` of the size (1, 2, 4 or 8): libjpeg-turbo's scaled inverse
/// DCT makes each 8x8 block 4x4, 2x2 or 1x1 texels straight from its coefficients, which is
/// how libvips shrinks a JPEG on load. `out` holds `ceil(columns / d)` texels of each of the
/// first `ceil(rows / d)` rows.
pub(super) fn decode_scaled(
    stream: &[u8],
    colour: Colour,
    extent: Extent,
    denominator: u32,
    out: &mut [u8],
) -> Result<(), String> {
    if ![1, 2, 4, 8].contains(&denominator) {
        return Err(format!("internal: a JPEG is decoded at 1/1, 1/2, 1/4 or 1/8, not 1/{denominator}"));
    }
    let d = denominator as usize;
    let row_bytes = extent.columns.div_ceil(d) * colour.components();
    let rows = extent.rows.div_ceil(d);
    if out.len() != row_bytes * rows {
        return Err(format!("internal: {} bytes for {rows} rows of {row_bytes}", out.len()));
    }
    // A frame libjpeg-turbo here does not decode would fail as "damaged" data: say what it is.
    if let Some(kind) =
        crate::source::stored::read_header(stream).filter(|h| h.frame != 0).and_then(|h| unsupported_frame(h.frame))
    {
        return Err(format!(
            "{kind} JPEG, which is not supported (baseline and progressive Huffman-coded JPEG tiles are read); re-save the TIFF, e.g. with `vips tiffsave --compression jpeg`"
        ));
    }
    let mut err = Box::new(error_manager(false));
    // Boxed: libjpeg keeps pointers to the struct in its memory pools while it lives.
    let mut cinfo: Box<jpeg_decompress_struct> = Box::new(zeroed_cinfo());
    cinfo.common.err = &mut *err;
    let result = catch_unwind(AssertUnwindSafe(|| run(&mut cinfo, stream, colour, (extent, denominator), out)));
    destroy(&mut cinfo);
    match result {
        Ok(result) => result,
        Err(payload) => Err(format!("damaged JPEG data: {}", panic_message(payload))),
    }
}

#[expect(unsafe_code, reason = "libjpeg's C interface")]
fn zeroed_cinfo() -> jpeg_decompress_struct {
    // SAFETY: an all-zero jpeg_decompress_struct is what libjpeg's create function expects
    // (null pointers, zero counts); `jpeg_create_decompress` fills it in before any use.
    unsafe { std::mem::zeroed() }
}

#[expect(unsafe_code, reason = "libjpeg's C interface")]
fn destroy(cinfo: &mut jpeg_decompress_struct) {
    // SAFETY: valid after `jpeg_create_decompress`, also after an error unwound out of libjpeg
    // (as after libjpeg's usual longjmp); a struct never created has a null `mem`, which
    // `jpeg_destroy` checks, and its err still points at the live error manager.
    unsafe { mozjpeg_sys::jpeg_destroy_decompress(cinfo) };
}

#[expect(unsafe_code, reason = "libjpeg's C interface")]
fn run(
    cinfo: &mut jpeg_decompress_struct,
    stream: &[u8],
    colour: Colour,
    (extent, denominator): (Extent, u32),
    out: &mut [u8],
) -> Result<(), String> {
    // SAFETY: `cinfo` was zeroed, its `err` points at a live error manager whose
    // `error_exit` unwinds (caught by our caller), and `stream` outlives the decompressor,
    // which is destroyed before `decode` returns.
    unsafe {
        mozjpeg_sys::jpeg_create_decompress(cinfo);
        mozjpeg_sys::jpeg_mem_src(cinfo, stream.as_ptr(), stream.len() as _);
        if mozjpeg_sys::jpeg_read_header(cinfo, 1) != 1 {
            return Err("the stream holds no image".into());
        }
    }
    let (w, h, n) = (cinfo.image_width as usize, cinfo.image_height as usize, cinfo.num_components as usize);
    if n != colour.components() {
        return Err(format!("the JPEG stream has {n} components, the TIFF's {colour:?} needs {}", colour.components()));
    }
    if !(extent.columns..=extent.max_columns).contains(&w) || !(extent.rows..=extent.max_rows).contains(&h) {
        return Err(format!(
            "the JPEG stream is {w}x{h}, the TIFF's chunk is {}x{} with {}x{} texels in the image",
            extent.max_columns, extent.max_rows, extent.columns, extent.rows
        ));
    }
    (cinfo.jpeg_color_space, cinfo.out_color_space) = match colour {
        Colour::Grey => (J_COLOR_SPACE::JCS_GRAYSCALE, J_COLOR_SPACE::JCS_GRAYSCALE),
        Colour::YCbCr => (J_COLOR_SPACE::JCS_YCbCr, J_COLOR_SPACE::JCS_RGB),
        Colour::Rgb => (J_COLOR_SPACE::JCS_RGB, J_COLOR_SPACE::JCS_RGB),
    };
    (cinfo.scale_num, cinfo.scale_denom) = (1, denominator);
    // SAFETY: as above; the header has been read.
    unsafe { mozjpeg_sys::jpeg_start_decompress(cinfo) };
    // libjpeg rounds a scaled size up, as `ceil(w / d)`.
    let (out_w, d) = (cinfo.output_width as usize, denominator as usize);
    if out_w != w.div_ceil(d) || cinfo.output_components as usize != n {
        return Err(format!("internal: libjpeg decodes {w} columns at 1/{d} into {out_w} of {} samples", n));
    }
    let row_bytes = extent.columns.div_ceil(d) * n;
    let mut scanline = vec![0u8; out_w * n];
    for row in out.chunks_exact_mut(row_bytes) {
        let mut at = scanline.as_mut_ptr();
        // SAFETY: `at` points at one writable row of `output_width` x `output_components`
        // bytes (checked above: the output has as many components as the input).
        let got = unsafe { mozjpeg_sys::jpeg_read_scanlines(cinfo, &mut at, 1) };
        if got != 1 {
            return Err(format!("libjpeg stopped at row {}", cinfo.output_scanline));
        }
        row.copy_from_slice(&scanline[..row_bytes]);
    }
    Ok(())
}

/// A chunk's complete JPEG stream: the shared tables (JPEGTables without its SOI and EOI, or
/// nothing) spliced in after the chunk's SOI.
pub(super) fn splice(tables: &[u8], chunk: &[u8], stream: &mut Vec<u8>) -> Result<(), String> {
    if !chunk.starts_with(&[0xFF, 0xD8]) {
        return Err("the data does not start with a JPEG SOI marker".into());
    }
    stream.clear();
    stream.reserve(tables.len() + chunk.len());
    stream.extend_from_slice(&chunk[..2]);
    stream.extend_from_slice(tables);
    stream.extend_from_slice(&chunk[2..]);
    Ok(())
}

/// The marker segments of a JPEGTables tag value (an abbreviated table-specification
/// stream: SOI, tables, EOI), without its SOI and EOI.
pub(super) fn tables_body(tables: &[u8]) -> Option<&[u8]> {
    let body = tables.strip_prefix(&[0xFF, 0xD8])?;
    Some(body.strip_suffix(&[0xFF, 0xD9]).unwrap_or(body))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Lossless and arithmetic-coded tiles are named as what they are, with their SOF marker,
    /// not as damaged data.
    #[test]
    fn unsupported_frames_are_named_with_their_marker() {
        let mut stream = Vec::new();
        let texels = vec![128u8; 16 * 16 * 3];
        jpeg_encoder::Encoder::new(&mut stream, 90).encode(&texels, 16, 16, jpeg_encoder::ColorType::Rgb).unwrap();
        let sof = stream.windows(2).position(|w| w == [0xFF, 0xC0]).expect("a baseline frame");
        let extent = Extent { columns: 16, rows: 16, max_columns: 16, max_rows: 16 };
        let mut out = vec![0u8; 16 * 16 * 3];
        assert_eq!(decode(&stream, Colour::YCbCr, extent, &mut out), Ok(()));
        for (marker, says) in [
            (0xC9, "arithmetic-coded (SOF9, marker 0xFFC9) JPEG, which is not supported"),
            (0xC3, "lossless (SOF3, marker 0xFFC3) JPEG, which is not supported"),
        ] {
            stream[sof + 1] = marker;
            let e = decode(&stream, Colour::YCbCr, extent, &mut out).unwrap_err();
            assert!(e.starts_with(says) && !e.contains("damaged"), "{e}");
        }
    }
}
