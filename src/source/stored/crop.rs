//! Cropping a stored JPEG tile to its top-left `width x height` texels without decoding it:
//! what `jpegtran -crop WxH+0+0` does. The DCT coefficients are read and written back under
//! a smaller image size; the blocks past it are dropped, the ones kept are the same numbers, so
//! a decoder reconstructs the same texels (libjpeg's `jpeg_read_coefficients` /
//! `jpeg_write_coefficients`, through mozjpeg-sys).
//!
//! An edge page of a Deep Zoom, IIIF or XYZ output is the top-left part of a stored tile that
//! reaches past the image, and its top-left corner is on the block grid; so it can be copied
//! this way. What the crop cannot keep is chroma upsampling's view of the samples past the new
//! edge: see [`exact`].

use std::panic::{AssertUnwindSafe, catch_unwind};

use mozjpeg_sys::{
    J_INT_PARAM, JINT_COMPRESS_PROFILE_VALUE, boolean, jpeg_compress_struct, jpeg_decompress_struct,
    jpeg_destination_mgr,
};

use super::Header;
use crate::source::libjpeg::{error_manager, panic_message};

/// Whether the top-left `crop` of a stored tile of `full` texels, cropped in the DCT domain,
/// decodes to exactly the texels decoding the whole tile gives there.
///
/// Where every component has the same sampling factors (4:4:4, RGB, grey), yes: each texel
/// is its own blocks' samples. With chroma subsampled by 2 (4:2:0, 4:2:2), libjpeg-turbo's
/// default ("fancy") upsampling blends each odd column's texel with the chroma sample to its
/// right (each even one's with the sample to its left), and at a new right edge after an even
/// width that sample is gone: libjpeg repeats the last one instead, so the last column can
/// differ (likewise the last row after an even height). After an odd width the last column
/// blends leftwards only, and is exact. A chroma row of 1 or 2 samples (a width of 4 or less)
/// is upsampled by plain replication, unlike the whole tile's, so such narrow crops are not
/// exact either. Other factors are not copied. The tests try every size.
pub fn exact(header: &Header, full: (u32, u32), (width, height): (u32, u32)) -> bool {
    let (max_h, max_v) = header.sampling.iter().fold((1, 1), |(h, v), &(ch, cv)| (h.max(ch), v.max(cv)));
    let mut halved = (false, false);
    for &(h, v) in &header.sampling {
        for (factor, max, half) in [(h, max_h, &mut halved.0), (v, max_v, &mut halved.1)] {
            if factor * 2 == max {
                *half = true;
            } else if factor != max {
                return false;
            }
        }
    }
    let across = !halved.0 || width == full.0 || (width % 2 == 1 && width >= 5);
    let down = !halved.1 || height == full.1 || height % 2 == 1;
    across && down
}

/// `file` (a complete baseline or progressive JPEG file) cropped to its top-left
/// `width x height` texels, as a baseline JPEG file with Huffman tables fitted to it: every
/// viewer opens it. The colour-space marker (JFIF or Adobe) is what libjpeg writes for the
/// file's colour space, as the stored file had. An error says what libjpeg found wrong.
pub fn crop(file: &[u8], (width, height): (u32, u32)) -> Result<Vec<u8>, String> {
    let mut src_err = Box::new(error_manager(false));
    let mut dst_err = Box::new(error_manager(false));
    // Boxed: libjpeg keeps pointers to the structs in its memory pools while they live.
    let mut src: Box<jpeg_decompress_struct> = Box::new(zeroed());
    let mut dst: Box<jpeg_compress_struct> = Box::new(zeroed());
    let mut out = Box::new(VecDestination::new());
    src.common.err = &mut *src_err;
    dst.common.err = &mut *dst_err;
    let result = catch_unwind(AssertUnwindSafe(|| transcode(&mut src, &mut dst, &mut out, file, (width, height))));
    destroy(&mut src, &mut dst);
    match result {
        Ok(Ok(())) => Ok(std::mem::take(&mut out.bytes)),
        Ok(Err(message)) => Err(message),
        Err(payload) => Err(format!("damaged JPEG data: {}", panic_message(payload))),
    }
}

#[expect(unsafe_code, reason = "libjpeg's C interface")]
fn zeroed<S>() -> S {
    // SAFETY: only used for libjpeg's (de)compress structs, for which all-zero is what the
    // create functions expect (null pointers, zero counts); they fill them in before any use.
    unsafe { std::mem::zeroed() }
}

#[expect(unsafe_code, reason = "libjpeg's C interface")]
fn destroy(src: &mut jpeg_decompress_struct, dst: &mut jpeg_compress_struct) {
    // SAFETY: each is valid after its create call, also after an error unwound out of libjpeg;
    // one never created has a null `mem`, which `jpeg_destroy` checks. The compressor goes
    // first: it may point at the decompressor's coefficient arrays.
    unsafe {
        mozjpeg_sys::jpeg_destroy_compress(dst);
        mozjpeg_sys::jpeg_destroy_decompress(src);
    }
}

