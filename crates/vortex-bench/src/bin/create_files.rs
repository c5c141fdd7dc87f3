//! What creating a tile file costs the file system, apart from everything else a tiler does
//! (issue 45): FILES files of SIZE bytes created in a new directory by THREADS threads,
//! opened as our tile directories open theirs (`create_new`: `O_CREAT | O_EXCL`) or as
//! libvips does (`--truncate`: `O_CREAT | O_TRUNC`). Two rounds: into the fresh directory,
//! then, once those files are deleted, into it again. Prints one JSON line: per round the wall time
//! and the system CPU time per file (getrusage, all threads).
//!
//!     cargo run --release -p vortex-bench --bin create_files -- DIR [--files 4096] [--size 20000] [--threads 2] [--truncate]
//!
//! DIR must not exist; it is removed at the end. Why the second round matters: on an ext4
//! without a journal, a new inode skips every inode freed in the last one to six minutes,
//! reading each one's inode-table block for its deletion time (docs/benchmarks.md, "Creating
//! files").
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests and measurement programs may panic on a broken set-up

use std::fs::{self, OpenOptions};
use std::io::Write;
use std::path::Path;
use std::time::{Duration, Instant};

const USAGE: &str = "usage: create_files DIR [--files N] [--size BYTES] [--threads N] [--truncate]";

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let dir = Path::new(args.first().filter(|a| !a.starts_with("--")).expect(USAGE));
    let number = |flag: &str, default: usize| {
        args.iter()
            .position(|a| a == flag)
            .map_or(default, |i| args.get(i + 1).and_then(|v| v.parse().ok()).expect(USAGE))
    };
    let (files, size, threads) = (number("--files", 4096), number("--size", 20_000), number("--threads", 2).max(1));
    let truncate = args.iter().any(|a| a == "--truncate");
    fs::create_dir(dir).unwrap_or_else(|e| panic!("{}: {e} (it must not exist)", dir.display()));
    let bytes = vec![0x5a_u8; size];

    // The second round in the same directory, where the file system looks for the new inodes
    // first (a new directory may be placed elsewhere).
    let fresh = round(dir, files, threads, truncate, &bytes);
    for entry in fs::read_dir(dir).unwrap() {
        fs::remove_file(entry.unwrap().path()).unwrap();
    }
    // ext4 keeps a deletion's time in whole seconds and counts it as recent from the next one.
    std::thread::sleep(Duration::from_secs(2));
    let again = round(dir, files, threads, truncate, &bytes);
    fs::remove_dir_all(dir).unwrap();

    let json = |(wall, sys): (Duration, Duration)| {
        format!(
            r#"{{"wallSeconds":{:.3},"sysMicrosPerFile":{:.1}}}"#,
            wall.as_secs_f64(),
            sys.as_secs_f64() * 1e6 / files as f64
        )
    };
    println!(
        r#"{{"files":{files},"size":{size},"threads":{threads},"open":"{}","fresh":{},"afterDeleting":{}}}"#,
        if truncate { "truncate" } else { "create_new" },
        json(fresh),
        json(again)
    );
}

/// Creates `files` files named like a Deep Zoom level's (`COL_ROW.jpeg`, 64 columns) in the empty
/// directory `dir`, thread `t` of `threads` taking every `threads`-th; the wall and system CPU
/// time it took.
fn round(dir: &Path, files: usize, threads: usize, truncate: bool, bytes: &[u8]) -> (Duration, Duration) {
    let (started, sys) = (Instant::now(), system_time());
    std::thread::scope(|scope| {
        for t in 0..threads {
            scope.spawn(move || {
                for i in (t..files).step_by(threads) {
                    let path = dir.join(format!("{}_{}.jpeg", i % 64, i / 64));
                    let mut open = OpenOptions::new();
                    match truncate {
                        true => open.write(true).create(true).truncate(true),
                        false => open.write(true).create_new(true),
                    };
                    open.open(&path).and_then(|mut f| f.write_all(bytes)).unwrap();
                }
            });
        }
    });
    (started.elapsed(), system_time() - sys)
}

/// The process's system CPU time so far, all threads.
#[expect(unsafe_code, reason = "getrusage, the one way to read the system CPU time of every thread")]
fn system_time() -> Duration {
    // SAFETY: getrusage writes one `rusage` into the zeroed struct it is given.
    let usage = unsafe {
        let mut usage = std::mem::zeroed::<libc::rusage>();
        assert_eq!(libc::getrusage(libc::RUSAGE_SELF, &mut usage), 0);
        usage
    };
    Duration::from_secs(usage.ru_stime.tv_sec as u64) + Duration::from_micros(usage.ru_stime.tv_usec as u64)
}
