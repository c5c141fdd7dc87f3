//! What each stage of a `split` costs in CPU time (issue 28): `--json`'s `stages.cpu` and `-v`'s
//! CPU milliseconds per source megapixel, read from the CPU clock of the thread that runs each
//! stage. No durations are compared with expectations: only what must hold however loaded the
//! machine is (a thread spends no more CPU than the time that passes; the stages' CPU is part
//! of the process's; encoding tiles takes some, and so does decoding a JPEG TIFF's tiles on the
//! pool).

use std::path::Path;

use crate::common::Image;
use crate::common::cli::{self, s};
use tiff::encoder::{TiffEncoder, colortype};
use vortex_tiler::pixel::{Channels, Depth, PixelLayout};

const CPU_STAGES: [&str; 6] =
    ["readSeconds", "decodeSeconds", "pyramidSeconds", "cutSeconds", "encodeSeconds", "storeSeconds"];

/// A `width x height` random RGB TIFF in strips of 16 rows.
fn strip_tiff(path: &Path, width: u32, height: u32) {
    let image = Image::random(width, height, PixelLayout::new(Channels::Rgb, Depth::U8), 28);
    let texels: Vec<u8> = image.samples.iter().map(|&v| v as u8).collect();
    let mut tif = TiffEncoder::new(std::fs::File::create(path).unwrap()).unwrap();
    let mut img = tif.new_image::<colortype::RGB8>(width, height).unwrap();
    img.rows_per_strip(16).unwrap();
    img.write_data(&texels).unwrap();
}

/// The CPU time (user and system) of every child of this process waited for so far.
#[expect(unsafe_code, reason = "getrusage, the kernel's count of the children's CPU time")]
fn children_cpu_seconds() -> f64 {
    // SAFETY: an all-zero `rusage` is a valid value of the plain C struct the call fills.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: `usage` is a valid, writable rusage for the call to fill.
    assert_eq!(unsafe { libc::getrusage(libc::RUSAGE_CHILDREN, &mut usage) }, 0);
    let seconds = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 / 1e6;
    seconds(usage.ru_utime) + seconds(usage.ru_stime)
}

#[test]
fn json_says_what_cpu_each_stage_spent_within_the_process() {
    let dir = tempfile::tempdir().unwrap();
    let source = dir.path().join("strips.tif");
    strip_tiff(&source, 1200, 900);
    // Read ahead with the cutting on its own thread, into a pack (a writer stores in order);
    // and under a budget that stripes the run, reading on the pyramid's thread, into a directory.
    let pack = dir.path().join("out.vtpk");
    let tree = dir.path().join("tree");
    let mut runs: Vec<(&str, &Path, Vec<&str>)> = vec![
        ("pack, read ahead", &source, vec!["--pack", s(&pack)]),
        ("directory, striped", &source, vec!["-o", s(&tree), "--max-memory", "2M"]),
    ];
    // A JPEG-tiled TIFF, its tiles decoded on the pool beside the reading thread.
    let jpeg = dir.path().join("jpeg.tif");
    if crate::common::have_program("tiffcp", "-h", "libtiff-tools") {
        let args = ["-c", "jpeg", "-t", "-w", "128", "-l", "128", s(&source), s(&jpeg)];
        let out = std::process::Command::new("tiffcp").args(args).output().unwrap();
        assert!(out.status.success(), "tiffcp: {}", String::from_utf8_lossy(&out.stderr));
        runs.push(("JPEG tiles, pack", &jpeg, vec!["--pack", s(&pack)]));
    }
    for (what, input, output) in runs {
        let before = children_cpu_seconds();
        let mut args = vec!["split", s(input), "--tile-size", "128", "--force", "--json"];
        args.extend(output);
        let out = cli::ok(&args);
        // This run's CPU time, and that of any other test's child reaped meanwhile: a bound.
        let process = children_cpu_seconds() - before;
        let doc: serde_json::Value = serde_json::from_str(&out).unwrap();
        let stages = &doc["stages"];
        let cpu = &stages["cpu"];
        if !cfg!(any(target_os = "linux", target_os = "android", target_os = "macos", target_os = "freebsd")) {
            assert!(cpu.is_null(), "{what}: no per-thread CPU clock, no CPU times: {stages}");
            continue;
        }
        let seconds = |name: &str| {
            let v = cpu[name].as_f64().unwrap_or_else(|| panic!("{what}: stages.cpu.{name} missing: {stages}"));
            assert!(v.is_finite() && v >= 0.0, "{what}: stages.cpu.{name} = {v}");
            v
        };
        let total: f64 = CPU_STAGES.iter().map(|name| seconds(name)).sum();
        assert!(total <= process, "{what}: the stages' {total} s of CPU over the process's {process} s: {stages}");
        assert!(seconds("encodeSeconds") > 0.0, "{what}: tiles were encoded: {stages}");
        assert_eq!(
            seconds("decodeSeconds") > 0.0,
            what.starts_with("JPEG"),
            "{what}: tiles decoded on the pool: {stages}"
        );
        assert!(doc["encoded"].as_u64().unwrap() > 0, "{doc}");
        // Reading and storing each run on one thread, timed around the same calls as their wall
        // time: no more CPU than wall.
        for name in ["readSeconds", "storeSeconds"] {
            let wall = stages[name].as_f64().unwrap();
            assert!(seconds(name) <= wall, "{what}: {name}: CPU {} over wall {wall}", seconds(name));
        }
        if what.contains("striped") {
            assert!(doc["passes"].as_u64().unwrap() > 1, "{what}: {doc}");
        }
    }
}

#[test]
fn verbose_says_the_cpu_per_source_megapixel_of_each_stage() {
    let dir = tempfile::tempdir().unwrap();
    let source = dir.path().join("strips.tif");
    strip_tiff(&source, 600, 500);
    let out = cli::ok(&["split", s(&source), "-o", s(&dir.path().join("out")), "--tile-size", "128", "-v"]);
    let line = out.lines().find(|l| l.starts_with("stages")).unwrap_or_else(|| panic!("no stages line: {out}"));
    let per_stage = ["read ", "decode ", "pyramid ", "cut ", "encode ", "store "];
    assert!(per_stage.iter().all(|stage| line.contains(stage)), "{line}");
    if cfg!(target_os = "linux") {
        assert!(line.contains("CPU ms per source Mpx") && line.contains("wall s:"), "{line}");
    }
}

#[test]
fn docs_name_every_stage_member() {
    let doc = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/docs/cli.md")).unwrap();
    let wall_only = ["readWaitSeconds", "producerBlockedSeconds", "encodersIdleSeconds", "cpu"];
    for name in CPU_STAGES.into_iter().chain(wall_only) {
        assert!(doc.contains(&format!("| `{name}` |")), "docs/cli.md's stages table lacks {name}");
    }
}
