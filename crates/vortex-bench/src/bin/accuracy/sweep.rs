//! Which choices a run measures, and the project's defaults they are judged against: the codec
//! sweep, the filters that apply to an image, what `split` resolves with no flags.

use anyhow::{Result, bail};

use crate::choice::Choice;
use crate::choice::PNG_LEVELS;
use crate::images::Img;
use crate::measure::Measured;
use crate::tiler::{
    Bc7Effort, Channels, Codec, CodecChoice, Depth, Filter, PixelLayout, PngLevel, Requested, RowFilter, SplitOptions,
    Subsampling, settings,
};

/// The project's defaults, as `split` resolves them with no flags.
pub struct Defaults {
    pub opaque: SplitOptions,
    pub alpha: SplitOptions,
    pub zstd_level: i32,
    pub bc7: Codec,
}

pub fn defaults() -> Result<Defaults> {
    let rgb = PixelLayout::new(Channels::Rgb, Depth::U8);
    let rgba = PixelLayout::new(Channels::Rgba, Depth::U8);
    let none = Requested::default();
    let with = |codec| Requested { codec: Some(codec), ..Requested::default() };
    let zstd = settings::resolve(&with(CodecChoice::Zstd), None, rgb)?.0.codec;
    let bc7 = settings::resolve(&with(CodecChoice::Bc7), None, rgb)?.0.codec;
    Ok(Defaults {
        opaque: settings::resolve(&none, None, rgb)?.0,
        alpha: settings::resolve(&none, None, rgba)?.0,
        zstd_level: match zstd {
            Codec::Zstd { level, .. } => level,
            _ => bail!("zstd resolved to {}", zstd.name()),
        },
        bc7,
    })
}

/// Every codec setting measured (with the default filter).
pub fn codec_sweep() -> Vec<Codec> {
    let mut v = Vec::new();
    for quality in [50, 75, 85, 95] {
        for subsampling in [Subsampling::S420, Subsampling::S444] {
            v.push(Codec::Jpeg { quality, subsampling });
        }
    }
    v.extend(PNG_LEVELS.map(|level| Codec::Png { level }));
    v.push(Codec::Raw);
    for delta in [false, true] {
        for level in [1, 3, 9, 19] {
            v.push(Codec::Zstd { level, filter: RowFilter::delta(delta) });
        }
    }
    v.push(Codec::Bc1);
    v.extend([Bc7Effort::UltraFast, Bc7Effort::VeryFast, Bc7Effort::Basic].map(|effort| Codec::Bc7 { effort }));
    v
}

/// Whether `choice` is measured on `img`: the codec must store its texels, and without alpha
/// `premultiplied` is `box` and `linear` is `linear-premultiplied` (the same code), so only
/// the latter of each pair runs.
pub fn applies(img: &Img, extra: bool, choice: Choice) -> bool {
    let codec = choice.codec.codec();
    if codec.stored_layout(img.layout(), false, None).is_err() {
        return false;
    }
    let filter = choice.filter();
    if !img.has_alpha() && matches!(filter, Filter::Premultiplied | Filter::Linear) {
        return false;
    }
    !extra
        || (filter.is_exact() && codec == Codec::Png { level: PngLevel::Fast })
        || (filter == Filter::default() && matches!(codec, Codec::Bc7 { .. }))
}

pub fn is_default(m: &Measured, img: &Img, d: &Defaults) -> bool {
    let o = if img.has_alpha() { &d.alpha } else { &d.opaque };
    m.choice == Choice::new(o.filter, o.codec)
}
