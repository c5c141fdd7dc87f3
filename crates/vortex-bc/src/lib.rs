//! BC1 and BC7 blocks of RGBA8 tiles, by Intel's ISPC texture compressor: the one place Vortex
//! encodes BC, for the tiler's `--codec bc1|bc7` tiles and the runtime's transcoding of pages on
//! their way into a BC cache. The blocks come in rows of blocks, top down, as a GPU upload and the
//! pack format (`bc1`, `bc7` payloads) take them.
//!
//! In the browser (wasm32) the kernels do not build: there the crate has [`Bc7Effort`] and no
//! encoder, and its build script links nothing.
//!
//! ```
//! # #[cfg(not(target_arch = "wasm32"))]
//! # fn main() -> Result<(), vortex_bc::BcError> {
//! // An 8 x 8 opaque tile of one colour: four blocks.
//! let texels = [40u8, 120, 200, 255].repeat(8 * 8);
//! let mut blocks = Vec::new();
//! vortex_bc::encode_bc7(&texels, 8, 8, vortex_bc::Bc7Effort::UltraFast, false, &mut blocks)?;
//! assert_eq!(blocks.len(), 4 * vortex_bc::BC7_BLOCK_BYTES);
//! vortex_bc::encode_bc1(&texels, 8, 8, &mut blocks)?;
//! assert_eq!(blocks.len(), 4 * vortex_bc::BC1_BLOCK_BYTES);
//! # Ok(())
//! # }
//! # #[cfg(target_arch = "wasm32")]
//! # fn main() {}
//! ```
#![warn(missing_docs)]

/// Bytes of one 4x4 BC1 block.
pub const BC1_BLOCK_BYTES: usize = 8;
/// Bytes of one 4x4 BC7 block.
pub const BC7_BLOCK_BYTES: usize = 16;

/// BC7 encoder effort: the presets of Intel's ISPC texture compressor, fastest first.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Bc7Effort {
    /// About 1 ms per 256-texel RGB tile on one core.
    UltraFast,
    /// About 10x slower than ultra-fast, about 3 dB better.
    VeryFast,
    /// About 18x slower, a little better.
    Fast,
    /// About 45x slower.
    Basic,
    /// About 160x slower, best.
    Slow,
}

impl Bc7Effort {
    /// Every value, fastest first, in the order `--help` lists them.
    pub const ALL: [Bc7Effort; 5] =
        [Bc7Effort::UltraFast, Bc7Effort::VeryFast, Bc7Effort::Fast, Bc7Effort::Basic, Bc7Effort::Slow];

    /// The name used on the command line (`--bc7-effort`) and in `info.json`.
    pub fn name(self) -> &'static str {
        match self {
            Bc7Effort::UltraFast => "ultra-fast",
            Bc7Effort::VeryFast => "very-fast",
            Bc7Effort::Fast => "fast",
            Bc7Effort::Basic => "basic",
            Bc7Effort::Slow => "slow",
        }
    }

    /// The value `name` names, if any.
    pub fn from_name(name: &str) -> Option<Bc7Effort> {
        Bc7Effort::ALL.into_iter().find(|v| v.name() == name)
    }

    /// One line on what the value does (`--help` lists it).
    pub fn about(self) -> &'static str {
        match self {
            Bc7Effort::UltraFast => "About 1 ms per 256-texel RGB tile on one core",
            Bc7Effort::VeryFast => "About 10x slower than ultra-fast, about 3 dB better",
            Bc7Effort::Fast => "About 18x slower, a little better",
            Bc7Effort::Basic => "About 45x slower",
            Bc7Effort::Slow => "About 160x slower, best",
        }
    }
}

/// Texels that cannot be encoded as asked. Checked before the encoder sees them: its kernels
/// read `width x height` texels with no bounds of their own.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum BcError {
    /// BC blocks are 4x4 texels: each side must be a positive multiple of 4.
    #[error("a {width}x{height} image cannot be cut into 4x4 BC blocks: both sides must be positive multiples of 4")]
    Size {
        /// The width asked for.
        width: u32,
        /// The height asked for.
        height: u32,
    },
    /// The texels are not `width x height` RGBA8 texels.
    #[error("{len} bytes are not the {width}x{height} RGBA8 texels to encode ({expected} bytes)")]
    Length {
        /// The width asked for.
        width: u32,
        /// The height asked for.
        height: u32,
        /// The bytes given.
        len: usize,
        /// The bytes `width x height` RGBA8 texels take.
        expected: u64,
    },
}

/// The bytes of the blocks covering `width x height` texels, `block_bytes` each, after checking
/// that `rgba` holds exactly those texels and that the sides cut into whole blocks.
#[cfg(not(target_arch = "wasm32"))]
fn checked_len(rgba: &[u8], width: u32, height: u32, block_bytes: usize) -> Result<usize, BcError> {
    if width == 0 || height == 0 || !width.is_multiple_of(4) || !height.is_multiple_of(4) {
        return Err(BcError::Size { width, height });
    }
    let expected = u64::from(width) * u64::from(height) * 4;
    if rgba.len() as u64 != expected {
        return Err(BcError::Length { width, height, len: rgba.len(), expected });
    }
    // A sixteenth (BC7) or a 32nd (BC1) of the texels' bytes, which are in memory already.
    Ok((width as usize / 4) * (height as usize / 4) * block_bytes)
}

