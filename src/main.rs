//! `vortex-tiler`: the command line. Parses flags, opens the input, runs the library's
//! pipeline with a progress bar and prints one summary line. All tiling logic lives in the
//! library; this file is glue.

mod cli;

use std::process::ExitCode;

use clap::{CommandFactory, FromArgMatches};

fn main() -> ExitCode {
    tune_allocator();
    // The matches as well as the arguments: where each flag stood pairs `split`'s outputs with
    // their layouts.
    let matches = cli::Args::command().get_matches();
    let args = cli::Args::from_arg_matches(&matches).unwrap_or_else(|e| e.exit());
    match cli::run(args, &matches) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // A name in a message the library or the system wrote may hold a control
            // character or a terminal escape: it reaches the terminal escaped.
            eprintln!("error: {}", vortex_tiler::error::escape_controls(&cli::report::chain(&e)));
            cli::exit_code(&e)
        }
    }
}

/// A page of texels (192 KiB for 256-texel RGB) is above glibc's first mmap threshold (128
/// KiB): until the threshold adapts, each one is mapped, faulted in 4 KiB at a time and
/// unmapped, and freed heap is trimmed back to the system as soon as it is free. A run's
/// pages come and go by the thousand, so keep them in the heap: short runs (a shard, a small
/// image) spent twice the system time of a long one. Peak memory is what the run holds at
/// most either way.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
#[expect(unsafe_code, reason = "mallopt, called before any other thread starts")]
fn tune_allocator() {
    // SAFETY: mallopt only changes allocator parameters; nothing else runs yet.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 32 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 256 << 20);
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn tune_allocator() {}
