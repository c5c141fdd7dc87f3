//! `--keep-icc`: the ICC profile the texels are in, written into every JPEG and PNG tile file,
//! so that a colour-managed browser or viewer shows each tile in its colours (a tile without
//! one is taken for sRGB). JPEG tiles get the profile as APP2 `ICC_PROFILE` segments (ICC.1
//! annex B.4: chunks of at most 65519 bytes, numbered from 1), after the JFIF APP0 where there
//! is one; PNG tiles an `iCCP` chunk (the profile zlib-compressed) after IHDR, as libvips,
//! libpng and libjpeg write them. Other tiles (raw, zstd, BC, WebP) pass as they are: a pack
//! keeps the profile in its info.json.

use std::io::Write;

use super::{Crop, TileSink};
use crate::error::{Result, TilerError};

/// Profile bytes one APP2 segment holds: 65535 less the length field and the 14-byte header.
const APP2_CHUNK: usize = 65_519;

/// A profile ready to splice into tiles: its APP2 segments and its iCCP chunk.
#[derive(Clone, Debug)]
pub struct Profile {
    app2: Vec<u8>,
    iccp: Vec<u8>,
}

impl Profile {
    pub fn new(icc: &[u8]) -> Result<Profile> {
        let chunks = icc.len().div_ceil(APP2_CHUNK);
        if icc.is_empty() || chunks > 255 {
            return Err(TilerError::Options(format!(
                "an ICC profile of {} bytes cannot be written into JPEG tiles (1 byte to 255 x 65519 bytes)",
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
        let mut body = b"iCCP".to_vec();
        body.extend_from_slice(b"ICC profile\0\0"); // name, separator, compression method 0
        let mut zlib = flate2::write::ZlibEncoder::new(body, flate2::Compression::default());
        let body = zlib.write_all(icc).and_then(|()| zlib.finish()).map_err(|e| TilerError::Options(e.to_string()))?;
        let mut iccp = ((body.len() - 4) as u32).to_be_bytes().to_vec();
        iccp.extend_from_slice(&body);
        iccp.extend_from_slice(&crc32(&body).to_be_bytes());
        Ok(Profile { app2, iccp })
    }

    /// `tile` with the profile in it, if it is a JPEG or PNG file; `None` leaves it as it is.
    pub fn embed(&self, tile: &[u8]) -> Option<Vec<u8>> {
        let (at, insert) = if tile.starts_with(&[0xFF, 0xD8]) {
            // After SOI, and after a JFIF APP0, which must come first.
            let app0 = tile.get(2..4) == Some(&[0xFF, 0xE0]) && tile.get(6..11) == Some(b"JFIF\0");
            let at = match app0 {
                true => 4 + u16::from_be_bytes([tile[4], tile[5]]) as usize,
                false => 2,
            };
            (at, &self.app2)
        } else if tile.starts_with(b"\x89PNG\r\n\x1a\n") && tile.get(12..16) == Some(b"IHDR") {
            (8 + 25, &self.iccp) // the signature, then IHDR: length, type, 13 bytes, CRC
        } else {
            return None;
        };
        let at = at.min(tile.len());
        let mut out = Vec::with_capacity(tile.len() + insert.len());
        out.extend_from_slice(&tile[..at]);
        out.extend_from_slice(insert);
        out.extend_from_slice(&tile[at..]);
        Some(out)
    }
}

/// CRC-32 (ISO-HDLC), as PNG chunks carry it.
fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in bytes {
        crc ^= b as u32;
        for _ in 0..8 {
            crc = (crc >> 1) ^ (0xEDB8_8320 & (crc & 1).wrapping_neg());
        }
    }
    !crc
}

/// A sink whose JPEG and PNG tiles carry `profile`.
pub struct WithProfile<'a> {
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

    #[test]
    fn large_profiles_are_cut_into_numbered_app2_chunks() {
        let icc: Vec<u8> = (0..150_000u32).map(|i| i as u8).collect();
        let profile = Profile::new(&icc).unwrap();
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
}
