//! ICC colour management: an embedded profile other than sRGB is converted to sRGB, row by row,
//! through LittleCMS (the `lcms2` crate over the system's liblcms2), before the pyramid: its
//! linear-light filters assume sRGB's transfer curve, and browsers show untagged tiles as sRGB.
//!
//! RGB(A) and grey(A) stay what they are, 8 or 16 bits per sample; alpha is copied. Grey goes to
//! a grey profile with sRGB's curve. A profile that maps every probe colour to itself within
//! one step of the sample scale is sRGB already and is left alone (no CPU spent). CMYK JPEG rows
//! go through `Cmyk` into RGB.

use std::path::Path;

use lcms2::{CIExyY, ColorSpaceSignature, Flags, Intent, PixelFormat, Profile, ThreadContext, ToneCurve, Transform};

use super::{ImageHeader, RowSource};
use crate::error::{Result, TilerError};
use crate::pixel::{Channels, Depth, PixelLayout};

/// Where a CMYK JPEG without a profile of its own is converted from: Ghostscript's default CMYK
/// profile (a SWOP-like press, Debian package libgs-common), the profile Ghostscript and
/// ImageMagick-with-Ghostscript assume for untagged CMYK.
pub const DEFAULT_CMYK_PROFILE: &str = "/usr/share/color/icc/ghostscript/default_cmyk.icc";

/// The largest ICC profile read from any image: 16 MiB, just above the most a JPEG can carry
/// (255 APP2 chunks of 65519 bytes: 16,707,345 bytes); real profiles are a few hundred bytes to
/// a few MiB. The cap is the same for every `--max-memory`, so whether a profile is honoured
/// never depends on the budget; a profile held also counts against `--max-memory`
/// (`Described`).
pub(crate) const MAX_PROFILE_BYTES: u64 = 16 << 20;

/// The error for an embedded profile (`whence`: where the file keeps it) of `bytes` bytes
/// (`None`: more than the cap, where it was cut off while inflating), past
/// [`MAX_PROFILE_BYTES`].
pub(crate) fn too_large(path: &Path, bytes: Option<u64>, whence: &str) -> TilerError {
    let holds = bytes.map_or_else(String::new, |n| format!("{n} bytes, "));
    TilerError::unsupported(
        path,
        format!(
            "the embedded ICC profile ({whence}) holds {holds}more than the {} MiB a profile may have here; strip it (`exiftool -icc_profile= FILE`) or convert the image to sRGB first",
            MAX_PROFILE_BYTES >> 20
        ),
    )
}

type RowTransform = Transform<u8, u8, ThreadContext>;

/// The intent vips and browsers use for matrix-shaper photo profiles: relative colorimetric
/// (media white to media white); the perceptual tables of LUT profiles are not wanted here.
const INTENT: Intent = Intent::RelativeColorimetric;

fn lcms_error(path: &Path, what: &str, e: impl std::fmt::Display) -> TilerError {
    // LittleCMS's "Could not create the object." has a second line guessing at causes.
    let e = e.to_string();
    let e = e.lines().next().unwrap_or_default().trim_end_matches('.');
    TilerError::decode(
        path,
        format!(
            "{what}: {e}; convert the image to sRGB first, or pass --keep-icc to keep its pixels as stored (and the profile with them)"
        ),
    )
}

fn format_of(layout: PixelLayout) -> PixelFormat {
    match (layout.channels, layout.depth) {
        (Channels::Grey, Depth::U8) => PixelFormat::GRAY_8,
        (Channels::GreyAlpha, Depth::U8) => PixelFormat::GRAYA_8,
        (Channels::Rgb, Depth::U8) => PixelFormat::RGB_8,
        (Channels::Rgba, Depth::U8) => PixelFormat::RGBA_8,
        (Channels::Grey, Depth::U16) => PixelFormat::GRAY_16,
        (Channels::GreyAlpha, Depth::U16) => PixelFormat::GRAYA_16,
        (Channels::Rgb, Depth::U16) => PixelFormat::RGB_16,
        (Channels::Rgba, Depth::U16) => PixelFormat::RGBA_16,
        // `to_srgb` converts 8- and 16-bit images only.
        (_, _) => PixelFormat::RGBA_16,
    }
}

/// The sRGB (or sRGB-curve grey) profile a `layout` is converted into.
fn target(layout: PixelLayout) -> Result<Profile<ThreadContext>> {
    if is_colour(layout) {
        return Ok(Profile::new_srgb_context(ThreadContext::new()));
    }
    let failed = |e: lcms2::Error| TilerError::Internal(format!("LittleCMS could not make an sRGB grey profile: {e}"));
    // sRGB's own curve (IEC 61966-2-1) as an ICC parametric curve of type 4.
    let curve =
        ToneCurve::new_parametric(4, &[2.4, 1.0 / 1.055, 0.055 / 1.055, 1.0 / 12.92, 0.04045]).map_err(failed)?;
    let d50 = CIExyY { x: 0.3457, y: 0.3585, Y: 1.0 };
    Profile::new_gray_context(ThreadContext::new(), &d50, &curve).map_err(failed)
}

