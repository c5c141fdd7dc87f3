//! What the main header of a JPEG 2000 codestream (ISO/IEC 15444-1 Annex A) says: the image
//! and its components (SIZ) and how they were coded (COD). The one reader of those bytes: the
//! JPEG 2000 tile reader checks a tile against it before OpenJPEG allocates, and states the
//! slide's lossy history from it; an output that copies the tiles as stored (a DICOM series'
//! JPEG 2000 frames) states their colour and wavelet from it.

/// A codestream's main header, as far as this program reads it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Codestream {
    /// The image area's size on the reference grid (Xsiz - XOsiz, Ysiz - YOsiz).
    pub width: u32,
    pub height: u32,
    /// The image area's origin on the reference grid (XOsiz, YOsiz).
    pub origin: (u32, u32),
    pub components: Vec<Component>,
    /// How the default coding style (COD) codes every component; `None` where the main header
    /// has no COD before its first tile-part (not a valid codestream, as decoders will say).
    pub coding: Option<Coding>,
}

/// One component of the image (SIZ's Ssiz, XRsiz, YRsiz).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Component {
    /// Bits a sample, 1 to 38.
    pub precision: u8,
    pub signed: bool,
    /// Its subsampling across and down (1: a sample every texel).
    pub dx: u8,
    pub dy: u8,
}

/// The default coding style (COD).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Coding {
    /// The reversible 5-3 wavelet (lossless), not the irreversible 9-7 one.
    pub reversible: bool,
    /// Whether the first three components went through the multiple component transform (the
    /// reversible RCT with the 5-3 wavelet, the irreversible ICT with the 9-7): a decoder turns
    /// them back into R, G, B.
    pub transform: bool,
}

impl Codestream {
    /// Reads the main header at the start of `head` (SOC, SIZ, then segments up to the first
    /// SOT), or says what is wrong with it. `head` may be the first bytes of the codestream
    /// only: what lies past the first tile-part is not read.
    pub fn read(head: &[u8]) -> Result<Codestream, String> {
        if head.get(..4) != Some(&[0xFF, 0x4F, 0xFF, 0x51]) {
            return Err("not a JPEG 2000 codestream (no SOC and SIZ markers at its start)".into());
        }
        let be32 = |at: usize| head.get(at..at + 4).map(|b| u32::from_be_bytes([b[0], b[1], b[2], b[3]]));
        let short = || "the JPEG 2000 SIZ marker is cut short".to_string();
        let (x, y, x0, y0) = (be32(8).ok_or_else(short)?, be32(12).ok_or_else(short)?, be32(16), be32(20));
        let (x0, y0) = (x0.ok_or_else(short)?, y0.ok_or_else(short)?);
        let count = head.get(40..42).map(|b| u16::from_be_bytes([b[0], b[1]])).ok_or_else(short)?;
        if count == 0 {
            return Err("the JPEG 2000 SIZ marker declares no components".into());
        }
        let mut components = Vec::with_capacity(usize::from(count.min(16)));
        for i in 0..usize::from(count) {
            let Some(&[s, dx, dy]) = head.get(42 + 3 * i..45 + 3 * i) else { return Err(short()) };
            if dx == 0 || dy == 0 {
                return Err(format!("JPEG 2000 component {i} is subsampled {dx}x{dy}"));
            }
            components.push(Component { precision: (s & 0x7F) + 1, signed: s & 0x80 != 0, dx, dy });
        }
        let (width, height) = (x.saturating_sub(x0), y.saturating_sub(y0));
        Ok(Codestream { width, height, origin: (x0, y0), components, coding: coding(head) })
    }
}

/// The COD segment's coding style, found by walking the main header's segments by their
/// lengths from SIZ on; `None` where the first SOT (or the end of `head`) comes first.
fn coding(head: &[u8]) -> Option<Coding> {
    let mut at = 2;
    while at + 4 <= head.len() && head[at] == 0xFF {
        let (marker, length) = (head[at + 1], u16::from_be_bytes([head[at + 2], head[at + 3]]));
        match marker {
            // COD: Lcod, Scod, SGcod (progression order, layers (2 bytes), the multiple
            // component transform), SPcod (levels, code-block width and height, style, then
            // the wavelet: 0 irreversible 9-7, 1 reversible 5-3).
            0x52 => {
                let (transform, wavelet) = (head.get(at + 8)?, head.get(at + 13)?);
                return Some(Coding { reversible: *wavelet == 1, transform: *transform == 1 });
            }
            0x90 => return None,
            _ => at += 2 + usize::from(length),
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    /// SOC, a SIZ of a `w` x `h` image of `components` (Ssiz, XRsiz, YRsiz) at origin
    /// (3, 5), then a COD with `transform` and `wavelet`, then an SOT.
    fn codestream(w: u32, h: u32, components: &[[u8; 3]], transform: u8, wavelet: u8) -> Vec<u8> {
        let mut raw = vec![0xFF, 0x4F, 0xFF, 0x51];
        raw.extend((38 + 3 * components.len() as u16).to_be_bytes());
        raw.extend([0, 0]);
        for v in [w + 3, h + 5, 3, 5, w, h, 0, 0] {
            raw.extend(v.to_be_bytes());
        }
        raw.extend((components.len() as u16).to_be_bytes());
        raw.extend(components.iter().flatten());
        // COD: Lcod 12, Scod, progression, 1 layer, transform, 5 levels, 64x64 blocks, style.
        raw.extend([0xFF, 0x52, 0, 12, 0, 0, 0, 1, transform, 5, 4, 4, 0, wavelet]);
        raw.extend([0xFF, 0x90, 0, 10]);
        raw
    }

    /// The sizes, components and coding style are read where ISO/IEC 15444-1 A.5.1 and
    /// A.6.1 put them.
    #[test]
    fn the_main_header_is_read_field_by_field() {
        let raw = codestream(240, 128, &[[7, 1, 1], [0x87, 2, 2], [11, 1, 2]], 1, 0);
        let c = Codestream::read(&raw).unwrap();
        assert_eq!((c.width, c.height, c.origin), (240, 128, (3, 5)));
        let want = [(8, false, 1, 1), (8, true, 2, 2), (12, false, 1, 2)];
        let got: Vec<_> = c.components.iter().map(|c| (c.precision, c.signed, c.dx, c.dy)).collect();
        assert_eq!(got, want);
        assert_eq!(c.coding, Some(Coding { reversible: false, transform: true }));
        let lossless = Codestream::read(&codestream(16, 16, &[[7, 1, 1]], 0, 1)).unwrap();
        assert_eq!(lossless.coding, Some(Coding { reversible: true, transform: false }));
    }

    /// What is not a codestream, or is cut short, says so; a header without a COD before the
    /// first tile-part has no coding.
    #[test]
    fn what_is_short_or_wrong_is_named() {
        let raw = codestream(16, 16, &[[7, 1, 1]; 3], 0, 1);
        assert!(Codestream::read(&raw[2..]).unwrap_err().contains("no SOC"));
        assert!(Codestream::read(&raw[..44]).unwrap_err().contains("cut short"));
        let zero = codestream(16, 16, &[[7, 0, 1]], 0, 1);
        assert!(Codestream::read(&zero).unwrap_err().contains("subsampled 0x1"));
        let without_cod = [&raw[..51], &[0xFF, 0x90, 0, 10][..]].concat();
        assert_eq!(Codestream::read(&without_cod).unwrap().coding, None);
        assert_eq!(Codestream::read(&raw[..60]).unwrap().coding, None, "cut inside the COD");
    }
}
