//! Encoding: texels into a JPEG XL file (lossy at a distance, or lossless), and a JPEG file
//! into a JPEG XL file that gives the same JPEG back byte for byte.
//!
//! One libjxl encoder per call, owned by a guard that destroys it on every path, single
//! threaded: the tiler encodes many small tiles at once, one per thread of its pool.

#![expect(unsafe_code, reason = "libjxl's C interface")]

use std::ffi::c_void;
use std::ops::RangeInclusive;
use std::ptr;

use crate::Error;
use crate::ffi;

/// Interleaved samples, rows top down: 8-bit, or 16-bit in native byte order.
#[derive(Clone, Copy, Debug)]
pub enum Pixels<'a> {
    /// 8 bits a sample.
    U8(&'a [u8]),
    /// 16 bits a sample.
    U16(&'a [u16]),
}

/// An image to encode: `channels` is 1 (grey), 2 (grey + alpha), 3 (RGB) or 4 (RGBA), the
/// colour sRGB, alpha straight.
#[derive(Clone, Copy, Debug)]
pub struct Image<'a> {
    /// Texels across.
    pub width: u32,
    /// Texels down.
    pub height: u32,
    /// Samples a texel.
    pub channels: u32,
    /// `width x height x channels` samples.
    pub pixels: Pixels<'a>,
}

/// What the encoder may lose.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Quality {
    /// Every sample kept exactly (modular mode).
    Lossless,
    /// Lossy (VarDCT) at this Butteraugli distance: 1.0 is "visually lossless" (libjxl's
    /// default), larger is smaller and worse; [`Quality::DISTANCES`] holds the accepted ones.
    Distance(f32),
}

impl Quality {
    /// The distances libjxl accepts for lossy encoding.
    pub const DISTANCES: RangeInclusive<f32> = 0.01..=25.0;
}

/// The Butteraugli distance a JPEG-like `quality` (1 to 100) stands for, as libjxl's `cjxl
/// --quality` maps it: `0.1 + (100 - q) x 0.09` from 30 up (90 gives 1.0, 85 gives 1.45),
/// a parabola below (`53 q^2 / 3000 - 23 q / 20 + 25`, 1 gives 23.9), continuous at 30.
/// Unlike cjxl, 100 gives 0.1, not lossless: lossless is [`Quality::Lossless`].
pub fn distance_for_quality(quality: u8) -> f32 {
    let q = f32::from(quality.clamp(1, 100));
    if q >= 30.0 { 0.1 + (100.0 - q) * 0.09 } else { 53.0 / 3000.0 * q * q - 23.0 / 20.0 * q + 25.0 }
}

/// Encoder effort, 1 (fastest) to 9 (smallest files, slowest): libjxl's speed/size trade-off,
/// never what is kept or lost.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Effort(u8);

impl Effort {
    /// The efforts libjxl 0.7 has.
    pub const RANGE: RangeInclusive<u8> = 1..=9;

    /// `effort`, if libjxl has it.
    pub fn new(effort: u8) -> Result<Effort, Error> {
        match Effort::RANGE.contains(&effort) {
            true => Ok(Effort(effort)),
            false => Err(Error::Input(format!("JPEG XL effort {effort} is outside 1..=9"))),
        }
    }

    /// `effort` brought into 1..=9 (for constants; [`Effort::new`] refuses what is outside).
    pub const fn clamped(effort: u8) -> Effort {
        match effort {
            0 => Effort(1),
            1..=9 => Effort(effort),
            _ => Effort(9),
        }
    }

    /// The number, 1 to 9.
    pub fn get(self) -> u8 {
        self.0
    }
}

