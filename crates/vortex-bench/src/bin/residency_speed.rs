//! Times one frame of the residency update and the incremental page-table update (with the changes
//! packed for upload) on a 512-pages-per-side texture (10 LODs, 349,525 page-table entries) and a
//! 1024-slot cache, with a camera panning over the texture: a few hundred pages requested per frame
//! (an 8x8 window of pages around the view centre at each of LODs 0-5, finest first), the cache full
//! and evicting after the first frames. The full `rebuild()` is timed for comparison.
//!
//! `cargo run --release -p vortex-bench --bin residency_speed`
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests and measurement programs may panic on a broken set-up

use std::time::{Duration, Instant};

use vortex_vt::page::{PageId, TextureGrid};
use vortex_vt::page_table::PageTable;
use vortex_vt::residency::{Residency, ResidencyConfig};

const PAGES: u16 = 512;
const SLOTS: usize = 1024;
const CACHE_SIDE: u16 = 32;
const BUDGET: usize = 32;
const WARMUP: u64 = 300;
const FRAMES: u64 = 3000;

/// The pages a camera centred on LOD-0 page (`cx`, `cy`) requests: an 8x8 window per LOD.
fn requests(grid: &TextureGrid, cx: u32, cy: u32, out: &mut Vec<PageId>) {
    out.clear();
    for lod in 0..6u8 {
        let side = grid.pages_at(lod)[0] as i64;
        let (x0, y0) = ((cx >> lod) as i64 - 4, (cy >> lod) as i64 - 4);
        for y in y0.max(0)..(y0 + 8).min(side) {
            for x in x0.max(0)..(x0 + 8).min(side) {
                out.push(PageId::new(0, lod, x as u16, y as u16));
            }
        }
    }
}

struct Stats {
    residency: Vec<Duration>,
    table: Vec<Duration>,
    requested: usize,
    loads: usize,
    evictions: usize,
    changes: usize,
}

fn run(pan_per_frame: u32) -> Stats {
    let grid = TextureGrid::new(PAGES.into(), PAGES.into()).unwrap();
    let mut residency = Residency::new(&[grid], ResidencyConfig::new(SLOTS, BUDGET)).unwrap();
    let mut table = PageTable::new(&[grid]);
    table.apply(&residency.update(0, &[]).unwrap());
    let mut req = Vec::new();
    let mut upload: Vec<(PageId, u32)> = Vec::new();
    let mut s = Stats { residency: vec![], table: vec![], requested: 0, loads: 0, evictions: 0, changes: 0 };
    for frame in 1..=WARMUP + FRAMES {
        // Pan along x, bouncing between the texture's edges, with a slow drift in y.
        let travel = (frame as u32 * pan_per_frame) % (2 * (PAGES as u32 - 64));
        let cx = 32 + if travel < PAGES as u32 - 64 { travel } else { 2 * (PAGES as u32 - 64) - travel };
        let cy = 256 + ((frame as f64 / 50.0).sin() * 100.0) as u32;
        requests(&grid, cx, cy, &mut req);

        let t0 = Instant::now();
        let update = residency.update(frame, &req).unwrap();
        let t1 = Instant::now();
        let changes = table.apply(&update);
        upload.clear();
        upload.extend(changes.iter().map(|c| (c.at, c.entry.pack(CACHE_SIDE))));
        let t2 = Instant::now();

        if frame > WARMUP {
            s.residency.push(t1 - t0);
            s.table.push(t2 - t1);
            s.requested += update.stats.requested;
            s.loads += update.loads.len();
            s.evictions += update.evictions.len();
            s.changes += changes.len();
        }
        std::hint::black_box(&upload);
    }
    s
}

fn percentile(v: &mut [Duration], p: f64) -> Duration {
    v.sort();
    v[((v.len() - 1) as f64 * p).round() as usize]
}

fn us(d: Duration) -> f64 {
    d.as_secs_f64() * 1e6
}

fn main() {
    println!(
        "{PAGES} pages per side ({} entries), {SLOTS} slots, budget {BUDGET}/frame, {FRAMES} frames timed",
        TextureGrid::new(PAGES.into(), PAGES.into()).unwrap().page_count()
    );
    for pan in [1, 4] {
        let mut s = run(pan);
        let n = FRAMES as f64;
        let mut total: Vec<Duration> = s.residency.iter().zip(&s.table).map(|(a, b)| *a + *b).collect();
        println!(
            "pan {pan} page/frame: per frame {:.0} wanted, {:.1} loads, {:.1} evictions, {:.1} entry changes",
            s.requested as f64 / n,
            s.loads as f64 / n,
            s.evictions as f64 / n,
            s.changes as f64 / n
        );
        println!(
            "  residency update  median {:6.1} us  p99 {:6.1} us  max {:7.1} us",
            us(percentile(&mut s.residency, 0.5)),
            us(percentile(&mut s.residency, 0.99)),
            us(*s.residency.last().unwrap())
        );
        println!(
            "  page-table apply  median {:6.1} us  p99 {:6.1} us  max {:7.1} us",
            us(percentile(&mut s.table, 0.5)),
            us(percentile(&mut s.table, 0.99)),
            us(*s.table.last().unwrap())
        );
        println!(
            "  both              median {:6.1} us  p99 {:6.1} us  max {:7.1} us",
            us(percentile(&mut total, 0.5)),
            us(percentile(&mut total, 0.99)),
            us(*total.last().unwrap())
        );
    }

    // The from-scratch alternative, for comparison.
    let grid = TextureGrid::new(PAGES.into(), PAGES.into()).unwrap();
    let mut residency = Residency::new(&[grid], ResidencyConfig::new(SLOTS, SLOTS)).unwrap();
    let mut req = Vec::new();
    requests(&grid, 256, 256, &mut req);
    residency.update(0, &req).unwrap();
    let mut times: Vec<Duration> = (0..50)
        .map(|_| {
            let t = Instant::now();
            std::hint::black_box(PageTable::rebuild(&[grid], residency.resident()));
            t.elapsed()
        })
        .collect();
    println!("full rebuild()     median {:6.1} us", us(percentile(&mut times, 0.5)));
}
