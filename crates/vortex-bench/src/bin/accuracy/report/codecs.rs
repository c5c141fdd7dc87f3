//! The tile-codec blocks: the table of every codec setting with the default filter, what it
//! shows, and the table of every choice on every image.

use vortex_bench::out;

use super::{PNG_FAST, Results, db, f1, f2, get, jpeg, kib};
use crate::TILE_SIZE;
use crate::choice::CodecKey;
use crate::measure::{ImageResult, Measured};
use crate::sweep::{Defaults, codec_sweep, is_default};
use crate::tiler::{Bc7Effort, Codec, PngLevel, RowFilter};

pub fn default_mark(codec: Codec, d: &Defaults) -> &'static str {
    if codec == d.opaque.codec {
        " (default)"
    } else if codec == d.alpha.codec {
        " (default with alpha)"
    } else if codec == d.bc7 {
        " (default effort)"
    } else if matches!(codec, Codec::Zstd { level, .. } if level == d.zstd_level) {
        " (default level)"
    } else {
        ""
    }
}

/// `accuracy:codecs-table`: the default filter's name, then the table.
pub fn table(res: &Results, d: &Defaults) -> String {
    let f = d.opaque.filter;
    let mut s = String::new();
    out!(s, "With the default filter (`{}`):", f.name());
    out!(s);
    let opaque: Vec<&ImageResult> = res.main.iter().copied().filter(|r| !r.img.has_alpha()).collect();
    let ms = |codec: Codec| {
        let (mut t, mut mpx) = (0.0, 0.0);
        for r in &opaque {
            if let Some(m) = get(r, f, codec) {
                t += m.median_s();
                mpx += r.img.megapixels();
            }
        }
        1000.0 * t / mpx
    };
    let bytes = |codec: Codec| {
        let v: Vec<f64> = opaque.iter().filter_map(|r| get(r, f, codec).map(|m| m.bytes_per_tile)).collect();
        v.iter().sum::<f64>() / v.len() as f64
    };
    let mut head = String::from("| codec | ms/Mpx | KiB/tile | bits/texel |");
    let mut rule = String::from("|---|---:|---:|---:|");
    for r in &res.main {
        head += &format!(" {} dB |", r.img.key);
        rule += "---:|";
    }
    out!(s, "{head}");
    out!(s, "{rule}");
    for codec in codec_sweep() {
        let b = bytes(codec);
        let mut row = format!(
            "| {}{} | {:.1} | {} | {:.2} |",
            CodecKey::of(codec).label(),
            default_mark(codec, d),
            ms(codec),
            kib(b),
            b * 8.0 / (TILE_SIZE * TILE_SIZE) as f64,
        );
        for r in &res.main {
            match get(r, f, codec) {
                Some(m) => row += &format!(" {} ({}) |", db(m.all().psnr()), db(m.lods[0].psnr())),
                None => row += " - |",
            }
        }
        out!(s, "{row}");
    }
    s
}

