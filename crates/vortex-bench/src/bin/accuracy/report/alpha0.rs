//! The blocks on colour under alpha 0: the same cut-outs with noise and with black where alpha
//! is 0, side by side, and what that shows.

use vortex_bench::out;

use super::{PNG_FAST, Results, db, f1, get, kib};
use crate::measure::{ImageResult, Measured};
use crate::sweep::Defaults;
use crate::tiler::{Bc7Effort, Codec, Filter};

/// The noisy and the clean cut-outs.
fn pair<'a>(res: &Results<'a>) -> Option<(&'a ImageResult, &'a ImageResult)> {
    Some((res.image("alpha")?, res.image("alpha-clean")?))
}

/// `accuracy:alpha0-table`.
pub fn table(res: &Results) -> String {
    let Some((noisy, clean)) = pair(res) else { return String::new() };
    let mut s = String::new();
    out!(
        s,
        "| choice | KiB/tile | KiB/tile, black under 0 | LOD 0 dB | LOD 0 dB, black under 0 | alpha dB / max | alpha dB / max, black under 0 | LODs 1+ dB | LODs 1+ dB, black under 0 |"
    );
    out!(s, "|---|---:|---:|---:|---:|---:|---:|---:|---:|");
    for (choice, m) in &clean.measured {
        let Some(n) = noisy.measured.get(choice) else { continue };
        let (na, ca) = (n.all(), m.all());
        out!(
            s,
            "| {} | {} | {} | {} | {} | {} / {:.0} | {} / {:.0} | {} | {} |",
            choice.label(),
            kib(n.bytes_per_tile),
            kib(m.bytes_per_tile),
            db(n.lods[0].psnr()),
            db(m.lods[0].psnr()),
            db(na.psnr_alpha()),
            na.max_a,
            db(ca.psnr_alpha()),
            ca.max_a,
            db(n.coarse().psnr()),
            db(m.coarse().psnr()),
        );
    }
    s
}

/// `accuracy:alpha0-findings`.
pub fn findings(res: &Results, d: &Defaults) -> String {
    let Some((noisy, clean)) = pair(res) else { return String::new() };
    let mut s = String::new();
    let get2 = |r: &ImageResult, f: Filter, c: Codec, v: &dyn Fn(&Measured) -> f64| get(r, f, c).map_or(f64::NAN, v);
    let bc7 = |e| Codec::Bc7 { effort: e };
    out!(
        s,
        "- **Lossless tiles carry the noise**: PNG fast tiles are {}x larger with it ({} vs {} KiB).",
        f1(get2(noisy, d.alpha.filter, PNG_FAST, &|m| m.bytes_per_tile)
            / get2(clean, d.alpha.filter, PNG_FAST, &|m| m.bytes_per_tile)),
        kib(get2(noisy, d.alpha.filter, PNG_FAST, &|m| m.bytes_per_tile)),
        kib(get2(clean, d.alpha.filter, PNG_FAST, &|m| m.bytes_per_tile)),
    );
    out!(
        s,
        "- **BC7 ignores it.** Intel's encoder weighs the colour of every texel alike and would spend a block's endpoints on the noise (before the tiler cleared it, alpha was off by up to 225 code values and more effort made it worse); the tiler now stores colour under alpha 0 as 0 before BC7 encoding. LOD 0: {} / {} / {} dB (ultra-fast / very-fast / basic) with the noise, {} / {} / {} dB with black; alpha off by at most {} code values.",
        f1(get2(noisy, d.alpha.filter, bc7(Bc7Effort::UltraFast), &|m| m.lods[0].psnr())),
        f1(get2(noisy, d.alpha.filter, bc7(Bc7Effort::VeryFast), &|m| m.lods[0].psnr())),
        f1(get2(noisy, d.alpha.filter, bc7(Bc7Effort::Basic), &|m| m.lods[0].psnr())),
        f1(get2(clean, d.alpha.filter, bc7(Bc7Effort::UltraFast), &|m| m.lods[0].psnr())),
        f1(get2(clean, d.alpha.filter, bc7(Bc7Effort::VeryFast), &|m| m.lods[0].psnr())),
        f1(get2(clean, d.alpha.filter, bc7(Bc7Effort::Basic), &|m| m.lods[0].psnr())),
        f1([Bc7Effort::UltraFast, Bc7Effort::VeryFast, Bc7Effort::Basic]
            .iter()
            .map(|e| get2(noisy, d.alpha.filter, bc7(*e), &|m| m.lods[0].max_a))
            .fold(f64::NAN, f64::max)),
    );
    out!(
        s,
        "- **Black is no cure for `box`**: it trades the noise fringe for a dark one (LODs 1+: {} dB with noise, {} with black). The premultiplied filters ignore the colour under alpha 0 entirely and give the same texels either way ({} dB with `linear-premultiplied`); at LODs 1+ they store colour 0 where a whole footprint is transparent, while LOD 0 keeps the source's colour.",
        db(get2(noisy, Filter::Box, PNG_FAST, &|m| m.coarse().psnr())),
        db(get2(clean, Filter::Box, PNG_FAST, &|m| m.coarse().psnr())),
        db(get2(clean, Filter::LinearPremultiplied, PNG_FAST, &|m| m.coarse().psnr())),
    );
    s
}
