//! The Pareto fronts against time and size, in words: every front, cheapest first, and what
//! they show about lossless tiles and `box` LODs.

use std::collections::BTreeMap;

use vortex_bench::out;

use super::{PNG_FAST, Results, f1};
use crate::choice::CodecKey;
use crate::measure::{ImageResult, Measured};
use crate::pareto::{Axis, pareto};
use crate::sweep::Defaults;
use crate::tiler::{Bc7Effort, Codec, Filter};

/// `accuracy:fronts`.
pub fn fronts(res: &Results, d: &Defaults) -> String {
    let op = Results { all: res.all, main: res.main.iter().copied().filter(|r| !r.img.has_alpha()).collect() };
    let mut s = String::new();
    for (axis, name) in [(Axis::Time, "time"), (Axis::Size, "size")] {
        out!(s, "Pareto front against {name}, cheapest first:");
        out!(s);
        for r in &res.main {
            let ms: Vec<&Measured> = r.measured.values().collect();
            let pts: Vec<(f64, f64)> = ms.iter().map(|m| (axis.value(m, &r.img), m.plot_psnr())).collect();
            let front: Vec<String> = pareto(&pts)
                .into_iter()
                .map(|i| format!("{} ({}, {:.1} dB)", ms[i].choice.label(), axis.describe(pts[i].0), pts[i].1))
                .collect();
            out!(s, "- `{}`: {}", r.img.key, front.join(" → "));
        }
        out!(s);
    }
    out!(
        s,
        "Against time, the top of every front is the default filter with lossless tiles, since lossless tiles are cheap to make: raw {} ms/Mpx, PNG fast {}, against JPEG q85 {} and BC7 ultra-fast {} (opaque images, default filter). Against size the front climbs through JPEG, BC7 or high zstd levels and ends at lossless tiles. Choices with `box` LODs on a front: {}. They are cheap, but `box`'s error on LODs 1+ caps the PSNR of every codec stored with it (`box` + {}: {} / {} / {} dB on `photo` / `high-frequency` / `text`, against {} / {} / {} with the default filter).",
        f1(op.ms(d.opaque.filter, Codec::Raw)),
        f1(op.ms(d.opaque.filter, PNG_FAST)),
        f1(op.ms(d.opaque.filter, d.opaque.codec)),
        f1(op.ms(d.opaque.filter, Codec::Bc7 { effort: Bc7Effort::UltraFast })),
        box_on_fronts(&res.main),
        CodecKey::of(d.opaque.codec).label(),
        f1(op.num("photo", Filter::Box, d.opaque.codec, |m, _| m.all().psnr())),
        f1(op.num("high-frequency", Filter::Box, d.opaque.codec, |m, _| m.all().psnr())),
        f1(op.num("text", Filter::Box, d.opaque.codec, |m, _| m.all().psnr())),
        f1(op.num("photo", d.opaque.filter, d.opaque.codec, |m, _| m.all().psnr())),
        f1(op.num("high-frequency", d.opaque.filter, d.opaque.codec, |m, _| m.all().psnr())),
        f1(op.num("text", d.opaque.filter, d.opaque.codec, |m, _| m.all().psnr())),
    );
    s
}

/// Every choice with `box` LODs on a Pareto front: "label against time on `photo`, `text`".
pub fn box_on_fronts(results: &[&ImageResult]) -> String {
    let mut found: BTreeMap<(String, &str), Vec<String>> = BTreeMap::new();
    for r in results {
        let ms: Vec<&Measured> = r.measured.values().collect();
        for (axis, name) in [(Axis::Time, "time"), (Axis::Size, "size")] {
            let pts: Vec<(f64, f64)> = ms.iter().map(|m| (axis.value(m, &r.img), m.plot_psnr())).collect();
            for i in pareto(&pts).into_iter().filter(|&i| ms[i].choice.filter() == Filter::Box) {
                found.entry((ms[i].choice.label(), name)).or_default().push(format!("`{}`", r.img.key));
            }
        }
    }
    if found.is_empty() {
        return "none".into();
    }
    found
        .iter()
        .map(|((label, axis), keys)| format!("{label} against {axis} on {}", keys.join(", ")))
        .collect::<Vec<_>>()
        .join("; ")
}
