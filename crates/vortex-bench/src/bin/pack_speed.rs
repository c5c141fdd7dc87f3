//! How fast a pack opens, looks tiles up and verifies: a benchmark, not a test.
//!
//!     cargo run --release -p vortex-bench --bin pack_speed [-- DIR]
//!
//! Writes a pack of 349,525 tiles (a 512 x 512 grid at LOD 0, 10 levels: a 65536² texture in
//! 128-texel pages) with 1-4 KiB payloads into DIR (default: the system temp dir), then times
//! `Pack::open` (with and without the index's CRC), `tile()` at random addresses, and `verify`,
//! next to plain CRC-32C over the same bytes. Prints a markdown table.
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests and measurement programs may panic on a broken set-up

use std::hint::black_box;
use std::time::Instant;

use vortex_pack::{
    Description, Level, Limits, NewTile, Pack, PackWriter, TileId, TileKind, VerifyOptions, WriteOptions, verify,
};

fn median(mut v: Vec<f64>) -> f64 {
    vortex_bench::measure::median(&mut v)
}

fn main() {
    let dir = std::env::args().nth(1).map_or_else(std::env::temp_dir, Into::into);
    let path = dir.join("pack_speed.vtpk");
    let d = Description {
        width: 65536,
        height: 65536,
        tile_size: 128,
        border: 0,
        level_count: 10,
        channels: 3,
        sample_bytes: 1,
        sample_format: 0,
    };
    // A square grid of 512 x 512 tiles at LOD 0, halved at each level.
    let levels: Vec<Level> =
        (0..d.level_count).map(|lod| Level::new(512 >> lod, 512 >> lod, d.width >> lod, d.height >> lod)).collect();
    let started = Instant::now();
    let mut w = PackWriter::create(&path, d, levels.clone(), b"{}", WriteOptions::default()).unwrap();
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    let mut payload = vec![0u8; 4096];
    for (lod, l) in levels.iter().enumerate() {
        for y in 0..l.tiles_h {
            for x in 0..l.tiles_w {
                let len = 1024 + (next() % 3072) as usize;
                payload[..len].iter_mut().for_each(|b| *b = next() as u8);
                w.add(TileId { lod: lod as u32, x, y }, NewTile::Data(TileKind::Jpeg, &payload[..len])).unwrap();
            }
        }
    }
    let summary = w.finish().unwrap();
    let write_s = started.elapsed().as_secs_f64();

    let opens: Vec<f64> = (0..200)
        .map(|_| {
            let t = Instant::now();
            black_box(Pack::open(&path).unwrap());
            t.elapsed().as_secs_f64()
        })
        .collect();
    // The open without the index's CRC (what `verify` opens with, and what `open` was before
    // it checked the index), and that CRC alone on a pack already mapped.
    let opens_unchecked: Vec<f64> = (0..200)
        .map(|_| {
            let t = Instant::now();
            black_box(Pack::open_to_verify(&path, Limits::default()).unwrap());
            t.elapsed().as_secs_f64()
        })
        .collect();
    let pack = Pack::open(&path).unwrap();
    let index_crc_s = median(
        (0..200)
            .map(|_| {
                let t = Instant::now();
                pack.check_index().unwrap();
                t.elapsed().as_secs_f64()
            })
            .collect(),
    );
    let lookups = 4_000_000;
    let addresses: Vec<(u32, u32, u32)> = (0..lookups)
        .map(|_| {
            let lod = (next() % 10) as u32;
            let n = 512 >> lod;
            (lod, (next() % n as u64) as u32, (next() % n as u64) as u32)
        })
        .collect();
    let lookup_ns = median(
        (0..5)
            .map(|_| {
                let t = Instant::now();
                for &(lod, x, y) in &addresses {
                    black_box(pack.tile(vortex_pack::TileId::new(lod, x, y)).unwrap());
                }
                t.elapsed().as_secs_f64() * 1e9 / lookups as f64
            })
            .collect(),
    );
    let verify_s = median(
        (0..3)
            .map(|_| {
                let t = Instant::now();
                assert!(verify(&pack, VerifyOptions::default()).is_ok());
                t.elapsed().as_secs_f64()
            })
            .collect(),
    );
    let crc_s = median(
        (0..3)
            .map(|_| {
                let t = Instant::now();
                black_box(crc32c::crc32c(pack.file()));
                t.elapsed().as_secs_f64()
            })
            .collect(),
    );
    let gb = summary.file_bytes as f64 / 1e9;
    println!("| measure | value |");
    println!("|---|---:|");
    println!("| tiles | {} |", summary.tiles);
    println!("| file size | {:.2} GB |", gb);
    println!("| write (one pass, with dedup lookups) | {write_s:.2} s |");
    println!("| `Pack::open` (median of 200) | {:.1} µs |", median(opens) * 1e6);
    println!(
        "| `Pack::open_to_verify`: `open` without the index CRC (median of 200) | {:.1} µs |",
        median(opens_unchecked) * 1e6
    );
    let index_mib = summary.tiles as f64 * vortex_pack::format::ENTRY_LEN as f64 / (1 << 20) as f64;
    println!(
        "| `check_index()` on the mapped pack: CRC-32C of the {index_mib:.1} MiB index (median of 200) | {:.0} µs |",
        index_crc_s * 1e6
    );
    println!("| `tile(TileId)` at random addresses (median of 5 x 4M) | {lookup_ns:.1} ns |");
    println!("| `verify` (page cache, median of 3) | {verify_s:.3} s = {:.2} GB/s |", gb / verify_s);
    println!("| CRC-32C over the whole file | {crc_s:.3} s = {:.2} GB/s |", gb / crc_s);
    std::fs::remove_file(&path).unwrap();
}
