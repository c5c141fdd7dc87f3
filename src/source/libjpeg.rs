//! libjpeg-turbo's errors as Rust: the one error manager every libjpeg call of the sources
//! uses (whole JPEG files, JPEG-in-TIFF tiles, stored tiles cropped losslessly). Fatal errors
//! and warnings that mean lost pixels unwind with libjpeg's message, which the caller catches
//! at its call into libjpeg and turns into an error naming the file or tile.

use std::cell::Cell;
use std::ffi::c_int;
use std::panic::resume_unwind;

use mozjpeg_sys::{jpeg_common_struct, jpeg_error_mgr};

/// libjpeg's standard error manager with two methods replaced: fatal errors and corrupt-data
/// warnings both unwind with the formatted message.
/// `multi_scan`: whether the image may have several scans (progressive, or not known).
#[expect(unsafe_code, reason = "libjpeg's C interface")]
pub(super) fn error_manager(multi_scan: bool) -> jpeg_error_mgr {
    // SAFETY: `jpeg_std_error` fills in every field of the zeroed struct (method pointers and
    // pointers to libjpeg's static message tables); the struct holds no pointer to itself, so it
    // may be moved afterwards.
    let mut err: jpeg_error_mgr = unsafe { std::mem::zeroed() };
    // SAFETY: `err` is a valid, writable error manager for libjpeg to fill in.
    unsafe { mozjpeg_sys::jpeg_std_error(&mut err) };
    err.error_exit = Some(unwind_on_error);
    err.emit_message = Some(if multi_scan { warn_multi_scan } else { warn_single_scan });
    err
}

extern "C-unwind" fn unwind_on_error(cinfo: &mut jpeg_common_struct) {
    let message = format_message(cinfo);
    // `resume_unwind` rather than `panic!`: no panic hook, no message on stderr.
    resume_unwind(Box::new(message));
}

thread_local! {
    /// Set when libjpeg reaches the end of the file during the current call, which explains a
    /// later "premature end of data segment". Callbacks run on the thread that called into
    /// libjpeg, so a thread-local reset before each call is private to that call.
    pub(super) static HIT_EOF: Cell<bool> = const { Cell::new(false) };
}

/// Warnings that do not mean lost pixels: libjpeg decodes the image exactly as intended.
/// (Extraneous bytes can only sit between marker segments, never inside entropy-coded data,
/// which runs up to the next marker.) Everything else (bad Huffman code, premature end of data
/// segment, missing restart marker, inconsistent progression, ...) replaces data with guesses.
const HARMLESS: [c_int; 6] = [
    mozjpeg_sys::JWRN_ADOBE_XFORM,
    mozjpeg_sys::JWRN_EXTRANEOUS_DATA,
    mozjpeg_sys::JWRN_JFIF_MAJOR,
    mozjpeg_sys::JWRN_NOT_SEQUENTIAL,
    mozjpeg_sys::JWRN_TOO_MUCH_DATA,
    mozjpeg_sys::JWRN_BOGUS_ICC,
];

/// `emit_message` for single-scan images. `msg_level` -1 is a corrupt-data warning; 0 and up
/// are trace messages (ignored).
///
/// "Premature end of JPEG file" is not fatal by itself here: libjpeg's Huffman decoder reads
/// a few bytes ahead, so a file that lacks only its final EOI marker reaches the end of the
/// file with every pixel's data read. libjpeg then supplies an EOI marker, and if any block
/// still needs data it warns "premature end of data segment", which *is* fatal: a file cut
/// anywhere in its image data fails at the row where data runs out.
#[expect(unsafe_code, reason = "libjpeg's C interface")]
extern "C-unwind" fn warn_single_scan(cinfo: &mut jpeg_common_struct, msg_level: c_int) {
    if msg_level >= 0 {
        return;
    }
    // SAFETY: libjpeg calls this with `cinfo.err` pointing at our live error manager.
    let code = unsafe { (*cinfo.err).msg_code };
    if code == mozjpeg_sys::JWRN_JPEG_EOF {
        HIT_EOF.with(|eof| eof.set(true));
        return;
    }
    if !HARMLESS.contains(&code) {
        unwind_on_error(cinfo);
    }
}

/// `emit_message` for multi-scan images: all scans are read before the first row, and a file
/// cut between two scans ends without any other warning (libjpeg outputs the coarser image of
/// the scans it got), so the end of the file is fatal too.
#[expect(unsafe_code, reason = "libjpeg's C interface")]
extern "C-unwind" fn warn_multi_scan(cinfo: &mut jpeg_common_struct, msg_level: c_int) {
    if msg_level >= 0 {
        return;
    }
    // SAFETY: as above.
    let code = unsafe { (*cinfo.err).msg_code };
    if !HARMLESS.contains(&code) {
        unwind_on_error(cinfo);
    }
}

#[expect(unsafe_code, reason = "libjpeg's C interface")]
fn format_message(cinfo: &mut jpeg_common_struct) -> String {
    // libjpeg writes at most JMSG_LENGTH_MAX (200) bytes including the NUL.
    let mut buffer = [0u8; 256];
    // SAFETY: `cinfo.err` points at our live error manager. The binding declares the buffer as
    // `&[u8; 80]`, shorter than libjpeg's 200-byte maximum, so the function is called through a
    // pointer-typed signature (same ABI) with a large enough buffer.
    unsafe {
        let Some(format) = (*cinfo.err).format_message else {
            return format!("libjpeg error {}", (*cinfo.err).msg_code);
        };
        let format: unsafe extern "C-unwind" fn(&mut jpeg_common_struct, *mut u8) = std::mem::transmute(format);
        format(cinfo, buffer.as_mut_ptr());
    }
    let end = buffer.iter().position(|&b| b == 0).unwrap_or(buffer.len());
    String::from_utf8_lossy(&buffer[..end]).into_owned()
}

pub(super) fn panic_message(payload: Box<dyn std::any::Any + Send>) -> String {
    match payload.downcast::<String>() {
        Ok(s) => *s,
        Err(payload) => match payload.downcast::<&'static str>() {
            Ok(s) => (*s).to_string(),
            Err(_) => "libjpeg failed".to_string(),
        },
    }
}
