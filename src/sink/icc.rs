//! `--keep-icc`: the ICC profile the texels are in, written into every JPEG and PNG tile file,
//! so that a colour-managed browser or viewer shows each tile in its colours (a tile without
//! one is taken for sRGB). JPEG tiles get the profile as APP2 `ICC_PROFILE` segments (ICC.1
//! annex B.4: chunks of at most 65519 bytes, numbered from 1), after the JFIF APP0 where there
//! is one; PNG tiles an `iCCP` chunk (the profile zlib-compressed) after IHDR, as libvips,
//! libpng and libjpeg write them. Other tiles (raw, zstd, BC, WebP) pass as they are: a pack
//! keeps the profile in its info.json.

use std::io::Write;

use super::{Crop, TileSink};
use crate::codec::Codec;
use crate::error::{Result, TilerError};

/// Profile bytes one APP2 segment holds: 65535 less the length field and the 14-byte header.
const APP2_CHUNK: usize = 65_519;

/// The most profile bytes a JPEG holds: 255 numbered APP2 segments of `APP2_CHUNK` (65519) bytes.
pub(crate) const MAX_JPEG_PROFILE: usize = 255 * APP2_CHUNK;

/// A profile ready to splice into the tiles of one codec: the JPEG tiles' APP2 segments or the
/// PNG tiles' iCCP chunk.
#[derive(Clone, Debug)]
pub(crate) struct Profile {
    segments: Segments,
}

#[derive(Clone, Debug)]
enum Segments {
    App2(Vec<u8>),
    Iccp(Vec<u8>),
}

impl Profile {
    /// The profile `icc` ready for the tiles `codec` writes: `None` for tiles that are not
    /// image files (raw, zstd, BC, WebP in a pack), which carry no profile of their own (the
    /// output's info.json keeps it). A JPEG holds at most [`MAX_JPEG_PROFILE`] bytes of
    /// profile; a PNG's iCCP chunk has no such bound.
    pub fn for_tiles(icc: &[u8], codec: Codec) -> Result<Option<Profile>> {
        if icc.is_empty() {
            return Err(TilerError::Options("the kept ICC profile is empty: there is nothing to keep".into()));
        }
        let segments = match codec {
            Codec::Jpeg { .. } => Segments::App2(app2(icc)?),
            Codec::Png { .. } => Segments::Iccp(iccp(icc)?),
            // A JPEG XL file states its colour itself (sRGB, as encoded here): tiles that carry
            // another profile's texels would be shown wrong.
            Codec::Jxl { .. } => {
                return Err(TilerError::Options(
                    "--keep-icc: JPEG XL tiles do not carry an ICC profile yet; leave --keep-icc out to convert the texels to sRGB, or use --codec jpeg or png".into(),
                ));
            }
            _ => return Ok(None),
        };
        Ok(Some(Profile { segments }))
    }

    /// `tile` with the profile in it, if it is a file of the profile's kind (JPEG for APP2, PNG
    /// for iCCP); `None` leaves it as it is.
    pub fn embed(&self, tile: &[u8]) -> Option<Vec<u8>> {
        let (at, insert) = match &self.segments {
            Segments::App2(app2) if tile.starts_with(&[0xFF, 0xD8]) => {
                // After SOI, and after a JFIF APP0, which must come first.
                let app0 = tile.get(2..4) == Some(&[0xFF, 0xE0]) && tile.get(6..11) == Some(b"JFIF\0");
                let at = match app0 {
                    true => 4 + u16::from_be_bytes([tile[4], tile[5]]) as usize,
                    false => 2,
                };
                (at, app2)
            }
            Segments::Iccp(iccp) if tile.starts_with(b"\x89PNG\r\n\x1a\n") && tile.get(12..16) == Some(b"IHDR") => {
                (8 + 25, iccp) // the signature, then IHDR: length, type, 13 bytes, CRC
            }
            _ => return None,
        };
        let at = at.min(tile.len());
        let mut out = Vec::with_capacity(tile.len() + insert.len());
        out.extend_from_slice(&tile[..at]);
        out.extend_from_slice(insert);
        out.extend_from_slice(&tile[at..]);
        Some(out)
    }
}

