//! Tiling an image from Rust (the `vortex-tiler` library): what `vortex-tiler split IMAGE --pack
//! OUT.vtpk --tile-size 256` does, with a progress callback and cancellation of the caller's.
//!
//!     cargo run --example tile_image -- IMAGE OUT.vtpk [--stop-after TILES]
//!
//! A library user depends on `vortex-tiler` with `default-features = false`: the pipeline alone,
//! none of the command line's, server's or GPU's crates. `--stop-after` cancels the run once
//! that many tiles are done, as a signal handler or a web request's cancellation would: the run
//! returns `TilerError::Interrupted` and leaves nothing at OUT (the pack is written under a
//! temporary name and renamed only when finished).

use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};

use vortex_tiler::error::{Result, TilerError};
use vortex_tiler::formats::pack::PackSink;
use vortex_tiler::limits::Limits;
use vortex_tiler::output::{self, Product};
use vortex_tiler::settings::{Destination, Plan, Requested};
use vortex_tiler::split::{self, Progress, Summary};
use vortex_tiler::{source, vortex_pack::WriteOptions};

/// Counts finished tiles, prints every thousandth, and asks the run to stop past `stop_after`.
struct Watch {
    tiles: AtomicU64,
    stop_after: u64,
}

impl Progress for Watch {
    // Called from the encoding threads: atomics only, no lock held while tiles are encoded.
    fn advance(&self, tiles: u64) {
        let done = self.tiles.fetch_add(tiles, Ordering::Relaxed) + tiles;
        if done / 1000 != (done - tiles) / 1000 {
            eprintln!("{done} tiles");
        }
    }

    // Asked once per source row and per batch of tiles.
    fn cancelled(&self) -> bool {
        self.tiles.load(Ordering::Relaxed) >= self.stop_after
    }
}

/// `input` into 256-texel tiles with every LOD, into the pack `dest`.
fn tile(input: &Path, dest: &Path, watch: &Watch) -> Result<Summary> {
    // Refuses to replace anything but an older pack (`force` false), as the command line does.
    output::claim(dest, Product::Pack, &[input], false)?;
    let limits = Limits::default();
    let source = source::open(input, vortex_tiler::limits::Budget::new(limits.memory))?;
    // Each setting: what was asked for, else a previous output's info.json (none here), else the default.
    let asked = Requested { tile_size: Some(256), ..Requested::default() };
    let plan = Plan::new(&asked, None, &source.header(), Destination::Pack, &limits, None)?;
    let info = plan.info.to_json_pretty();
    let sink =
        PackSink::create(dest, &plan.layout, plan.stored, plan.opts.codec, info.as_bytes(), WriteOptions::default())?;
    // On an error (or a cancellation) the sink is dropped, and its unfinished pack with it.
    let summary = split::split(source, &sink, &plan.opts, watch)?;
    sink.finish()?;
    Ok(summary)
}

fn main() -> std::process::ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (input, dest) = match &args[..] {
        [input, dest, ..] => (Path::new(input), Path::new(dest)),
        _ => {
            eprintln!("usage: tile_image IMAGE OUT.vtpk [--stop-after TILES]");
            return std::process::ExitCode::FAILURE;
        }
    };
    let stop_after = match args.iter().position(|a| a == "--stop-after").map(|i| args.get(i + 1).map(|n| n.parse())) {
        None => u64::MAX,
        Some(Some(Ok(n))) => n,
        Some(_) => {
            eprintln!("--stop-after takes a number of tiles");
            return std::process::ExitCode::FAILURE;
        }
    };
    let watch = Watch { tiles: AtomicU64::new(0), stop_after };
    match tile(input, dest, &watch) {
        Ok(summary) => {
            println!("{}: {} tiles, {} bytes", dest.display(), summary.tiles, summary.bytes);
            std::process::ExitCode::SUCCESS
        }
        Err(TilerError::Interrupted) => {
            eprintln!(
                "stopped after {} tiles; nothing written at {}",
                watch.tiles.load(Ordering::Relaxed),
                dest.display()
            );
            std::process::ExitCode::from(130)
        }
        Err(e) => {
            eprintln!("error: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}
