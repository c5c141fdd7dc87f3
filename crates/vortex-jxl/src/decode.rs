//! Decoding: a JPEG XL file (a tile: small, whole in memory) into interleaved samples, with
//! its size checked against the caller's bound before anything is allocated.

#![expect(unsafe_code, reason = "libjxl's C interface")]

use std::ptr;

use crate::Error;
use crate::ffi;

/// What a JPEG XL file's header says of its image.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Header {
    /// Texels across.
    pub width: u32,
    /// Texels down.
    pub height: u32,
    /// 1 (grey), 2 (grey + alpha), 3 (RGB) or 4 (RGBA): what [`decode`] gives.
    pub channels: u32,
    /// Bits a sample as coded (8 for a recompressed JPEG); [`decode`] gives 8-bit samples up
    /// to 8, 16-bit ones above.
    pub bits_per_sample: u32,
}

/// Decoded samples, interleaved, rows top down, native byte order.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Samples {
    /// 8 bits a sample.
    U8(Vec<u8>),
    /// 16 bits a sample.
    U16(Vec<u16>),
}

/// A decoded image.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Decoded {
    /// Its size and channels.
    pub header: Header,
    /// Its samples (sRGB colour as coded, straight alpha).
    pub samples: Samples,
}

/// The header of the JPEG XL file `bytes`, without decoding its texels.
pub fn probe(bytes: &[u8]) -> Result<Header, Error> {
    let dec = Decoder::new(bytes, ffi::JXL_DEC_BASIC_INFO)?;
    match dec.process()? {
        ffi::JXL_DEC_BASIC_INFO => dec.header(),
        _ => Err(Error::Corrupt("no basic info".into())),
    }
}

/// Decodes the JPEG XL file `bytes` whole; an image larger than `max` (width, height) is
/// [`Error::TooLarge`], refused from its header.
pub fn decode(bytes: &[u8], max: (u32, u32)) -> Result<Decoded, Error> {
    let dec = Decoder::new(bytes, ffi::JXL_DEC_BASIC_INFO | ffi::JXL_DEC_FULL_IMAGE)?;
    let mut image: Option<(Header, Samples)> = None;
    loop {
        match dec.process()? {
            ffi::JXL_DEC_BASIC_INFO => {
                let header = dec.header()?;
                if header.width > max.0 || header.height > max.1 {
                    let (width, height) = (header.width, header.height);
                    return Err(Error::TooLarge { width, height, max_width: max.0, max_height: max.1 });
                }
                let samples = (header.width as usize)
                    .checked_mul(header.height as usize)
                    .and_then(|n| n.checked_mul(header.channels as usize))
                    .ok_or(Error::TooLarge {
                        width: header.width,
                        height: header.height,
                        max_width: max.0,
                        max_height: max.1,
                    })?;
                let samples = match header.bits_per_sample {
                    ..=8 => Samples::U8(vec![0; samples]),
                    _ => Samples::U16(vec![0; samples]),
                };
                image = Some((header, samples));
            }
            ffi::JXL_DEC_NEED_IMAGE_OUT_BUFFER => {
                let Some((header, samples)) = image.as_mut() else {
                    return Err(Error::Corrupt("an image before its basic info".into()));
                };
                let (format, buffer, size) = match samples {
                    Samples::U8(s) => (format(header.channels, ffi::JXL_TYPE_UINT8), s.as_mut_ptr().cast(), s.len()),
                    Samples::U16(s) => {
                        (format(header.channels, ffi::JXL_TYPE_UINT16), s.as_mut_ptr().cast(), size_of_val(&s[..]))
                    }
                };
                let mut need = 0usize;
                // SAFETY: `dec.raw` is live and `format`, `need` valid for the call.
                let status = unsafe { ffi::JxlDecoderImageOutBufferSize(dec.raw, &format, &mut need) };
                if status != ffi::JXL_DEC_SUCCESS || need != size {
                    return Err(Error::Corrupt(format!(
                        "an image buffer of {need} bytes, not the {size} its header gives"
                    )));
                }
                // SAFETY: `buffer` is `size` writable bytes owned by `image`, which is neither
                // moved nor resized until the decoder is destroyed (it outlives `dec`'s use).
                let status = unsafe { ffi::JxlDecoderSetImageOutBuffer(dec.raw, &format, buffer, size) };
                if status != ffi::JXL_DEC_SUCCESS {
                    return Err(Error::Corrupt("the decoder refused the image buffer".into()));
                }
            }
            ffi::JXL_DEC_FULL_IMAGE => {}
            ffi::JXL_DEC_SUCCESS => break,
            other => return Err(Error::Corrupt(format!("unexpected decoder event {other:#x}"))),
        }
    }
    drop(dec);
    let (header, samples) = image.ok_or(Error::Truncated)?;
    Ok(Decoded { header, samples })
}

