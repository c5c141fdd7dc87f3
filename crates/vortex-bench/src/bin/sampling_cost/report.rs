//! The tables of `docs/gpu-sampling.md`: one row per view x border x filter with times relative
//! to bilinear border 4, and the diagnostics (spreads, convergence, where pixels differ).

use vortex_bench::out;

use crate::VIEWS;
use crate::api::SampleFilter as Filter;
use crate::compare::{Check, Worst};

pub struct Row {
    pub view: usize,
    pub border: u32,
    pub filter: Filter,
    pub frame_ms: f64,
    /// The 10th and 90th percentiles of the frame times.
    pub frame_spread: [f64; 2],
    pub sample_ms: f64,
    pub converged_after: u32,
    pub check: Check,
}

/// The `q` quantile of `v` (0.5: the median), interpolated between the closest ranks.
pub fn quantile(v: &mut [f64], q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    let at = q * (v.len() - 1) as f64;
    let (lo, hi) = (at.floor() as usize, at.ceil() as usize);
    v[lo] + (v[hi] - v[lo]) * (at - lo as f64)
}

/// The row of bilinear, border 4 on the same view: what times are relative to.
pub fn baseline(rows: &[Row], view: usize) -> &Row {
    rows.iter().find(|r| r.view == view && r.border == 4 && r.filter == Filter::Bilinear).expect("a baseline row")
}

pub fn db(psnr: f64) -> String {
    if psnr.is_infinite() { "exact".into() } else { format!("{psnr:.1} dB") }
}

pub fn table(rows: &[Row]) -> String {
    let mut s = String::new();
    s.push_str("| border | filter | view | ms/frame | relative | sampling ms | relative | PSNR vs own model | max err | PSNR vs ideal |\n");
    s.push_str("|---:|---|---|---:|---:|---:|---:|---:|---:|---:|\n");
    let mut sorted: Vec<&Row> = rows.iter().collect();
    sorted.sort_by_key(|r| (r.view, r.border, r.filter as u8));
    for r in sorted {
        let base = baseline(rows, r.view);
        out!(
            s,
            "| {} | {} | {} | {:.2} | {:.2} | {:.2} | {:.2} | {} | {} | {} |",
            r.border,
            r.filter.name(),
            VIEWS[r.view].name,
            r.frame_ms,
            r.frame_ms / base.frame_ms,
            r.sample_ms,
            r.sample_ms / base.sample_ms,
            db(r.check.own.psnr),
            r.check.own.max,
            db(r.check.ideal.psnr),
        );
    }
    s
}

/// Where each run differs from its own model, and anything unexpected.
pub fn diagnostics(rows: &[Row]) -> String {
    let mut s = String::new();
    s.push_str(
        "| border | filter | view | ms/frame p10-p90 | frames to converge | px > 2 off, at page edges | px > 2 off, inside pages | max err at edges | max err inside | worst pixel (x, y): GPU vs model |\n",
    );
    s.push_str("|---:|---|---|---:|---:|---:|---:|---:|---:|---|\n");
    let mut sorted: Vec<&Row> = rows.iter().collect();
    sorted.sort_by_key(|r| (r.view, r.border, r.filter as u8));
    for r in sorted {
        let c = &r.check;
        let Worst { x, y, got: g, want: w, .. } = c.worst;
        out!(
            s,
            "| {} | {} | {} | {:.2}-{:.2} | {} | {} | {} | {} | {} | ({x}, {y}): {:?} vs {:?} |",
            r.border,
            r.filter.name(),
            VIEWS[r.view].name,
            r.frame_spread[0],
            r.frame_spread[1],
            r.converged_after,
            c.edge_off,
            c.inner_off,
            c.edge_max,
            c.inner_max,
            &g[..3],
            &w[..3],
        );
    }
    let notes: Vec<String> = rows
        .iter()
        .flat_map(|r| {
            let label = format!("border {} {} on {}", r.border, r.filter.name(), VIEWS[r.view].name);
            let c = &r.check;
            let mut n = Vec::new();
            if c.fallback.pixels > 0 {
                n.push(format!("{label}: drawn from a coarser page after convergence: {}", c.fallback.describe()));
            }
            if c.sampling_only_differs {
                n.push(format!("{label}: the draw without streaming differs from the frame's picture"));
            }
            if c.loaded_while_timed > 0 {
                n.push(format!("{label}: {} pages loaded during the timed frames", c.loaded_while_timed));
            }
            n
        })
        .collect();
    if notes.is_empty() {
        s.push_str(
            "\nEvery picture was drawn without fallback, nothing streamed during the timed frames, and the \
             draws without streaming gave the frames' picture exactly.\n",
        );
    } else {
        s.push('\n');
        for n in notes {
            out!(s, "- {n}");
        }
    }
    s
}
