//! The opening blocks of `docs/accuracy.md`: when and where the run happened, the headline
//! numbers, what was built and measured (sizes, runs, spreads, tile counts).

use vortex_bench::out;
use vortex_bench::run_info::{machine, today};

use super::{PNG_FAST, Results, RunInfo, f1, f2, filters::filter_verdict, jpeg};
use crate::measure::ImageResult;
use crate::sweep::Defaults;
use crate::tiler::{Bc7Effort, Codec, Filter};
use crate::{BORDER, SLOW_RUN_S, SLOW_RUNS, TILE_SIZE};

/// `accuracy:run`: the date, duration, machine and load of this run.
pub fn run(run: &RunInfo) -> String {
    let mut s = String::new();
    out!(
        s,
        "Written by `accuracy` (`crates/vortex-bench`) on {} in {:.0} s on {}, Linux; the 1-minute load average was {} at the start and {} at the end{}.",
        today(),
        run.seconds,
        machine(),
        run.load_start.map_or("?".into(), |l| format!("{l:.2}")),
        run.load_end.map_or("?".into(), |l| format!("{l:.2}")),
        if run.load_start.is_some_and(|l| l >= 1.0) { " (other work shared the machine)" } else { "" }
    );
    s
}

/// `accuracy:summary`: "In short", the headline numbers and the verdict on the default filter.
pub fn summary(res: &Results, d: &Defaults) -> String {
    let mut s = String::new();
    let op = Results { all: res.all, main: res.main.iter().copied().filter(|r| !r.img.has_alpha()).collect() };
    let coarse = |key: &str, f: Filter| res.num(key, f, PNG_FAST, |m, _| m.coarse().psnr());
    let gains: Vec<(String, f64, f64)> = res
        .main
        .iter()
        .map(|r| {
            (r.img.key.to_string(), coarse(r.img.key, Filter::Box), coarse(r.img.key, Filter::LinearPremultiplied))
        })
        .collect();
    let list =
        gains.iter().map(|(k, b, l)| format!("{} to {} dB on `{k}`", f1(*b), f1(*l))).collect::<Vec<_>>().join(", ");
    out!(
        s,
        "- **The LOD filter matters more than the codec.** Going from `box` (the mean of stored sRGB values, as `vips dzsave` averages) to `linear-premultiplied` (the default; `linear` on images without alpha) raises the PSNR of LODs 1+ against the physically right reference from {list}, for {}x the time with raw tiles (the pyramid's own cost) and {}x with PNG fast tiles. `box` is exact to its own definition (within 0.5) but wrong about light: it averages sRGB code values.",
        f2(res.ratio((Filter::LinearPremultiplied, Codec::Raw), (Filter::Box, Codec::Raw))),
        f2(res.ratio((Filter::LinearPremultiplied, PNG_FAST), (Filter::Box, PNG_FAST)))
    );
    let l0 = |key: &str, c: Codec| res.num(key, d.opaque.filter, c, |m, _| m.lods[0].psnr());
    out!(
        s,
        "- **JPEG q85 4:2:0** (the default for opaque images) gives {} dB at LOD 0 on `photo` for {} KiB per tile; 4:4:4 {} dB for {}% more bytes. 4:2:0 cannot hold colour detail of one or two texels at any quality: {} dB at LOD 0 on `high-frequency` (q95: {}), where 4:4:4 reaches {} dB.",
        f1(l0("photo", d.opaque.codec)),
        f1(res.num("photo", d.opaque.filter, d.opaque.codec, |m, _| m.bytes_per_tile / 1024.0)),
        f1(l0("photo", jpeg(85, true))),
        f1(100.0 * (res.bytes_ratio((d.opaque.filter, jpeg(85, true)), (d.opaque.filter, jpeg(85, false))) - 1.0)),
        f1(l0("high-frequency", jpeg(85, false))),
        f1(l0("high-frequency", jpeg(95, false))),
        f1(l0("high-frequency", jpeg(85, true)))
    );
    out!(
        s,
        "- **BC7 ultra-fast** (the BC7 default) is {} dB at LOD 0 on `photo`, 16 KiB per tile; very-fast adds {} dB for {}x the time. Random colour under alpha 0 costs it nothing, as it is cleared before encoding (`alpha`, LOD 0: ultra-fast {} dB, very-fast {} dB; see [below](#colour-under-alpha-0)).",
        f1(l0("photo", Codec::Bc7 { effort: Bc7Effort::UltraFast })),
        f1(l0("photo", Codec::Bc7 { effort: Bc7Effort::VeryFast })
            - l0("photo", Codec::Bc7 { effort: Bc7Effort::UltraFast })),
        f1(op.ratio(
            (d.opaque.filter, Codec::Bc7 { effort: Bc7Effort::VeryFast }),
            (d.opaque.filter, Codec::Bc7 { effort: Bc7Effort::UltraFast })
        )),
        f1(res.num("alpha", d.alpha.filter, Codec::Bc7 { effort: Bc7Effort::UltraFast }, |m, _| m.lods[0].psnr())),
        f1(res.num("alpha", d.alpha.filter, Codec::Bc7 { effort: Bc7Effort::VeryFast }, |m, _| m.lods[0].psnr())),
    );
    let clearly = filter_verdict(res, d).3;
    out!(
        s,
        "- **Defaults**: the numbers {} `linear-premultiplied` over `box` as the default filter (the project's default since these measurements), and support the codec defaults; see [Defaults](#defaults).",
        if clearly { "clearly favour" } else { "do not clearly favour" }
    );
    s
}