/// Encodes `image` as one JPEG XL file (a bare codestream) at `quality` and `effort`.
pub fn encode(image: &Image, quality: Quality, effort: Effort) -> Result<Vec<u8>, Error> {
    let (bits, data_type, bytes, data) = check(image)?;
    if let Quality::Distance(d) = quality
        && !Quality::DISTANCES.contains(&d)
    {
        return Err(Error::Input(format!("JPEG XL distance {d} is outside 0.01..=25")));
    }
    let lossless = quality == Quality::Lossless;
    let enc = Encoder::new()?;
    let mut info = ffi::JxlBasicInfo::zeroed();
    // SAFETY: `info` is a valid, writable JxlBasicInfo of libjxl 0.7's layout (tested in ffi).
    unsafe { ffi::JxlEncoderInitBasicInfo(&mut info) };
    let alpha = image.channels.is_multiple_of(2);
    info.xsize = image.width;
    info.ysize = image.height;
    info.bits_per_sample = bits;
    info.num_color_channels = if image.channels <= 2 { 1 } else { 3 };
    info.num_extra_channels = u32::from(alpha);
    info.alpha_bits = if alpha { bits } else { 0 };
    // Lossless keeps the samples as given; lossy codes in libjxl's XYB space.
    info.uses_original_profile = if lossless { ffi::JXL_TRUE } else { ffi::JXL_FALSE };
    // SAFETY: `enc.0` is a live encoder; `info` is initialised and only read during the call.
    enc.check(unsafe { ffi::JxlEncoderSetBasicInfo(enc.0, &info) }, "JxlEncoderSetBasicInfo")?;
    let mut colour = ffi::JxlColorEncoding::default();
    let grey = if image.channels <= 2 { ffi::JXL_TRUE } else { ffi::JXL_FALSE };
    // SAFETY: `colour` is a valid, writable JxlColorEncoding.
    unsafe { ffi::JxlColorEncodingSetToSRGB(&mut colour, grey) };
    // SAFETY: `enc.0` is live; `colour` is initialised and only read.
    enc.check(unsafe { ffi::JxlEncoderSetColorEncoding(enc.0, &colour) }, "JxlEncoderSetColorEncoding")?;
    let settings = enc.frame_settings(effort)?;
    let set = match quality {
        // SAFETY: `settings` belongs to the live encoder `enc`.
        Quality::Lossless => unsafe { ffi::JxlEncoderSetFrameLossless(settings, ffi::JXL_TRUE) },
        // SAFETY: as above.
        Quality::Distance(d) => unsafe { ffi::JxlEncoderSetFrameDistance(settings, d) },
    };
    enc.check(set, "setting the distance")?;
    let format =
        ffi::JxlPixelFormat { num_channels: image.channels, data_type, endianness: ffi::JXL_NATIVE_ENDIAN, align: 0 };
    // SAFETY: `data` points at `bytes` readable bytes (checked against the image's size in
    // `check`), which libjxl copies before returning; `format` is only read.
    let added = unsafe { ffi::JxlEncoderAddImageFrame(settings, &format, data, bytes) };
    enc.check(added, "JxlEncoderAddImageFrame")?;
    enc.finish(bytes / 4 + 4096, most_encoded_bytes(bytes))
}

/// The most bytes [`encode`] writes for an image of `raw` bytes of samples: larger output is
/// an [`Error::Encoder`] (lossless files of noise come close to the samples' size; lossy ones
/// at the smallest distance up to some 1.5 times it).
pub fn most_encoded_bytes(raw: usize) -> usize {
    raw.saturating_mul(2).saturating_add(64 << 10)
}