/// `icc` as APP2 `ICC_PROFILE` segments (ICC.1 annex B.4).
fn app2(icc: &[u8]) -> Result<Vec<u8>> {
    let chunks = icc.len().div_ceil(APP2_CHUNK);
    if chunks > 255 {
        return Err(TilerError::Options(format!(
            "an ICC profile of {} bytes cannot be written into JPEG tiles, which hold at most {MAX_JPEG_PROFILE} bytes of profile (255 APP2 segments of {APP2_CHUNK}): use --codec png, whose iCCP chunk holds any size, or leave --keep-icc out to convert the texels to sRGB",
            icc.len()
        )));
    }
    let mut app2 = Vec::with_capacity(icc.len() + chunks * 18);
    for (i, chunk) in icc.chunks(APP2_CHUNK).enumerate() {
        app2.extend_from_slice(&[0xFF, 0xE2]);
        app2.extend_from_slice(&((2 + 14 + chunk.len()) as u16).to_be_bytes());
        app2.extend_from_slice(b"ICC_PROFILE\0");
        app2.extend_from_slice(&[i as u8 + 1, chunks as u8]);
        app2.extend_from_slice(chunk);
    }
    Ok(app2)
}

/// `icc` as a PNG `iCCP` chunk: length, type, name, compression method 0, zlib data, CRC.
fn iccp(icc: &[u8]) -> Result<Vec<u8>> {
    let mut body = b"iCCP".to_vec();
    body.extend_from_slice(b"ICC profile\0\0"); // name, separator, compression method 0
    let mut zlib = flate2::write::ZlibEncoder::new(body, flate2::Compression::default());
    let failed = |e: std::io::Error| TilerError::Internal(format!("compressing the ICC profile for PNG tiles: {e}"));
    let body = zlib.write_all(icc).and_then(|()| zlib.finish()).map_err(failed)?;
    let length = u32::try_from(body.len() - 4).ok().filter(|&l| l <= i32::MAX as u32).ok_or_else(|| {
        TilerError::Options(format!("an ICC profile of {} bytes is too large for a PNG chunk", icc.len()))
    })?;
    let mut iccp = length.to_be_bytes().to_vec();
    iccp.extend_from_slice(&body);
    iccp.extend_from_slice(&crc32(&body).to_be_bytes());
    Ok(iccp)
}

/// CRC-32 (ISO-HDLC), as PNG chunks carry it: flate2's, as the PNG reader checks it.
fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = flate2::Crc::new();
    crc.update(bytes);
    crc.sum()
}

/// A sink whose JPEG and PNG tiles carry `profile`.
pub(crate) struct WithProfile<'a> {
    pub inner: &'a dyn TileSink,
    pub profile: &'a Profile,
}

