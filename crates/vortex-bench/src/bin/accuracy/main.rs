//! `accuracy`: what accuracy costs in time and size. Every LOD filter and tile codec on a few
//! synthetic test images, against a float64 reference pyramid. A benchmark, not a test.
//!
//! ```sh
//! cargo run --release -p vortex-bench --bin accuracy     # docs/accuracy.md and its two plots
//! cargo run --release -p vortex-bench --bin accuracy -- --runs 3 --size 512x500 --out /tmp/acc
//! ```
//!
//! Four deterministic 8-bit images ([`images`]) are split in memory through the real pipeline
//! (`split::split`, the pack sink, a temporary pack file), once per LOD filter (with lossless
//! PNG fast and raw tiles) and once per codec setting (with the default filter) ([`sweep`]).
//! Each split is timed (median of the runs, interleaved over all choices), the pack's tiles are
//! decoded with `vortex_pack` and every texel of every LOD is compared with a float64 reference
//! ([`reference`]) computed from the source: the alpha-premultiplied mean in linear light over
//! the texel's footprint (real pixels only) ([`measure`]). The tables and verdicts ([`report`])
//! are spliced between the markers of `DIR/accuracy.md` (its prose is written by hand), and
//! `DIR/accuracy-time.svg`, `DIR/accuracy-size.svg` ([`plot`]) are rewritten. `DIR` is `docs/`
//! unless `--out` says otherwise; a directory without `accuracy.md` gets a copy of
//! `docs/accuracy.md` first.
#![allow(clippy::unwrap_used, clippy::expect_used)] // measurement programs may panic on a broken set-up

mod choice;
mod images;
mod measure;
mod pareto;
mod plot;
mod reference;
mod report;
mod sweep;
mod tiler;

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use vortex_bench::run_info::{load_average, write_atomically};
use vortex_bench::splice::splice_file;

use crate::choice::{Choice, FILTERS};
use crate::measure::{ImageResult, measure, split_once};
use crate::pareto::Axis;
use crate::reference::{RefLevel, reference, to_linear, to_srgb};
use crate::report::RunInfo;
use crate::sweep::{applies, codec_sweep, defaults};
use crate::tiler::{Codec, Filter, Layout, PngLevel};

/// Stored tile side and border: the README's first command (id Tech 5's 120-texel payload).
const TILE_SIZE: u32 = 128;
const BORDER: u32 = 4;
/// Default image size: 8 x 8 payloads of 120 texels hold it (4 LODs), and neither side is a
/// multiple of 8, so the last column and row of texels of LODs 1-3 have partial footprints.
const DEFAULT_SIZE: (u32, u32) = (950, 930);
/// Runs per choice; choices slower than `SLOW_RUN_S` per run stop after `SLOW_RUNS`.
const DEFAULT_RUNS: usize = 9;
const SLOW_RUNS: usize = 3;
const SLOW_RUN_S: f64 = 0.75;
/// No round starts after this many seconds of timing (the whole run should stay near 6 min).
const TIME_BUDGET_S: f64 = 270.0;
/// PSNR shown for an exact match (no error at all) in plots.
const PSNR_CAP: f64 = 99.0;
/// The committed document, whose prose a fresh `--out` directory starts from.
const DOC: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../docs/accuracy.md");

struct Args {
    runs: usize,
    size: (u32, u32),
    out: PathBuf,
}

fn parse_args() -> Result<Args> {
    let mut a = Args {
        runs: DEFAULT_RUNS,
        size: DEFAULT_SIZE,
        out: PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../docs")),
    };
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut it = args.iter();
    while let Some(flag) = it.next() {
        let mut value = || it.next().with_context(|| format!("{flag} needs a value"));
        match flag.as_str() {
            "--runs" => a.runs = value()?.parse().context("--runs")?,
            "--size" => {
                let v = value()?;
                let (w, h) = v.split_once('x').context("--size WxH")?;
                a.size = (w.parse().context("--size")?, h.parse().context("--size")?);
            }
            "--out" => a.out = PathBuf::from(value()?),
            _ => bail!("usage: accuracy [--runs N] [--size WxH] [--out DIR]"),
        }
    }
    if a.runs == 0 {
        bail!("--runs must be at least 1");
    }
    Ok(a)
}

