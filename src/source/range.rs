//! `--range MIN:MAX`: 32-bit integer and float samples mapped linearly onto 8 or 16 bits, for
//! the codecs that hold no more (JPEG, PNG, BC*) and the 8/16-bit tile types.
//!
//! MIN becomes 0 and MAX the largest code (255 or 65535), each sample rounded to the nearest
//! code (halves away from zero). Samples below MIN or above MAX, and NaNs, cannot be shown: they
//! are clamped to the nearest end (NaN to MIN) and counted, and the summary says how many, so
//! a range that cuts the data is never silent. Every channel is mapped, alpha included.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use super::{Embedded, ImageHeader, RowSource};
use crate::error::{Result, TilerError};
use crate::pixel::{Depth, PixelLayout};

/// The values mapped to the first and the last code.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Range {
    /// The value mapped to code 0; lower values clamp to it.
    pub min: f64,
    /// The value mapped to the largest code (255, or 65535 for 16 bits); higher ones clamp.
    pub max: f64,
}

impl std::str::FromStr for Range {
    type Err = String;

    /// `MIN:MAX`, two finite numbers with MIN < MAX (e.g. `0:4095`, `-0.5:1.5`).
    fn from_str(text: &str) -> std::result::Result<Range, String> {
        let (min, max) = text.split_once(':').ok_or_else(|| format!("{text:?} is not MIN:MAX (e.g. 0:4095)"))?;
        let number = |s: &str| match s.trim().parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(format!("{s:?} in {text:?} is not a finite number")),
        };
        let (min, max) = (number(min)?, number(max)?);
        if min >= max {
            return Err(format!("{text:?}: MIN must be below MAX"));
        }
        Ok(Range { min, max })
    }
}

/// Samples outside the range, counted as the rows go by and read after the run.
#[derive(Clone, Debug, Default)]
struct Clamped(Arc<AtomicU64>);

impl Clamped {
    fn count(&self) -> u64 {
        self.0.load(Ordering::Relaxed)
    }
}

/// `source`'s 32-bit samples mapped through `range` to `depth` (8 or 16 bits); the samples
/// clamped are told by its [`RowSource::after_run`].
pub fn map(source: Box<dyn RowSource>, range: Range, depth: Depth) -> Result<Box<dyn RowSource>> {
    let from = source.layout();
    if from.depth.is_narrow_int() {
        return Err(TilerError::Options(format!(
            "--range maps 32-bit integer and float samples onto 8 or 16 bits; the source is {from} already"
        )));
    }
    if !depth.is_narrow_int() {
        return Err(TilerError::Options(format!(
            "--range maps onto 8 or 16 bits; --tile-type {} keeps the samples as they are: leave --range out",
            depth.tile_type()
        )));
    }
    let clamped = Clamped::default();
    let header = ImageHeader { layout: PixelLayout::new(from.channels, depth), ..source.header() };
    let row = vec![0u8; source.width() as usize * from.bytes_per_pixel()];
    let mapped = Mapped { inner: source, range, header, from: from.depth, row, clamped };
    Ok(Box::new(mapped))
}

struct Mapped {
    inner: Box<dyn RowSource>,
    range: Range,
    /// The mapped image's header (8- or 16-bit samples).
    header: ImageHeader,
    /// The source's depth (U32 or F32).
    from: Depth,
    /// A source row as read.
    row: Vec<u8>,
    clamped: Clamped,
}

impl Mapped {}

impl Range {
    /// One sample's code in `0..=top`, and whether the sample was outside the range.
    fn code(self, value: f64, top: f64) -> (f64, bool) {
        let scaled = (value - self.min) / (self.max - self.min) * top;
        match scaled {
            s if s.is_nan() => (0.0, true),
            s if s < 0.0 => (0.0, value < self.min),
            s if s > top => (top, value > self.max),
            s => (s.round(), false),
        }
    }
}

impl RowSource for Mapped {
    fn header(&self) -> ImageHeader {
        self.header
    }

    fn read_row(&mut self, out: &mut [u8]) -> Result<()> {
        let samples = out.len() / self.header.layout.depth.bytes();
        let row = &mut self.row[..samples * 4];
        self.inner.read_row(row)?;
        let top = if self.header.layout.depth == Depth::U8 { 255.0 } else { 65535.0 };
        let mut outside = 0u64;
        for (i, bytes) in row.chunks_exact(4).enumerate() {
            let bytes = [bytes[0], bytes[1], bytes[2], bytes[3]];
            let value = match self.from {
                Depth::F32 => f32::from_ne_bytes(bytes) as f64,
                _ => u32::from_ne_bytes(bytes) as f64,
            };
            let (code, out_of_range) = self.range.code(value, top);
            outside += out_of_range as u64;
            match self.header.layout.depth {
                Depth::U8 => out[i] = code as u8,
                _ => out[2 * i..2 * i + 2].copy_from_slice(&(code as u16).to_ne_bytes()),
            }
        }
        self.clamped.0.fetch_add(outside, Ordering::Relaxed);
        Ok(())
    }

    fn describe(&self) -> String {
        format!(
            "{}, mapped from {} to {} bits (--range {}:{})",
            self.inner.describe(),
            self.from.tile_type(),
            8 * self.header.layout.depth.bytes(),
            short(self.range.min),
            short(self.range.max)
        )
    }

    forward_row_order_to_inner!();

    fn embedded(&self) -> Embedded {
        self.inner.embedded()
    }

    fn after_run(&self) -> Option<Box<dyn Fn() -> String + Send>> {
        let clamped = self.clamped.clone();
        Some(Box::new(move || match clamped.count() {
            0 => "no sample outside --range".to_string(),
            n => format!("{n} samples outside --range clamped to it"),
        }))
    }
}

/// `v` as a summary shows it: as written between 1e-4 and 1e15 (`0.5`, `4095`), else in
/// exponent form (`1e300`, not 301 digits).
fn short(v: f64) -> String {
    match v.abs() {
        a if a == 0.0 || (1e-4..1e15).contains(&a) => format!("{v}"),
        _ => format!("{v:e}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_in_the_summary_are_short() {
        assert_eq!(short(-0.5), "-0.5");
        assert_eq!(short(4095.0), "4095");
        assert_eq!(short(0.0), "0");
        assert_eq!(short(-1e300), "-1e300");
        assert_eq!(short(f64::MAX), "1.7976931348623157e308");
        assert_eq!(short(1e-7), "1e-7");
    }

    #[test]
    fn ranges_parse_and_refuse_what_is_not_one() {
        assert_eq!("-0.5:1.5".parse::<Range>(), Ok(Range { min: -0.5, max: 1.5 }));
        assert_eq!("0:4095".parse::<Range>(), Ok(Range { min: 0.0, max: 4095.0 }));
        for bad in ["4095", "1:1", "2:1", "a:1", "0:inf", "NaN:1"] {
            assert!(bad.parse::<Range>().is_err(), "{bad}");
        }
    }
}