/// `accuracy:codecs-findings`: what the table shows, with its numbers.
pub fn findings(res: &Results, d: &Defaults) -> String {
    let f = d.opaque.filter;
    let opaque: Vec<&ImageResult> = res.main.iter().copied().filter(|r| !r.img.has_alpha()).collect();
    let mut s = String::new();

    let op = Results { all: res.all, main: opaque.clone() };
    let l0 = |key: &str, c: Codec| res.num(key, f, c, |m, _| m.lods[0].psnr());
    let b = |c: Codec| op.bytes(f, c) / 1024.0;
    let t = |c: Codec| op.ms(f, c);
    let bc7 = |e| Codec::Bc7 { effort: e };
    out!(
        s,
        "- **JPEG.** LOD 0 on `photo`: q50 {} dB, q75 {}, q85 {}, q95 {} (4:2:0); 4:4:4 adds {} dB at q85 for {}% more bytes and {}x the time. On `text` 4:4:4 adds {} dB at q85. On `high-frequency`, 4:2:0 stays at {}-{} dB at LOD 0 whatever the quality (1-texel red/green and blue/yellow detail averaged away), 4:4:4 reaches {} at q85 and {} at q95. Over all LODs of `text`, lossless tiles reach {} dB and JPEG q95 4:4:4 {}.",
        f1(l0("photo", jpeg(50, false))),
        f1(l0("photo", jpeg(75, false))),
        f1(l0("photo", jpeg(85, false))),
        f1(l0("photo", jpeg(95, false))),
        f1(l0("photo", jpeg(85, true)) - l0("photo", jpeg(85, false))),
        f1(100.0 * (op.bytes_ratio((f, jpeg(85, true)), (f, jpeg(85, false))) - 1.0)),
        f2(op.ratio((f, jpeg(85, true)), (f, jpeg(85, false)))),
        f1(l0("text", jpeg(85, true)) - l0("text", jpeg(85, false))),
        f1([50, 75, 85, 95].iter().map(|q| l0("high-frequency", jpeg(*q, false))).fold(f64::NAN, f64::min)),
        f1([50, 75, 85, 95].iter().map(|q| l0("high-frequency", jpeg(*q, false))).fold(f64::NAN, f64::max)),
        f1(l0("high-frequency", jpeg(85, true))),
        f1(l0("high-frequency", jpeg(95, true))),
        f1(res.num("text", f, PNG_FAST, |m, _| m.all().psnr())),
        f1(res.num("text", f, jpeg(95, true), |m, _| m.all().psnr())),
    );
    out!(
        s,
        "- **PNG.** `default` and `best` tiles are {}% and {}% smaller than `fast` ones for {}x and {}x the time; `best` buys almost nothing over `default`.",
        f1(100.0 * (1.0 - op.bytes_ratio((f, Codec::Png { level: PngLevel::Default }), (f, PNG_FAST)))),
        f1(100.0 * (1.0 - op.bytes_ratio((f, Codec::Png { level: PngLevel::Best }), (f, PNG_FAST)))),
        f1(op.ratio((f, Codec::Png { level: PngLevel::Default }), (f, PNG_FAST))),
        f1(op.ratio((f, Codec::Png { level: PngLevel::Best }), (f, PNG_FAST))),
    );
    let z = |level, delta| Codec::Zstd { level, filter: RowFilter::delta(delta) };
    out!(
        s,
        "- **zstd** (packs only): the row-delta filter makes tiles {}% smaller at level 3, in {}x the time. `zstd-delta` levels 1 / 3 / 9 / 19: {} / {} / {} / {} KiB per tile for {} / {} / {} / {} ms/Mpx; level 19 costs {}x level 3's time for {}% less. `zstd-delta 3` tiles are {}% smaller than PNG fast ones, in {}x the time. Raw: {} ms/Mpx, {} KiB.",
        f1(100.0 * (1.0 - op.bytes_ratio((f, z(3, true)), (f, z(3, false))))),
        f2(op.ratio((f, z(3, true)), (f, z(3, false)))),
        f1(b(z(1, true))),
        f1(b(z(3, true))),
        f1(b(z(9, true))),
        f1(b(z(19, true))),
        f1(t(z(1, true))),
        f1(t(z(3, true))),
        f1(t(z(9, true))),
        f1(t(z(19, true))),
        f1(op.ratio((f, z(19, true)), (f, z(3, true)))),
        f1(100.0 * (1.0 - op.bytes_ratio((f, z(19, true)), (f, z(3, true))))),
        f1(100.0 * (1.0 - op.bytes_ratio((f, z(3, true)), (f, PNG_FAST)))),
        f2(op.ratio((f, z(3, true)), (f, PNG_FAST))),
        f1(t(Codec::Raw)),
        f1(b(Codec::Raw)),
    );
    out!(
        s,
        "- **BC1 and BC7** (packs only, fixed 8 and 16 KiB per tile). LOD 0 on `photo` / `text`: BC1 {} / {} dB, BC7 ultra-fast {} / {}, very-fast {} / {}, basic {} / {}; very-fast takes {}x ultra-fast's time, basic {}x. BC1: {} ms/Mpx{}.",
        f1(l0("photo", Codec::Bc1)),
        f1(l0("text", Codec::Bc1)),
        f1(l0("photo", bc7(Bc7Effort::UltraFast))),
        f1(l0("text", bc7(Bc7Effort::UltraFast))),
        f1(l0("photo", bc7(Bc7Effort::VeryFast))),
        f1(l0("text", bc7(Bc7Effort::VeryFast))),
        f1(l0("photo", bc7(Bc7Effort::Basic))),
        f1(l0("text", bc7(Bc7Effort::Basic))),
        f1(op.ratio((f, bc7(Bc7Effort::VeryFast)), (f, bc7(Bc7Effort::UltraFast)))),
        f1(op.ratio((f, bc7(Bc7Effort::Basic)), (f, bc7(Bc7Effort::UltraFast)))),
        f1(t(Codec::Bc1)),
        if codec_sweep().iter().all(|c| t(*c) >= t(Codec::Bc1)) { ", the fastest codec of all" } else { "" },
    );
    s
}

/// `accuracy:every-choice`: every choice on every image, one table per image.
pub fn every_choice(res: &Results, d: &Defaults) -> String {
    let mut s = String::new();
    for r in res.all {
        out!(s, "**{}** (`{}`), {:.2} Mpx:", r.img.title, r.img.key, r.img.megapixels());
        out!(s);
        let alpha = r.img.has_alpha();
        out!(
            s,
            "| choice | ms/Mpx | runs | spread | KiB/tile | all LODs dB | LOD 0 dB | LOD 0 max | LODs 1+ dB | LODs 1+ max |{}",
            if alpha { " alpha dB | alpha max |" } else { "" }
        );
        out!(s, "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|{}", if alpha { "---:|---:|" } else { "" });
        let mut ms: Vec<&Measured> = r.measured.values().collect();
        ms.sort_by(|a, b| a.choice.family().cmp(&b.choice.family()).then(a.choice.cmp(&b.choice)));
        for m in ms {
            let (all, l0, c) = (m.all(), m.lods[0], m.coarse());
            let mut row = format!(
                "| {}{} | {:.1} | {} | {:.0}% | {} | {} | {} | {:.1} | {} | {:.1} |",
                m.choice.label(),
                if is_default(m, &r.img, d) { " (default)" } else { "" },
                m.ms_per_mpx(&r.img),
                m.times.len(),
                100.0 * m.spread(),
                kib(m.bytes_per_tile),
                db(all.psnr()),
                db(l0.psnr()),
                l0.max,
                db(c.psnr()),
                c.max
            );
            if alpha {
                row += &format!(" {} | {:.1} |", db(all.psnr_alpha()), all.max_a);
            }
            out!(s, "{row}");
        }
        out!(s);
    }
    s
}
