//! `--background`: what fills the padding between the image and the virtual texture's edge.

use std::fmt;
use std::str::FromStr;

use crate::pixel::{Channels, Sample};

/// What fills a page's texels past the image's right and bottom edges (`--background`,
/// `info.json`'s `background`): `edge`, `#rrggbb` or `#rrggbbaa`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Background {
    /// Repeat the image's edge texels (no visible seam when a runtime filters across the edge).
    #[default]
    Edge,
    /// A colour, 8 bits per channel, RGBA.
    Colour([u8; 4]),
}

impl Background {
    /// One texel of the colour in the given channels, or `None` for `Edge`. Grey is the
    /// Rec. 601 luma of the colour; wider samples are the 8-bit value scaled to their range
    /// ([`Sample::from_u8_scaled`]).
    pub fn texel<T: Sample>(&self, channels: Channels) -> Option<Vec<T>> {
        let Background::Colour([r, g, b, a]) = *self else { return None };
        let luma = ((299 * r as u32 + 587 * g as u32 + 114 * b as u32 + 500) / 1000) as u8;
        let values: &[u8] = match channels {
            Channels::Grey => &[luma],
            Channels::GreyAlpha => &[luma, a],
            Channels::Rgb => &[r, g, b],
            Channels::Rgba => &[r, g, b, a],
        };
        Some(values.iter().map(|v| T::from_u8_scaled(*v)).collect())
    }

    /// The colour alpha is flattened over: the background colour, or black for `Edge`.
    #[expect(clippy::expect_used, reason = "a colour has a texel in every layout")]
    pub(crate) fn matte<T: Sample>(&self, channels: Channels) -> Vec<T> {
        let colour = match *self {
            Background::Colour(c) => Background::Colour([c[0], c[1], c[2], 255]),
            Background::Edge => Background::Colour([0, 0, 0, 255]),
        };
        colour.texel(channels.without_alpha()).expect("a colour")
    }
}

impl FromStr for Background {
    type Err = String;

    /// `edge`, `#rrggbb`, `#rrggbbaa`, `r,g,b`, `r,g,b,a` or a grey level `v` (0-255).
    fn from_str(s: &str) -> Result<Self, String> {
        let bad =
            || format!("'{s}' is not a background: use edge, #rrggbb, #rrggbbaa, r,g,b[,a] or a grey level 0-255");
        if s == "edge" {
            return Ok(Background::Edge);
        }
        let values: Vec<u8> = if let Some(hex) = s.strip_prefix('#') {
            if !matches!(hex.len(), 6 | 8) || !hex.is_ascii() {
                return Err(bad());
            }
            (0..hex.len())
                .step_by(2)
                .map(|i| u8::from_str_radix(&hex[i..i + 2], 16))
                .collect::<Result<_, _>>()
                .map_err(|_| bad())?
        } else {
            s.split(',').map(|v| v.trim().parse::<u8>()).collect::<Result<_, _>>().map_err(|_| bad())?
        };
        Ok(Background::Colour(match values[..] {
            [v] => [v, v, v, 255],
            [r, g, b] => [r, g, b, 255],
            [r, g, b, a] => [r, g, b, a],
            _ => return Err(bad()),
        }))
    }
}

impl fmt::Display for Background {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Background::Edge => f.write_str("edge"),
            Background::Colour([r, g, b, 255]) => write!(f, "#{r:02x}{g:02x}{b:02x}"),
            Background::Colour([r, g, b, a]) => write!(f, "#{r:02x}{g:02x}{b:02x}{a:02x}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_and_prints() {
        for (text, shown) in [
            ("edge", "edge"),
            ("#FF8000", "#ff8000"),
            ("1,2,3,4", "#01020304"),
            ("128", "#808080"),
            ("#00000000", "#00000000"),
        ] {
            let b: Background = text.parse().unwrap();
            assert_eq!(b.to_string(), shown);
            assert_eq!(b.to_string().parse::<Background>().unwrap(), b);
        }
        for bad in ["", "#12345", "1,2", "300", "#gg0000", "red"] {
            assert!(bad.parse::<Background>().is_err(), "{bad}");
        }
    }

    #[test]
    fn texel_in_each_layout() {
        let b = Background::Colour([255, 0, 0, 128]);
        assert_eq!(b.texel::<u8>(Channels::Rgba), Some(vec![255, 0, 0, 128]));
        assert_eq!(b.texel::<u16>(Channels::GreyAlpha), Some(vec![76 * 257, 128 * 257]));
        assert_eq!(Background::Edge.texel::<u8>(Channels::Rgb), None);
    }
}