fn main() -> Result<()> {
    let args = parse_args()?;
    let started = Instant::now();
    let load_start = load_average();
    let defaults = defaults()?;
    let (w, h) = args.size;
    eprintln!("generating 5 images of {w}x{h}");
    let images = images::all(w, h);
    let layout = Layout::new(w as u64, h as u64, TILE_SIZE, BORDER)?;
    let lut: [f64; 256] = std::array::from_fn(|c| to_linear(c as f64 / 255.0));
    // Shown colour of a stored (code, alpha): over black, as an sRGB code value.
    let shown_lut: Vec<[f64; 256]> =
        (0..256).map(|a| std::array::from_fn(|c| 255.0 * to_srgb(lut[c] * a as f64 / 255.0))).collect();

    let mut choices: Vec<Choice> = Vec::new();
    for codec in [Codec::Png { level: PngLevel::Fast }, Codec::Raw] {
        choices.extend(FILTERS.map(|f| Choice::new(f, codec)));
    }
    choices.extend(codec_sweep().into_iter().map(|c| Choice::new(defaults.opaque.filter, c)));
    // The default JPEG tiles with `box` (as vips averages): what changing only the filter gives.
    choices.push(Choice::new(Filter::Box, defaults.opaque.codec));
    choices.sort();
    choices.dedup();

    let mut results: Vec<ImageResult> = Vec::new();
    let mut jobs: Vec<(usize, Choice)> = Vec::new();
    let mut refs = Vec::new();
    for (i, (img, extra)) in images.into_iter().enumerate() {
        eprintln!("reference pyramid of {} ({} LODs)", img.key, layout.lod_count);
        refs.push(reference(&img, &layout, &lut));
        jobs.extend(choices.iter().filter(|c| applies(&img, extra, **c)).map(|c| (i, *c)));
        results.push(ImageResult { img, measured: BTreeMap::new(), extra });
    }
    let rounds = time_and_measure(&args, &layout, &jobs, &refs, &shown_lut, &mut results)?;
    let load_end = load_average();

    std::fs::create_dir_all(&args.out)?;
    let path = args.out.join("accuracy.md");
    if !path.exists() {
        std::fs::copy(DOC, &path).with_context(|| format!("{DOC}: cannot copy to {}", path.display()))?;
    }
    let run =
        RunInfo { size: args.size, layout, rounds, load_start, load_end, seconds: started.elapsed().as_secs_f64() };
    let plotted: Vec<&ImageResult> = results.iter().filter(|r| !r.extra).collect();
    for (name, axis) in [("accuracy-time.svg", Axis::Time), ("accuracy-size.svg", Axis::Size)] {
        let svg = plot::plot(&plotted, axis, &defaults)?;
        write_atomically(&args.out.join(name), svg.as_bytes()).with_context(|| name.to_string())?;
    }
    splice_file(&path, "accuracy:", &report::blocks(&results, &defaults, &run))?;
    eprintln!("wrote {} and its plots in {:.0} s", path.display(), started.elapsed().as_secs_f64());
    Ok(())
}

/// Runs every job once per round (a shifted order each round) until `args.runs` rounds or the
/// time budget; measures each choice's errors on its first run. Returns the rounds run.
fn time_and_measure(
    args: &Args,
    layout: &Layout,
    jobs: &[(usize, Choice)],
    refs: &[Vec<RefLevel>],
    shown_lut: &[[f64; 256]],
    results: &mut [ImageResult],
) -> Result<usize> {
    let tmp = tempfile::tempdir()?;
    let timing_started = Instant::now();
    let mut rounds_done = 0;
    for round in 0..args.runs {
        if round > 0 && timing_started.elapsed().as_secs_f64() > TIME_BUDGET_S {
            eprintln!("time budget reached: stopping after {round} rounds");
            break;
        }
        let round_started = Instant::now();
        // A different order each round, so that load from elsewhere falls on every choice alike.
        let offset = round * jobs.len() / args.runs.max(1);
        for k in 0..jobs.len() {
            let (i, choice) = jobs[(k + offset) % jobs.len()];
            let r = &mut results[i];
            if let Some(m) = r.measured.get(&choice)
                && m.times.len() >= SLOW_RUNS
                && m.times[0] > SLOW_RUN_S
            {
                continue;
            }
            let dest = tmp.path().join(format!("{}-{round}-{k}.vtpk", r.img.key));
            let t = split_once(&r.img, layout, choice, &dest).with_context(|| choice.label())?;
            match r.measured.get_mut(&choice) {
                Some(m) => m.times.push(t),
                None => {
                    let m = measure(&dest, &r.img, layout, &refs[i], choice, shown_lut, t)
                        .with_context(|| choice.label())?;
                    eprintln!(
                        "  {:<15} {:<34} {:>7.1} ms/Mpx {:>8.0} B/tile  PSNR {:>6.2} dB (LOD 0 {:>6.2}, LODs 1+ {:>6.2})",
                        r.img.key,
                        choice.label(),
                        m.ms_per_mpx(&r.img),
                        m.bytes_per_tile,
                        m.all().psnr(),
                        m.lods[0].psnr(),
                        m.coarse().psnr()
                    );
                    r.measured.insert(choice, m);
                }
            }
            std::fs::remove_file(&dest)?;
        }
        rounds_done = round + 1;
        eprintln!("round {}/{} done in {:.1} s", round + 1, args.runs, round_started.elapsed().as_secs_f64());
    }
    Ok(rounds_done)
}