fn format(channels: u32, data_type: i32) -> ffi::JxlPixelFormat {
    ffi::JxlPixelFormat { num_channels: channels, data_type, endianness: ffi::JXL_NATIVE_ENDIAN, align: 0 }
}

/// A libjxl decoder reading one whole file, destroyed when dropped.
struct Decoder<'a> {
    raw: *mut ffi::JxlDecoder,
    _input: &'a [u8],
}

impl Decoder<'_> {
    /// A decoder of `bytes` (kept borrowed while it lives) reporting `events`.
    fn new(bytes: &[u8], events: i32) -> Result<Decoder<'_>, Error> {
        if !crate::is_jxl(bytes) {
            return Err(Error::Corrupt("no JPEG XL signature".into()));
        }
        // SAFETY: a null memory manager asks for libjxl's default allocator.
        let raw = unsafe { ffi::JxlDecoderCreate(ptr::null()) };
        if raw.is_null() {
            return Err(Error::OutOfMemory("decoder"));
        }
        let dec = Decoder { raw, _input: bytes };
        // SAFETY: `raw` is live; `bytes` outlives the decoder (the borrow in `_input`).
        let ok = unsafe {
            ffi::JxlDecoderSubscribeEvents(raw, events) == ffi::JXL_DEC_SUCCESS
                && ffi::JxlDecoderSetInput(raw, bytes.as_ptr(), bytes.len()) == ffi::JXL_DEC_SUCCESS
        };
        if !ok {
            return Err(Error::Corrupt("the decoder refused its input".into()));
        }
        // SAFETY: `raw` is live; all the input is set.
        unsafe { ffi::JxlDecoderCloseInput(raw) };
        Ok(dec)
    }

    /// The next event, or the error that stopped decoding.
    fn process(&self) -> Result<i32, Error> {
        // SAFETY: `self.raw` is live and its input still borrowed.
        match unsafe { ffi::JxlDecoderProcessInput(self.raw) } {
            ffi::JXL_DEC_ERROR => Err(Error::Corrupt("libjxl's decoder failed".into())),
            ffi::JXL_DEC_NEED_MORE_INPUT => Err(Error::Truncated),
            event => Ok(event),
        }
    }

    /// The basic info, once reported, as a [`Header`] of an image this crate decodes.
    fn header(&self) -> Result<Header, Error> {
        let mut info = ffi::JxlBasicInfo::zeroed();
        // SAFETY: `self.raw` is live and `info` a writable JxlBasicInfo of 0.7's layout.
        if unsafe { ffi::JxlDecoderGetBasicInfo(self.raw, &mut info) } != ffi::JXL_DEC_SUCCESS {
            return Err(Error::Corrupt("no basic info".into()));
        }
        if info.exponent_bits_per_sample != 0 || info.bits_per_sample == 0 || info.bits_per_sample > 16 {
            return Err(Error::Corrupt(format!(
                "{} bits a sample{}: this decoder reads integer samples up to 16 bits",
                info.bits_per_sample,
                if info.exponent_bits_per_sample != 0 { " (float)" } else { "" }
            )));
        }
        if info.have_animation != 0 {
            return Err(Error::Corrupt("an animation, not one image".into()));
        }
        let colour = match info.num_color_channels {
            1 | 3 => info.num_color_channels,
            n => return Err(Error::Corrupt(format!("{n} colour channels"))),
        };
        let channels = colour + u32::from(info.alpha_bits > 0);
        Ok(Header { width: info.xsize, height: info.ysize, channels, bits_per_sample: info.bits_per_sample })
    }
}