#[expect(unsafe_code, reason = "libjpeg's C interface")]
fn transcode(
    src: &mut jpeg_decompress_struct,
    dst: &mut jpeg_compress_struct,
    out: &mut VecDestination,
    file: &[u8],
    (width, height): (u32, u32),
) -> Result<(), String> {
    // SAFETY: both structs were zeroed and point at live error managers whose `error_exit`
    // unwinds (caught by our caller); `file` and `out` outlive both, which are destroyed before
    // `crop` returns.
    unsafe {
        mozjpeg_sys::jpeg_create_decompress(src);
        mozjpeg_sys::jpeg_mem_src(src, file.as_ptr(), file.len() as _);
        if mozjpeg_sys::jpeg_read_header(src, 1) != 1 {
            return Err("the file holds no image".into());
        }
    }
    if width == 0 || height == 0 || width > src.image_width || height > src.image_height {
        return Err(format!("cannot crop a {}x{} JPEG to {width}x{height}", src.image_width, src.image_height));
    }
    // SAFETY: as above. mozjpeg's default profile would make the copy progressive with
    // trellis-optimised scans; `JCP_FASTEST` is libjpeg-turbo's defaults, which
    // `jpeg_copy_critical_parameters` (it calls `jpeg_set_defaults`) then applies: one
    // baseline scan. The coefficient arrays are the whole tile's; the compressor reads only the
    // blocks within the smaller size (jpegtran hands them on the same way for a crop at 0,0).
    unsafe {
        let coefficients = mozjpeg_sys::jpeg_read_coefficients(src);
        mozjpeg_sys::jpeg_create_compress(dst);
        let profile = JINT_COMPRESS_PROFILE_VALUE::JCP_FASTEST as i32;
        mozjpeg_sys::jpeg_c_set_int_param(dst, J_INT_PARAM::JINT_COMPRESS_PROFILE, profile);
        mozjpeg_sys::jpeg_copy_critical_parameters(src, dst);
        (dst.image_width, dst.image_height) = (width, height);
        // Huffman tables fitted to the data (still baseline): smaller files, as `jpegtran
        // -optimize` makes.
        dst.optimize_coding = 1;
        (dst.scan_info, dst.num_scans) = (std::ptr::null(), 0);
        // A pointer to the whole struct, whose first field is the manager: the callbacks reach
        // `bytes` through it.
        dst.dest = std::ptr::from_mut(out).cast();
        mozjpeg_sys::jpeg_write_coefficients(dst, coefficients);
        mozjpeg_sys::jpeg_finish_compress(dst);
        mozjpeg_sys::jpeg_finish_decompress(src);
    }
    Ok(())
}

/// A libjpeg destination that grows a `Vec`. `manager` comes first, so that the pointer libjpeg
/// holds to it is a pointer to the whole struct.
#[repr(C)]
struct VecDestination {
    manager: jpeg_destination_mgr,
    bytes: Vec<u8>,
}

/// The first buffer: a cropped tile of a few tens of KiB takes a few doublings.
const FIRST_BUFFER: usize = 16 << 10;

impl VecDestination {
    fn new() -> VecDestination {
        let manager = jpeg_destination_mgr {
            next_output_byte: std::ptr::null_mut(),
            free_in_buffer: 0,
            init_destination: Some(init_destination),
            empty_output_buffer: Some(empty_output_buffer),
            term_destination: Some(term_destination),
        };
        VecDestination { manager, bytes: Vec::new() }
    }

    /// Makes the bytes from `used` on the buffer libjpeg writes into.
    fn hand_out(&mut self, used: usize) {
        // Written bytes are kept; the rest is room, zeroed so that the Vec holds no undefined bytes.
        self.bytes.resize((2 * used).max(FIRST_BUFFER), 0);
        self.manager.next_output_byte = self.bytes[used..].as_mut_ptr();
        self.manager.free_in_buffer = self.bytes.len() - used;
    }
}

#[expect(unsafe_code, reason = "libjpeg's C interface")]
fn destination(cinfo: &mut jpeg_compress_struct) -> &mut VecDestination {
    // SAFETY: `dest` points at a live `VecDestination` (repr(C), the manager first), set by
    // `transcode`; libjpeg calls back on the thread that called it, holding no other
    // reference to it.
    unsafe { &mut *(cinfo.dest as *mut VecDestination) }
}

extern "C-unwind" fn init_destination(cinfo: &mut jpeg_compress_struct) {
    destination(cinfo).hand_out(0);
}