/// `accuracy:setup`: how each choice is built and checked, and the images.
pub fn setup(all: &[ImageResult], run: &RunInfo) -> String {
    let (w, h) = run.size;
    let layout = &run.layout;
    let mut s = String::new();
    out!(
        s,
        "Every choice builds the whole pyramid of {w}x{h} 8-bit synthetic images through the real pipeline (`split::split` into a pack, as `split --pack` does) in {}-texel tiles with a border of {} ({}-texel payloads: {} x {} tiles at LOD 0, {} LODs; neither side is a multiple of 8, so the last texel column and row of LODs 1-{} have partial footprints). The pack's tiles are decoded with `Pack::decode_rgba8` (as `verify --decode` and the runtime's loader do) and every texel of every LOD is compared with a float64 reference pyramid computed from the source. The images are generated, deterministically, by the program:",
        TILE_SIZE,
        BORDER,
        layout.payload(),
        layout.columns,
        layout.rows,
        layout.lod_count,
        layout.lod_count - 1
    );
    out!(s);
    out!(s, "| image | content |");
    out!(s, "|---|---|");
    for r in all {
        out!(s, "| {} (`{}`) | {} |", r.img.title, r.img.key, r.img.what);
    }
    s
}

/// `accuracy:measured`: the definitions that carry this run's numbers (LOD 0's share, runs,
/// spread, tile counts).
pub fn measured(res: &Results, run: &RunInfo) -> String {
    let layout = &run.layout;
    let mut s = String::new();
    out!(
        s,
        "- **PSNR**, `10 log10(255² / MSE)` over the three colour samples of every texel compared (\"exact\": no error at all); **max**: the largest absolute difference, in code values. *All LODs* pools every texel of every LOD (LOD 0 is {:.0}% of them), *LOD 0* is the codec's error alone, *LODs 1+* the coarser levels (filter and codec). The plots use *all LODs*.",
        100.0 / (0..layout.lod_count).map(|k| 0.25f64.powi(k as i32)).sum::<f64>()
    );
    out!(
        s,
        "- **ms/Mpx**: wall time of the whole split (pyramid, encoding on all cores, the pack written to a temporary file) per source megapixel; the median of {} runs ({} for choices slower than {:.2} s a run). The runs are interleaved (each round runs every choice once, in a shifted order) so that load from elsewhere falls on all choices alike. Even so, the runs of one choice, less the slowest and the fastest, span {:.0}% of their median (the median over all choices; each choice's is in the table of every choice): on this small shared machine, read ratios, and take differences under about 20% for noise.",
        run.rounds,
        SLOW_RUNS.min(run.rounds),
        SLOW_RUN_S,
        {
            let mut v: Vec<f64> =
                res.all.iter().flat_map(|r| r.measured.values().map(|m| 100.0 * m.spread())).collect();
            v.sort_by(f64::total_cmp);
            v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
        }
    );
    let shown_tiles: u64 = (0..layout.lod_count)
        .map(|k| {
            let (lw, lh) = layout.level_extent(k);
            (lw.div_ceil(layout.payload()) * lh.div_ceil(layout.payload())) as u64
        })
        .sum();
    out!(
        s,
        "- **KiB/tile**: mean payload bytes of the {shown_tiles} tiles that show part of the image (of the pyramid's {}), identical tiles counted at each place; a one-colour tile costs 0 (a pack stores its colour). **bits/texel**: the same per stored texel.",
        layout.total_tiles()
    );
    s
}