/// `jpeg`, a JPEG file, recompressed losslessly into JPEG XL (its DCT coefficients coded
/// anew, plus the data to rebuild the file): `djxl` or any full decoder gives the same JPEG
/// back byte for byte, and a JPEG XL viewer shows it as it is.
pub fn recompress_jpeg(jpeg: &[u8], effort: Effort) -> Result<Vec<u8>, Error> {
    if !jpeg.starts_with(&[0xFF, 0xD8]) {
        return Err(Error::Input("the bytes to recompress are not a JPEG file (no SOI marker)".into()));
    }
    let enc = Encoder::new()?;
    // SAFETY: `enc.0` is a live encoder that has not started encoding.
    enc.check(unsafe { ffi::JxlEncoderStoreJPEGMetadata(enc.0, ffi::JXL_TRUE) }, "JxlEncoderStoreJPEGMetadata")?;
    let settings = enc.frame_settings(effort)?;
    // SAFETY: `jpeg` is `jpeg.len()` readable bytes, copied by libjxl before it returns.
    let added = unsafe { ffi::JxlEncoderAddJPEGFrame(settings, jpeg.as_ptr(), jpeg.len()) };
    if added != ffi::JXL_ENC_SUCCESS {
        return Err(Error::JpegRecompression { step: "JxlEncoderAddJPEGFrame", reason: enc.reason() });
    }
    enc.finish(jpeg.len() + 4096, most_encoded_bytes(jpeg.len())).map_err(|e| match e {
        Error::Encoder { step, reason } => Error::JpegRecompression { step, reason },
        other => other,
    })
}

/// The image's bits a sample, libjxl's data type, its length in bytes and a pointer to it,
/// once its counts agree.
fn check(image: &Image) -> Result<(u32, i32, usize, *const c_void), Error> {
    let (width, height, channels) = (image.width, image.height, image.channels);
    if width == 0 || height == 0 || !(1..=4).contains(&channels) {
        return Err(Error::Input(format!(
            "a {width}x{height} image of {channels} channels: JPEG XL tiles need a size and 1 to 4 channels"
        )));
    }
    let samples = (width as usize).checked_mul(height as usize).and_then(|n| n.checked_mul(channels as usize));
    let (given, bits, data_type, bytes, data) = match image.pixels {
        Pixels::U8(s) => (s.len(), 8, ffi::JXL_TYPE_UINT8, s.len(), s.as_ptr().cast()),
        Pixels::U16(s) => (s.len(), 16, ffi::JXL_TYPE_UINT16, size_of_val(s), s.as_ptr().cast()),
    };
    if samples != Some(given) {
        return Err(Error::Input(format!(
            "a {width}x{height} image of {channels} channels has {} samples, not {given}",
            samples.map_or("too many".into(), |n| n.to_string())
        )));
    }
    Ok((bits, data_type, bytes, data))
}

/// A libjxl encoder, destroyed when dropped.
struct Encoder(*mut ffi::JxlEncoder);

impl Encoder {
    fn new() -> Result<Encoder, Error> {
        // SAFETY: a null memory manager asks for libjxl's default allocator.
        let enc = unsafe { ffi::JxlEncoderCreate(ptr::null()) };
        match enc.is_null() {
            true => Err(Error::OutOfMemory("encoder")),
            false => Ok(Encoder(enc)),
        }
    }

    /// A frame's settings at `effort`, owned by the encoder (freed with it).
    fn frame_settings(&self, effort: Effort) -> Result<*mut ffi::JxlEncoderFrameSettings, Error> {
        // SAFETY: `self.0` is live; a null source asks for the defaults.
        let settings = unsafe { ffi::JxlEncoderFrameSettingsCreate(self.0, ptr::null()) };
        if settings.is_null() {
            return Err(Error::OutOfMemory("frame settings"));
        }
        let effort = i64::from(effort.get());
        // SAFETY: `settings` was just created for this live encoder.
        let set = unsafe { ffi::JxlEncoderFrameSettingsSetOption(settings, ffi::JXL_ENC_FRAME_SETTING_EFFORT, effort) };
        self.check(set, "setting the effort")?;
        Ok(settings)
    }

    /// `status` as a result, naming `step` and libjxl's reason on failure.
    fn check(&self, status: i32, step: &'static str) -> Result<(), Error> {
        match status {
            ffi::JXL_ENC_SUCCESS => Ok(()),
            _ => Err(Error::Encoder { step, reason: self.reason() }),
        }
    }