fn open_profile(path: &Path, icc: &[u8]) -> Result<Profile<ThreadContext>> {
    Profile::new_icc_context(ThreadContext::new(), icc)
        .map_err(|e| lcms_error(path, &format!("the embedded ICC profile ({} bytes) is damaged", icc.len()), e))
}

/// The profile's description, for the summary line ("Adobe RGB (1998)").
fn name(profile: &Profile<ThreadContext>) -> String {
    profile
        .info(lcms2::InfoType::Description, lcms2::Locale::none())
        .map(|s| s.trim().to_string())
        .filter(|s| !s.is_empty())
        .unwrap_or_else(|| "unnamed".to_string())
}

/// `inner`, its colours converted from the embedded profile `icc` to sRGB, or `inner` as it is
/// when the profile is sRGB already.
pub fn to_srgb(path: &Path, inner: Box<dyn RowSource>, icc: &[u8]) -> Result<Box<dyn RowSource>> {
    let layout = inner.layout();
    let profile = open_profile(path, icc)?;
    let wanted = if is_colour(layout) { ColorSpaceSignature::RgbData } else { ColorSpaceSignature::GrayData };
    if profile.color_space() != wanted {
        return Err(lcms_error(
            path,
            &format!("the embedded ICC profile is for {:?} but the image is {layout}", profile.color_space()),
            "they do not match",
        ));
    }
    if !layout.depth.is_narrow_int() {
        // Colour management of measurements (float, 32-bit) is not what their users want.
        return Ok(Box::new(Described {
            inner,
            note: format!("ICC profile of a {layout} image kept as data, not converted"),
            transform: None,
            held: icc.len() as u64,
        }));
    }
    let format = format_of(layout);
    let transform = RowTransform::new_flags_context(
        ThreadContext::new(),
        &profile,
        format,
        &target(layout)?,
        format,
        INTENT,
        Flags::COPY_ALPHA,
    )
    .map_err(|e| lcms_error(path, "LittleCMS cannot convert from the embedded ICC profile", e))?;
    let name = name(&profile);
    if is_identity(&transform, layout) {
        return Ok(Box::new(Described {
            inner,
            note: format!("ICC profile '{name}' is sRGB: left as is"),
            transform: None,
            held: icc.len() as u64,
        }));
    }
    Ok(Box::new(Described {
        inner,
        note: format!("ICC '{name}' converted to sRGB (LittleCMS)"),
        transform: Some(transform),
        held: icc.len() as u64,
    }))
}

/// Whether `transform` leaves a grid of colours (and greys) unchanged within one step.
fn is_identity(transform: &RowTransform, layout: PixelLayout) -> bool {
    let levels: Vec<u16> = (0..=8u16).map(|i| (i * 32).min(255)).collect();
    let channels = layout.channels.count();
    let mut probe = Vec::new();
    let mut push = |v: &[u16]| {
        for &s in v {
            match layout.depth {
                Depth::U8 => probe.push(s as u8),
                _ => probe.extend_from_slice(&(s * 257).to_ne_bytes()),
            }
        }
    };
    let colour = is_colour(layout);
    for &r in &levels {
        for &g in if colour { &levels[..] } else { &levels[..1] } {
            for &b in if colour { &levels[..] } else { &levels[..1] } {
                let mut texel = if colour { vec![r, g, b] } else { vec![r] };
                if layout.channels.has_alpha() {
                    texel.push(255);
                }
                texel.truncate(channels);
                push(&texel);
            }
        }
    }
    let mut out = probe.clone();
    transform.transform_in_place(&mut out);
    let step = if layout.depth == Depth::U8 { 1 } else { 257 };
    match layout.depth {
        Depth::U8 => probe.iter().zip(&out).all(|(a, b)| a.abs_diff(*b) <= step as u8),
        _ => {
            let wide = |v: &[u8]| -> Vec<u16> { v.chunks_exact(2).map(|c| u16::from_ne_bytes([c[0], c[1]])).collect() };
            wide(&probe).iter().zip(&wide(&out)).all(|(a, b)| a.abs_diff(*b) <= step)
        }
    }
}