/// BC1 blocks of `width x height` RGBA8 texels (rows top down) into `out`, replacing what it
/// held. BC1 keeps no alpha: it is for opaque textures.
#[cfg(not(target_arch = "wasm32"))]
pub fn encode_bc1(rgba: &[u8], width: u32, height: u32, out: &mut Vec<u8>) -> Result<(), BcError> {
    let len = checked_len(rgba, width, height, BC1_BLOCK_BYTES)?;
    let surface = intel_tex_2::RgbaSurface { data: rgba, width, height, stride: width * 4 };
    out.clear();
    out.resize(len, 0);
    intel_tex_2::bc1::compress_blocks_into(&surface, out);
    Ok(())
}

/// BC7 blocks of `width x height` RGBA8 texels (rows top down) into `out`, replacing what it
/// held, at `effort`. `alpha` picks the presets that spend bits on alpha; the opaque ones take
/// alpha as 255 whatever it is.
#[cfg(not(target_arch = "wasm32"))]
pub fn encode_bc7(
    rgba: &[u8],
    width: u32,
    height: u32,
    effort: Bc7Effort,
    alpha: bool,
    out: &mut Vec<u8>,
) -> Result<(), BcError> {
    use intel_tex_2::bc7;
    let len = checked_len(rgba, width, height, BC7_BLOCK_BYTES)?;
    let settings = match (effort, alpha) {
        (Bc7Effort::UltraFast, false) => bc7::opaque_ultra_fast_settings(),
        (Bc7Effort::VeryFast, false) => bc7::opaque_very_fast_settings(),
        (Bc7Effort::Fast, false) => bc7::opaque_fast_settings(),
        (Bc7Effort::Basic, false) => bc7::opaque_basic_settings(),
        (Bc7Effort::Slow, false) => bc7::opaque_slow_settings(),
        (Bc7Effort::UltraFast, true) => bc7::alpha_ultra_fast_settings(),
        (Bc7Effort::VeryFast, true) => bc7::alpha_very_fast_settings(),
        (Bc7Effort::Fast, true) => bc7::alpha_fast_settings(),
        (Bc7Effort::Basic, true) => bc7::alpha_basic_settings(),
        (Bc7Effort::Slow, true) => bc7::alpha_slow_settings(),
    };
    let surface = intel_tex_2::RgbaSurface { data: rgba, width, height, stride: width * 4 };
    out.clear();
    out.resize(len, 0);
    bc7::compress_blocks_into(&settings, &surface, out);
    Ok(())
}

#[cfg(all(test, not(target_arch = "wasm32")))]
mod tests {
    use super::*;

    /// The blocks decoded by an independent decoder (bcdec, Direct3D's definition).
    fn decoded(blocks: &[u8], side: usize, block_bytes: usize) -> Vec<u8> {
        let mut out = vec![0u8; side * side * 4];
        for (i, block) in blocks.chunks_exact(block_bytes).enumerate() {
            let (bx, by) = (i % (side / 4), i / (side / 4));
            let at = &mut out[(by * 4 * side + bx * 4) * 4..];
            if block_bytes == BC1_BLOCK_BYTES {
                bcdec_rs::bc1(block, at, side * 4);
            } else {
                bcdec_rs::bc7(block, at, side * 4);
            }
        }
        out
    }

    #[test]
    fn one_colour_decodes_to_that_colour_at_every_effort() {
        let colour = [40u8, 120, 200, 255];
        let texels = colour.repeat(16 * 16);
        let mut out = vec![1, 2, 3];
        // BC7 of one colour is exact to a code value (endpoint precision); BC1's 5:6:5 endpoints
        // are within 8 code values of any 8-bit colour (their interpolation narrows that).
        for effort in Bc7Effort::ALL {
            for alpha in [false, true] {
                encode_bc7(&texels, 16, 16, effort, alpha, &mut out).unwrap();
                assert_eq!(out.len(), 16 * BC7_BLOCK_BYTES);
                let back = decoded(&out, 16, BC7_BLOCK_BYTES);
                assert!(back.chunks_exact(4).all(|t| t.iter().zip(&colour).all(|(a, b)| a.abs_diff(*b) <= 1)));
            }
        }
        encode_bc1(&texels, 16, 16, &mut out).unwrap();
        assert_eq!(out.len(), 16 * BC1_BLOCK_BYTES);
        let back = decoded(&out, 16, BC1_BLOCK_BYTES);
        assert!(back.chunks_exact(4).all(|t| t[..3].iter().zip(&colour).all(|(a, b)| a.abs_diff(*b) <= 8)));
    }

    #[test]
    fn sizes_that_are_not_whole_blocks_or_not_the_texels_are_errors() {
        let mut out = Vec::new();
        let e = encode_bc1(&[0; 6 * 6 * 4], 6, 6, &mut out).unwrap_err();
        assert_eq!(e, BcError::Size { width: 6, height: 6 });
        assert!(e.to_string().contains("6x6"), "{e}");
        let e = encode_bc7(&[0; 10], 4, 4, Bc7Effort::Fast, false, &mut out).unwrap_err();
        assert_eq!(e, BcError::Length { width: 4, height: 4, len: 10, expected: 64 });
        assert_eq!(encode_bc1(&[], 0, 4, &mut out), Err(BcError::Size { width: 0, height: 4 }));
    }

    #[test]
    fn names_round_trip() {
        for v in Bc7Effort::ALL {
            assert_eq!(Bc7Effort::from_name(v.name()), Some(v));
        }
        assert_eq!(Bc7Effort::from_name("fastest"), None);
    }
}