/// libjpeg calls this when the buffer is full: all of it is written.
extern "C-unwind" fn empty_output_buffer(cinfo: &mut jpeg_compress_struct) -> boolean {
    let out = destination(cinfo);
    let used = out.bytes.len();
    out.hand_out(used);
    1
}

extern "C-unwind" fn term_destination(cinfo: &mut jpeg_compress_struct) {
    let out = destination(cinfo);
    let written = out.bytes.len() - out.manager.free_in_buffer;
    out.bytes.truncate(written);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::source::stored::read_header;

    /// A `w x h` tile of smooth ramps and noise (chroma that changes from texel to texel, so that
    /// upsampling's neighbours matter), as a JPEG at Q90 with chroma at `sampling` pixels per sample.
    fn tile(w: u32, h: u32, sampling: (u8, u8), seed: u32) -> Vec<u8> {
        let mut state = seed;
        let texels: Vec<u8> = (0..w * h)
            .flat_map(|i| {
                state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                let (x, y, noise) = (i % w, i / w, (state >> 24) as u8 / 3);
                [(x * 7) as u8 ^ noise, (y * 5) as u8, ((x + y) * 3) as u8 ^ noise.rotate_left(3)]
            })
            .collect();
        let mut c = mozjpeg::Compress::new(mozjpeg::ColorSpace::JCS_RGB);
        c.set_size(w as usize, h as usize);
        c.set_quality(90.0);
        c.set_chroma_sampling_pixel_sizes(sampling, sampling);
        let mut c = c.start_compress(Vec::new()).unwrap();
        c.write_scanlines(&texels).unwrap();
        c.finish().unwrap()
    }

    /// What our JPEG decoder (libjpeg-turbo through the `mozjpeg` crate, as the JPEG source
    /// reads) makes of `file`: width, height, RGB texels.
    fn decode(file: &[u8]) -> (u32, u32, Vec<u8>) {
        let d = mozjpeg::Decompress::new_mem(file).unwrap();
        let mut d = d.rgb().unwrap();
        let (w, h) = (d.width() as u32, d.height() as u32);
        let texels: Vec<u8> = d.read_scanlines().unwrap();
        d.finish().unwrap();
        (w, h, texels)
    }

    fn top_left(texels: &[u8], full_w: u32, (w, h): (u32, u32)) -> Vec<u8> {
        (0..h).flat_map(|y| &texels[(y * full_w * 3) as usize..][..(w * 3) as usize]).copied().collect()
    }

    /// Every crop of a 4:4:4 tile, single texels and sizes off the 8-texel grid included, decodes
    /// to the whole tile's texels there, exactly; the copy is one baseline scan.
    #[test]
    fn crops_of_full_chroma_are_exact() {
        let file = tile(40, 24, (1, 1), 7);
        let (_, _, whole) = decode(&file);
        let header = read_header(&file).unwrap();
        for (w, h) in [(1, 1), (1, 24), (40, 1), (9, 17), (33, 5), (40, 23), (39, 24), (8, 8), (16, 16)] {
            assert!(exact(&header, (40, 24), (w, h)));
            let cropped = crop(&file, (w, h)).unwrap();
            let h2 = read_header(&cropped).unwrap();
            assert_eq!((h2.frame, h2.width as u32, h2.height as u32), (0xC0, w, h), "{w}x{h}: baseline");
            assert!(h2.jfif, "{w}x{h}: a JFIF marker for YCbCr");
            assert_eq!(decode(&cropped), (w, h, top_left(&whole, 40, (w, h))), "{w}x{h}");
        }
    }

    /// 4:2:0 and 4:2:2: every crop `exact` calls exact is, for each width and height up to the
    /// tile's; and some it declines are not (the last column or row differs), which is why.
    #[test]
    fn subsampled_crops_are_exact_where_said() {
        for sampling in [(2, 2), (2, 1)] {
            let file = tile(34, 20, sampling, 11);
            let (_, _, whole) = decode(&file);
            let header = read_header(&file).unwrap();
            let mut differ = 0;
            for w in 1..=34 {
                for h in 1..=20 {
                    let same = decode(&crop(&file, (w, h)).unwrap()).2 == top_left(&whole, 34, (w, h));
                    if exact(&header, (34, 20), (w, h)) {
                        assert!(same, "{sampling:?} {w}x{h}: said exact, decodes otherwise");
                    }
                    differ += !same as u32;
                }
            }
            assert!(differ > 0, "{sampling:?}: no crop differs, so none need be declined");
        }
    }

    #[test]
    fn damaged_data_and_bad_sizes_are_errors() {
        let file = tile(16, 16, (2, 2), 3);
        assert!(crop(&file, (17, 4)).unwrap_err().contains("16x16"));
        assert!(crop(&file, (0, 4)).is_err());
        assert!(crop(&file[..file.len() / 2], (8, 8)).is_err());
        assert!(crop(b"not a jpeg", (8, 8)).is_err());
    }
}