/// A source with a note for the summary line, its rows converted by `transform` as they pass
/// (to sRGB), or passed through as they are.
pub(crate) struct Described {
    pub inner: Box<dyn RowSource>,
    pub note: String,
    pub transform: Option<RowTransform>,
    /// The bytes of an ICC profile held for the run (by the source and LittleCMS, or for the
    /// output to carry), counted against `--max-memory` with the decoder's buffers.
    pub held: u64,
}

impl RowSource for Described {
    fn header(&self) -> ImageHeader {
        self.inner.header()
    }
    fn read_row(&mut self, row: &mut [u8]) -> Result<()> {
        self.inner.read_row(row)?;
        if let Some(transform) = &self.transform {
            transform.transform_in_place(row);
        }
        Ok(())
    }
    fn describe(&self) -> String {
        format!("{}; {}", self.inner.describe(), self.note)
    }
    forward_row_order_to_inner!(held);
    /// Only rows passed through as they are may be copied as stored.
    fn stored_tiles(&self) -> Option<std::sync::Arc<dyn crate::source::stored::StoredTiles>> {
        self.transform.is_none().then(|| self.inner.stored_tiles()).flatten()
    }
    fn halved(&self) -> Option<Box<dyn RowSource>> {
        self.transform.is_none().then(|| self.inner.halved()).flatten()
    }
    fn stored_levels(&self) -> Result<Option<crate::source::stored::StoredLevels>> {
        match self.transform {
            None => self.inner.stored_levels(),
            Some(_) => Ok(None),
        }
    }
}

/// CMYK texels (8 bits, Adobe-inverted or not, or 16 bits) to sRGB through a CMYK profile.
pub(crate) struct Cmyk {
    transform: Transform<u8, u8, ThreadContext>,
    /// Where the profile came from, for the summary line.
    pub note: String,
}

impl Cmyk {
    /// The converter for a CMYK image with the embedded profile `icc`, or without one the
    /// default CMYK profile. `inverted`: 0 means full ink, as Photoshop writes CMYK JPEGs (an
    /// Adobe APP14 marker says so). `sixteen`: 16-bit samples in and out (native byte order),
    /// as a 16-bit CMYK TIFF holds them, kept at 16 bits.
    pub fn new(path: &Path, icc: Option<&[u8]>, inverted: bool, sixteen: bool) -> Result<Cmyk> {
        let (profile, whence) = match icc {
            Some(icc) => {
                let profile = open_profile(path, icc)?;
                let name = name(&profile);
                (profile, format!("embedded ICC '{name}'"))
            }
            None => {
                let bytes = std::fs::read(DEFAULT_CMYK_PROFILE).map_err(|e| {
                    TilerError::unsupported(
                        path,
                        format!(
                            "the CMYK image has no ICC profile and the default CMYK profile {DEFAULT_CMYK_PROFILE} cannot be read ({e}); install Debian's libgs-common, or convert the image to RGB first"
                        ),
                    )
                })?;
                let profile = Profile::new_icc_context(ThreadContext::new(), &bytes)
                    .map_err(|e| lcms_error(Path::new(DEFAULT_CMYK_PROFILE), "not a usable ICC profile", e))?;
                (profile, format!("no profile embedded: {DEFAULT_CMYK_PROFILE}"))
            }
        };
        if profile.color_space() != ColorSpaceSignature::CmykData {
            return Err(lcms_error(
                path,
                &format!("the embedded ICC profile is for {:?} but the image is CMYK", profile.color_space()),
                "they do not match",
            ));
        }
        let (input, output) = match (sixteen, inverted) {
            (false, false) => (PixelFormat::CMYK_8, PixelFormat::RGB_8),
            (false, true) => (PixelFormat::CMYK_8_REV, PixelFormat::RGB_8),
            (true, false) => (PixelFormat::CMYK_16, PixelFormat::RGB_16),
            (true, true) => (PixelFormat::CMYK_16_REV, PixelFormat::RGB_16),
        };
        let transform = Transform::new_flags_context(
            ThreadContext::new(),
            &profile,
            input,
            &Profile::new_srgb_context(ThreadContext::new()),
            output,
            INTENT,
            Flags::default(),
        )
        .map_err(|e| lcms_error(path, "LittleCMS cannot convert from the CMYK profile", e))?;
        let inverted = if inverted { ", Adobe-inverted" } else { "" };
        Ok(Cmyk { transform, note: format!("CMYK{inverted} to sRGB through {whence} (LittleCMS)") })
    }

    /// Converts one row of CMYK texels into RGB texels (each sample 2 bytes where `sixteen`).
    pub fn convert(&self, cmyk: &[u8], rgb: &mut [u8]) {
        self.transform.transform_pixels(cmyk, rgb);
    }
}

fn is_colour(layout: PixelLayout) -> bool {
    matches!(layout.channels, Channels::Rgb | Channels::Rgba)
}