impl TileSink for WithProfile<'_> {
    fn write_tile(&self, lod: u32, x: u32, y: u32, bytes: &[u8]) -> Result<()> {
        match self.profile.embed(bytes) {
            Some(tagged) => self.inner.write_tile(lod, x, y, &tagged),
            None => self.inner.write_tile(lod, x, y, bytes),
        }
    }
    fn write_stored(&self, lod: u32, x: u32, y: u32, bytes: &[u8]) -> Result<()> {
        match self.profile.embed(bytes) {
            Some(tagged) => self.inner.write_stored(lod, x, y, &tagged),
            None => self.inner.write_stored(lod, x, y, bytes),
        }
    }
    fn takes_constants(&self) -> bool {
        self.inner.takes_constants()
    }
    fn write_constant(&self, lod: u32, x: u32, y: u32, texel: &[u8]) -> Result<()> {
        self.inner.write_constant(lod, x, y, texel)
    }
    fn ordered(&self) -> bool {
        self.inner.ordered()
    }
    fn crop(&self, lod: u32, x: u32, y: u32) -> Option<Crop> {
        self.inner.crop(lod, x, y)
    }
    fn kept(&self, lod: u32, x: u32, y: u32) -> bool {
        self.inner.kept(lod, x, y)
    }
    fn bytes_written(&self) -> u64 {
        self.inner.bytes_written()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc32_is_pngs() {
        // The CRC of an IEND chunk's type, as every PNG ends.
        assert_eq!(crc32(b"IEND"), 0xAE42_6082);
    }

    const JPEG: Codec = Codec::Jpeg { quality: 90, subsampling: crate::codec::Subsampling::S420 };
    const PNG: Codec = Codec::Png { level: crate::codec::PngLevel::Fast };

    #[test]
    fn large_profiles_are_cut_into_numbered_app2_chunks() {
        let icc: Vec<u8> = (0..150_000u32).map(|i| i as u8).collect();
        let profile = Profile::for_tiles(&icc, JPEG).unwrap().unwrap();
        let tile = [0xFF, 0xD8, 0xFF, 0xD9];
        let tagged = profile.embed(&tile).unwrap();
        let mut joined = Vec::new();
        let mut at = 2;
        let mut seq = 1;
        while tagged[at + 1] == 0xE2 {
            let len = u16::from_be_bytes([tagged[at + 2], tagged[at + 3]]) as usize;
            assert_eq!(&tagged[at + 4..at + 16], b"ICC_PROFILE\0");
            assert_eq!((tagged[at + 16], tagged[at + 17]), (seq, 3));
            joined.extend_from_slice(&tagged[at + 18..at + 2 + len]);
            (at, seq) = (at + 2 + len, seq + 1);
        }
        assert_eq!(joined, icc);
        assert_eq!(&tagged[at..], &[0xFF, 0xD9]);
        assert_eq!(profile.embed(b"RIFF...."), None);
    }

    /// A profile larger than 255 APP2 segments hold is refused for JPEG tiles only, naming
    /// JPEG; PNG tiles take it whole in their iCCP chunk, and tiles that are not image files
    /// (a pack's raw tiles) need no copy of it.
    #[test]
    fn a_profile_too_large_for_jpeg_goes_into_png_tiles() {
        let icc: Vec<u8> = (0..MAX_JPEG_PROFILE + 1).map(|i| (i % 251) as u8).collect();
        let err = Profile::for_tiles(&icc, JPEG).unwrap_err().to_string();
        assert!(err.contains("JPEG tiles") && err.contains("--codec png"), "{err}");
        let png = Profile::for_tiles(&icc, PNG).unwrap().unwrap();
        let mut tile = b"\x89PNG\r\n\x1a\n\0\0\0\x0dIHDR".to_vec();
        tile.extend_from_slice(&[0; 17]);
        let tagged = png.embed(&tile).unwrap();
        let length = u32::from_be_bytes(tagged[33..37].try_into().unwrap()) as usize;
        assert_eq!(&tagged[37..41], b"iCCP");
        let zlib = &tagged[41 + b"ICC profile\0\0".len()..41 + length];
        let mut inflated = Vec::new();
        use std::io::Read;
        flate2::read::ZlibDecoder::new(zlib).read_to_end(&mut inflated).unwrap();
        assert!(inflated == icc);
        assert_eq!(png.embed(&[0xFF, 0xD8, 0xFF, 0xD9]), None, "a PNG profile goes into PNG tiles only");
        assert!(Profile::for_tiles(&icc, Codec::Raw).unwrap().is_none());
        assert!(Profile::for_tiles(&[], PNG).is_err());
        let jxl = Codec::Jxl { quality: None, effort: crate::codec::JxlEffort::clamped(3) };
        let err = Profile::for_tiles(&icc, jxl).unwrap_err().to_string();
        assert!(err.contains("JPEG XL tiles do not carry an ICC profile"), "{err}");
    }
}
