//! Times feedback analysis (prints medians; not a test).
//!
//! The realistic buffer: a 1280x720 frame with a 160x90 feedback buffer (1/8), a camera 2 m
//! above a ground plane textured with one 65536² virtual texture (512 pages per side of 128
//! texels, 10 LODs, 2 mm per texel), pitched 40° down, 75° vertical field of view, turned 30°
//! from the texture's axes. Near pages want LOD 0, far ones coarser LODs. Then two harder
//! buffers: 400 pages over LODs 0-3 in random order (no run coherence), and 14400 distinct pages.
//!
//! `cargo run --release -p vortex-bench --bin analysis_speed`
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests and measurement programs may panic on a broken set-up

use std::collections::{BTreeMap, HashSet};
use std::hint::black_box;
use std::time::Instant;

use vortex_vt::analysis::{Analysis, Analyzer, analyze};
use vortex_vt::feedback::{encode, feedback_bias};
use vortex_vt::page::{PageId, TextureGrid};

use vortex_bench::ground::{Camera, FEEDBACK, FRAME};

/// The still view: the camera at (64 m, 32 m), turned 30° from the texture's axes.
fn perspective_buffer(grid: &TextureGrid) -> Vec<u32> {
    let camera = Camera { x: 64.0, z: 32.0, yaw: 30.0 };
    let mut words = Vec::new();
    camera.feedback(grid, feedback_bias(FEEDBACK.0, FEEDBACK.1, FRAME.0, FRAME.1), &mut words);
    words
}

fn xorshift(s: &mut u64) -> u64 {
    *s ^= *s << 13;
    *s ^= *s >> 7;
    *s ^= *s << 17;
    *s
}

/// 400 distinct pages (100 per LOD 0-3, in a window near the texture's centre), each pixel one
/// of them at random.
fn scattered_buffer(grid: &TextureGrid) -> Vec<u32> {
    let pages: Vec<u32> = (0..4u8)
        .flat_map(|lod| {
            (0..100u16).map(move |i| encode(PageId::new(0, lod, (200 >> lod) + i % 10, (200 >> lod) + i / 10), grid))
        })
        .collect();
    let mut s = 0x9E37_79B9_7F4A_7C15;
    (0..FEEDBACK.0 * FEEDBACK.1).map(|_| pages[(xorshift(&mut s) % 400) as usize]).collect()
}

/// Every pixel a different LOD 0 page, shuffled.
fn distinct_buffer(grid: &TextureGrid) -> Vec<u32> {
    let mut words: Vec<u32> = (0..FEEDBACK.0 * FEEDBACK.1)
        .map(|i| encode(PageId::new(0, 0, (i % 512) as u16, (i / 512) as u16), grid))
        .collect();
    let mut s = 12345;
    for i in (1..words.len()).rev() {
        words.swap(i, (xorshift(&mut s) % (i as u64 + 1)) as usize);
    }
    words
}

fn median_us(mut f: impl FnMut()) -> f64 {
    let mut times: Vec<f64> = (0..1001)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64() * 1e6
        })
        .collect();
    times.sort_by(f64::total_cmp);
    times[times.len() / 2]
}

fn describe(name: &str, a: &Analysis) {
    let mut per_lod: BTreeMap<u8, usize> = BTreeMap::new();
    for q in a.requests.iter().filter(|q| q.direct > 0) {
        *per_lod.entry(q.page.lod).or_default() += 1;
    }
    println!(
        "{name}: {} samples, {} no request, {} invalid; {} pages requested, per LOD {:?}; {} with ancestors",
        a.samples,
        a.no_request,
        a.invalid,
        a.requested,
        per_lod,
        a.requests.len()
    );
}

fn main() {
    let grid = TextureGrid::new(512, 512).unwrap();
    let grids = [grid];

    // Resident: all of LOD 4 and coarser and a third of LOD 2, found through a hash set the way
    // a page-table stand-in would be (this look-up is the caller's cost, included below).
    let mut resident: HashSet<PageId> = HashSet::new();
    for lod in 2..grid.lod_count() {
        let n = grid.pages_at(lod)[0];
        for y in 0..n {
            for x in 0..n {
                if lod >= 4 || (x + y) % 3 == 0 {
                    resident.insert(PageId::new(0, lod, x, y));
                }
            }
        }
    }
    let resident_lod = |p: PageId| p.ancestors_and_self(&grid).find(|q| resident.contains(q)).map(|q| q.lod);

    println!("feedback buffer {}x{} for a {}x{} frame", FEEDBACK.0, FEEDBACK.1, FRAME.0, FRAME.1);
    let mut analyzer = Analyzer::new();
    for (name, words) in [
        ("perspective view", perspective_buffer(&grid)),
        ("400 pages at random", scattered_buffer(&grid)),
        ("14400 distinct pages", distinct_buffer(&grid)),
    ] {
        describe(name, &analyze(&words, &grids, resident_lod));
        let reused = median_us(|| {
            black_box(analyzer.analyze(black_box(&words), &grids, resident_lod));
        });
        let fresh = median_us(|| {
            black_box(analyze(black_box(&words), &grids, resident_lod));
        });
        let no_lookup = median_us(|| {
            black_box(analyzer.analyze(black_box(&words), &grids, |_| Some(9)));
        });
        println!(
            "  median {reused:.1} µs (Analyzer reused), {fresh:.1} µs (fresh analyze()), \
             {no_lookup:.1} µs without the hash-set residency look-ups"
        );
    }
}