    /// libjxl's last error, in words.
    fn reason(&self) -> &'static str {
        // SAFETY: `self.0` is a live encoder.
        match unsafe { ffi::JxlEncoderGetError(self.0) } {
            0 => "no error code",
            2 => "out of memory",
            3 => "the JPEG cannot be represented for bit-exact reconstruction",
            4 => "bad input",
            0x80 => "not supported",
            0x81 => "API misuse",
            _ => "generic error",
        }
    }

    /// Closes the input and collects the file, starting with `first` bytes of buffer and
    /// growing it up to `most`.
    fn finish(self, first: usize, most: usize) -> Result<Vec<u8>, Error> {
        // SAFETY: `self.0` is live; every frame has been added.
        unsafe { ffi::JxlEncoderCloseInput(self.0) };
        let mut out = vec![0u8; first.max(64)];
        let mut written = 0;
        loop {
            let mut avail = out.len() - written;
            // SAFETY: `written <= out.len()`, so the pointer stays inside (or one past) `out`.
            let mut next = unsafe { out.as_mut_ptr().add(written) };
            // SAFETY: `next` and `avail` describe the writable tail of `out`, which does not
            // move during the call; libjxl advances both by what it wrote.
            let status = unsafe { ffi::JxlEncoderProcessOutput(self.0, &mut next, &mut avail) };
            written = out.len() - avail;
            match status {
                ffi::JXL_ENC_SUCCESS => break,
                ffi::JXL_ENC_NEED_MORE_OUTPUT if out.len() < most => out.resize((out.len() * 2).min(most), 0),
                ffi::JXL_ENC_NEED_MORE_OUTPUT => {
                    return Err(Error::Encoder { step: "JxlEncoderProcessOutput", reason: "output past its bound" });
                }
                _ => return Err(Error::Encoder { step: "JxlEncoderProcessOutput", reason: self.reason() }),
            }
        }
        out.truncate(written);
        Ok(out)
    }
}

impl Drop for Encoder {
    fn drop(&mut self) {
        // SAFETY: `self.0` came from JxlEncoderCreate and is destroyed once, here.
        unsafe { ffi::JxlEncoderDestroy(self.0) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quality_maps_onto_cjxls_distances() {
        assert!((distance_for_quality(90) - 1.0).abs() < 1e-5);
        assert!((distance_for_quality(85) - 1.45).abs() < 1e-5);
        assert!((distance_for_quality(100) - 0.1).abs() < 1e-5);
        // Continuous at 30, and within libjxl's range at 1.
        assert!((distance_for_quality(30) - 6.4).abs() < 1e-4);
        let low = distance_for_quality(1);
        assert!(Quality::DISTANCES.contains(&low) && low > 23.0, "{low}");
        let mut last = 0.0;
        for q in (1..=100).rev() {
            let d = distance_for_quality(q);
            assert!(d > last, "distance falls as quality rises ({q}: {d})");
            last = d;
        }
    }

    #[test]
    fn refuses_inconsistent_images_and_settings() {
        let px = [0u8; 12];
        let image = |width, channels| Image { width, height: 2, channels, pixels: Pixels::U8(&px) };
        let e = Effort::new(3).unwrap();
        assert!(encode(&image(2, 3), Quality::Lossless, e).is_ok());
        assert!(matches!(encode(&image(3, 3), Quality::Lossless, e), Err(Error::Input(_))));
        assert!(matches!(encode(&image(2, 5), Quality::Lossless, e), Err(Error::Input(_))));
        assert!(matches!(encode(&image(0, 3), Quality::Lossless, e), Err(Error::Input(_))));
        assert!(matches!(encode(&image(2, 3), Quality::Distance(30.0), e), Err(Error::Input(_))));
        assert!(matches!(encode(&image(2, 3), Quality::Distance(f32::NAN), e), Err(Error::Input(_))));
        assert!(Effort::new(0).is_err() && Effort::new(10).is_err());
        assert!(matches!(recompress_jpeg(b"not a jpeg", e), Err(Error::Input(_))));
        // A JPEG's start and nothing else: libjxl refuses it, typed.
        assert!(matches!(recompress_jpeg(&[0xFF, 0xD8, 0xFF, 0xD9], e), Err(Error::JpegRecompression { .. })));
    }
}