impl Drop for Decoder<'_> {
    fn drop(&mut self) {
        // SAFETY: `self.raw` came from JxlDecoderCreate and is destroyed once, here.
        unsafe { ffi::JxlDecoderDestroy(self.raw) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Effort, Image, Pixels, Quality, encode};

    fn gradient(width: u32, height: u32, channels: u32) -> Vec<u8> {
        let n = (width * height * channels) as usize;
        (0..n).map(|i| ((i * 37) ^ (i / 7)) as u8).collect()
    }

    #[test]
    fn lossless_round_trips_every_layout() {
        for channels in 1..=4 {
            let px = gradient(13, 7, channels);
            let image = Image { width: 13, height: 7, channels, pixels: Pixels::U8(&px) };
            let file = encode(&image, Quality::Lossless, Effort::new(2).unwrap()).unwrap();
            let header = probe(&file).unwrap();
            assert_eq!(header, Header { width: 13, height: 7, channels, bits_per_sample: 8 });
            let back = decode(&file, (13, 7)).unwrap();
            assert_eq!(back.samples, Samples::U8(px), "{channels} channels");
        }
        let wide: Vec<u16> = (0..5 * 3 * 3).map(|i| (i * 1499) as u16).collect();
        let image = Image { width: 5, height: 3, channels: 3, pixels: Pixels::U16(&wide) };
        let file = encode(&image, Quality::Lossless, Effort::new(1).unwrap()).unwrap();
        assert_eq!(decode(&file, (5, 3)).unwrap().samples, Samples::U16(wide));
    }

    #[test]
    fn lossy_is_close_and_smaller_at_larger_distances() {
        let px: Vec<u8> = (0..64 * 64 * 3).map(|i| ((i / 3 % 64) * 3 + i / 192) as u8).collect();
        let image = Image { width: 64, height: 64, channels: 3, pixels: Pixels::U8(&px) };
        let effort = Effort::new(7).unwrap();
        let fine = encode(&image, Quality::Distance(0.5), effort).unwrap();
        let coarse = encode(&image, Quality::Distance(8.0), effort).unwrap();
        assert!(coarse.len() < fine.len(), "{} >= {}", coarse.len(), fine.len());
        let Samples::U8(back) = decode(&fine, (64, 64)).unwrap().samples else { panic!("8-bit") };
        let worst = back.iter().zip(&px).map(|(a, b)| a.abs_diff(*b)).max().unwrap();
        assert!(worst <= 8, "a smooth gradient at distance 0.5 is off by {worst}");
    }

    #[test]
    fn refuses_what_it_should() {
        let px = gradient(16, 16, 3);
        let image = Image { width: 16, height: 16, channels: 3, pixels: Pixels::U8(&px) };
        let file = encode(&image, Quality::Lossless, Effort::new(1).unwrap()).unwrap();
        assert!(matches!(decode(&file, (15, 16)), Err(Error::TooLarge { width: 16, .. })));
        assert!(matches!(decode(&file[..file.len() / 2], (16, 16)), Err(Error::Truncated | Error::Corrupt(_))));
        assert!(matches!(decode(b"\x89PNG", (16, 16)), Err(Error::Corrupt(_))));
        let mut bad = file.clone();
        for b in bad.iter_mut().skip(8) {
            *b ^= 0x5A;
        }
        assert!(decode(&bad, (16, 16)).is_err());
    }
}
