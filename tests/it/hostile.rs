//! The hostile-input suite: every way a user's mistake or an attacker's file could destroy
//! data, take the machine down or mislead, run as a user runs the tool. Each case asserts the
//! exit code, the message, and that nothing is left behind or changed.

use std::fs;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::common::cli::{BIN, fails_with, fixture, ok, run, s};

/// A scratch directory holding a copy of a fixture as `in.png`.
fn scratch_with_input() -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in.png");
    fs::copy(fixture("sample.png"), &input).unwrap();
    (dir, input)
}

/// The names in `dir`, sorted, to show that nothing was added or removed.
fn listing(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> =
        fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().into_string().unwrap()).collect();
    names.sort();
    names
}

#[test]
fn a_pack_onto_its_own_input_is_refused() {
    let (dir, input) = scratch_with_input();
    let before = fs::read(&input).unwrap();
    fails_with(&run(&["split", s(&input), "--pack", s(&input)]), &["is the input"]);
    fails_with(&run(&["split", s(&input), "--pack", s(&input), "--force"]), &["is the input"]);
    assert_eq!(fs::read(&input).unwrap(), before);
    assert_eq!(listing(dir.path()), ["in.png"]);
}

#[test]
fn an_output_directory_holding_the_input_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    fs::create_dir(&out).unwrap();
    let input = out.join("source.png");
    fs::copy(fixture("sample.png"), &input).unwrap();
    fs::write(out.join("info.json"), "{}").unwrap();
    fs::write(out.join("notes.txt"), "mine").unwrap();
    fails_with(&run(&["split", s(&input), "-o", s(&out)]), &["holds the input"]);
    assert_eq!(listing(&out), ["info.json", "notes.txt", "source.png"]);
    assert_eq!(listing(dir.path()), ["out"]);
}

#[test]
fn a_directory_with_foreign_files_is_never_replaced() {
    let (dir, input) = scratch_with_input();
    let out = dir.path().join("out");
    ok(&["split", s(&input), "-o", s(&out), "--quiet"]);
    fs::write(out.join("notes.txt"), "mine").unwrap();
    fails_with(&run(&["split", s(&input), "-o", s(&out), "--force"]), &["notes.txt", "not one of its tiles"]);
    assert_eq!(fs::read_to_string(out.join("notes.txt")).unwrap(), "mine");
    // Without the foreign file the previous output is ours, and is replaced.
    fs::remove_file(out.join("notes.txt")).unwrap();
    ok(&["split", s(&input), "-o", s(&out), "--quiet"]);
    assert_eq!(listing(dir.path()), ["in.png", "out"]);
}

#[cfg(unix)]
#[test]
fn device_nodes_and_links_are_never_replaced() {
    let (dir, input) = scratch_with_input();
    fails_with(&run(&["split", s(&input), "--pack", "/dev/null", "--force"]), &["/dev/null", "device node"]);
    use std::os::unix::fs::FileTypeExt;
    assert!(fs::metadata("/dev/null").unwrap().file_type().is_char_device());
    let target = dir.path().join("target.vtpk");
    ok(&["split", s(&input), "--pack", s(&target), "--quiet"]);
    let before = fs::read(&target).unwrap();
    let link = dir.path().join("link.vtpk");
    std::os::unix::fs::symlink(&target, &link).unwrap();
    fails_with(&run(&["split", s(&input), "--pack", s(&link)]), &["symbolic link"]);
    assert_eq!(fs::read(&target).unwrap(), before);
    assert!(fs::symlink_metadata(&link).unwrap().file_type().is_symlink());
}

#[test]
fn a_foreign_file_is_replaced_only_with_force() {
    let (dir, input) = scratch_with_input();
    let notes = dir.path().join("notes.vtpk");
    fs::write(&notes, "my notes").unwrap();
    fails_with(&run(&["split", s(&input), "--pack", s(&notes)]), &["not a pack", "--force"]);
    assert_eq!(fs::read_to_string(&notes).unwrap(), "my notes");
    ok(&["split", s(&input), "--pack", s(&notes), "--force", "--quiet"]);
    assert!(fs::read(&notes).unwrap().starts_with(b"\x89VTP"));
    // A previous pack is ours: replaced without --force.
    ok(&["split", s(&input), "--pack", s(&notes), "--quiet"]);
    let out = dir.path().join("out");
    ok(&["split", s(&input), "-o", s(&out), "--quiet"]);
    fails_with(&run(&["pack", s(&out), "-o", s(&out.join("p.vtpk"))]), &["lies inside the input"]);
    fails_with(&run(&["pack", s(&out), "-o", s(&input)]), &["not a pack", "--force"]);
    let report = dir.path().join("report.json");
    fs::write(&report, "{\"mine\": 1}").unwrap();
    fails_with(&run(&["render", "--pack", s(&notes), "--report", s(&report)]), &["not a render report", "--force"]);
    assert_eq!(fs::read_to_string(&report).unwrap(), "{\"mine\": 1}");
    fails_with(&run(&["unpack", s(&notes), "-o", s(&dir.path().join("in.png"))]), &["a file where"]);
    assert_eq!(listing(dir.path()), ["in.png", "notes.vtpk", "out", "report.json"]);
}

/// A grey PNG of `width` x 1, compressed to a few kilobytes.
fn wide_png(path: &Path, width: u32) {
    let file = fs::File::create(path).unwrap();
    let mut enc = png::Encoder::new(std::io::BufWriter::new(file), width, 1);
    enc.set_color(png::ColorType::Grayscale);
    enc.set_compression(png::Compression::Fast);
    let mut writer = enc.write_header().unwrap();
    writer.write_image_data(&(0..width).map(|x| (x / 97) as u8).collect::<Vec<u8>>()).unwrap();
}

#[test]
fn a_wide_strip_is_cut_in_stripes_within_max_memory() {
    // 1000000 x 1: one band would hold a 16 MiB row of sums per LOD and 48 MiB of tiles.
    let dir = tempfile::tempdir().unwrap();
    let wide = dir.path().join("wide.png");
    wide_png(&wide, 1_000_000);
    let pack = dir.path().join("wide.vtpk");
    let args = ["split", s(&wide), "--pack", s(&pack), "--tile-size", "256", "--border", "0", "--max-memory", "48M"];
    let line = ok(&args);
    assert!(line.contains("from 3907 x 1 pages") && line.contains("vertical stripes"), "{line}");
    let peak: f64 = line.split("peak memory ").nth(1).unwrap().split(' ').next().unwrap().parse().unwrap();
    assert!(peak < 48.0 + 16.0, "peak {peak} MiB: {line}");
    assert!(ok(&["verify", s(&pack)]).contains("OK"));
}

#[test]
fn sizes_are_checked_before_allocating() {
    let dir = tempfile::tempdir().unwrap();
    // A 131072^2 grey PPM (a sparse 16 GiB file) in 4-texel payloads: 1.4 billion tiles.
    let huge = dir.path().join("huge.pgm");
    let header = b"P5\n131072 131072\n255\n";
    fs::write(&huge, header).unwrap();
    fs::OpenOptions::new().write(true).open(&huge).unwrap().set_len(header.len() as u64 + (1 << 34)).unwrap();
    let pack = dir.path().join("huge.vtpk");
    fails_with(&run(&["split", s(&huge), "--pack", s(&pack), "--tile-size", "8", "--border", "2"]), &["tiles"]);
    fs::remove_file(&huge).unwrap();
    let input = dir.path().join("in.png");
    fs::copy(fixture("sample.png"), &input).unwrap();
    fails_with(
        &run(&["split", s(&input), "--pack", s(&pack), "--tile-size", "16384", "--border", "8190"]),
        &["--max-memory"],
    );
    fails_with(&run(&["split", s(&input), "--pack", s(&pack), "--threads", "1000000000"]), &["--threads", "per core"]);
    // A flag value clap refuses is a usage error: exit 2, as for any bad flag.
    let absurd = run(&["split", s(&input), "--pack", s(&pack), "--max-memory", "16777217T"]);
    assert_eq!(absurd.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&absurd.stderr).contains("'16777217T' is more than"));
    fails_with(&run(&["render", "--pack", s(&input), "--frame-count", "4000000000"]), &["frames"]);
    fails_with(
        &run(&["split", s(&input), "-o", s(&dir.path().join("o")), "--ff", "%1$65536d-%2$d-%3$d.png"]),
        &["width"],
    );
    assert_eq!(listing(dir.path()), ["in.png"]);
}

/// A PID that no process has: beyond the kernel's maximum.
fn dead_pid() -> u64 {
    fs::read_to_string("/proc/sys/kernel/pid_max").ok().and_then(|s| s.trim().parse().ok()).unwrap_or(4194304) + 1
}

#[test]
fn temporaries_of_dead_runs_are_removed() {
    if !Path::new("/proc/self").exists() {
        crate::common::skip_unless_ci(
            "the stale-temporaries test",
            "no /proc, so dead runs cannot be told from live ones",
        );
        return;
    }
    let (dir, input) = scratch_with_input();
    let pid = dead_pid();
    let stale_dir = dir.path().join(format!(".out.partial-{pid}"));
    fs::create_dir(&stale_dir).unwrap();
    fs::write(stale_dir.join("lod00-x0000-y0000.jpg"), "x").unwrap();
    let stale_pack = dir.path().join(format!(".p.vtpk.tmp-{pid}"));
    fs::write(&stale_pack, "x").unwrap();
    let out = run(&["split", s(&input), "-o", s(&dir.path().join("out")), "--quiet"]);
    assert!(out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("removed"), "{}", String::from_utf8_lossy(&out.stderr));
    ok(&["split", s(&input), "--pack", s(&dir.path().join("p.vtpk")), "--quiet"]);
    assert_eq!(listing(dir.path()), ["in.png", "out", "p.vtpk"]);
}

/// A PPM of noise, slow enough to encode as best-compressed PNG that a signal lands mid-run.
fn noise_ppm(path: &Path, side: usize) {
    let mut bytes = format!("P6\n{side} {side}\n255\n").into_bytes();
    let mut state = 0x2545_F491_4F6C_DD1Du64;
    bytes.extend((0..side * side * 3).map(|_| {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state as u8
    }));
    fs::write(path, bytes).unwrap();
}

#[cfg(unix)]
#[test]
fn signals_stop_cleanly_and_leave_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("noise.ppm");
    noise_ppm(&input, 3000);
    for (signal, code) in [("TERM", 143), ("INT", 130), ("HUP", 129)] {
        for (flag, dest) in [("-o", "out"), ("--pack", "out.vtpk")] {
            let child = Command::new(BIN)
                .args(["split", s(&input), flag, s(&dir.path().join(dest))])
                .args(["--codec", "png", "--png-compression", "best", "--tile-size", "256", "--quiet"])
                .stdout(Stdio::null())
                .stderr(Stdio::piped())
                .spawn()
                .unwrap();
            // Wait until the run has started writing, then signal it.
            let started = Instant::now();
            while listing(dir.path()).len() < 2 && started.elapsed() < Duration::from_secs(20) {
                std::thread::sleep(Duration::from_millis(5));
            }
            let sent = Command::new("kill").args([&format!("-{signal}"), &child.id().to_string()]).status().unwrap();
            assert!(sent.success());
            let out = child.wait_with_output().unwrap();
            let err = String::from_utf8_lossy(&out.stderr);
            assert_eq!(out.status.code(), Some(code), "SIG{signal} {flag}: {err}");
            assert!(err.contains("interrupted") && !err.contains("panicked"), "{err}");
            assert_eq!(listing(dir.path()), ["noise.ppm"], "SIG{signal} {flag} left temporaries");
        }
    }
}

#[test]
fn output_to_a_closed_pipe_ends_quietly() {
    let (dir, input) = scratch_with_input();
    let pack = dir.path().join("p.vtpk");
    ok(&["split", s(&input), "--pack", s(&pack), "--quiet"]);
    for command in ["verify", "info"] {
        // The reading end is closed before the child starts, so its first write finds no reader
        // whatever the scheduling (closing it after the spawn could race the child's output).
        let (reader, writer) = std::io::pipe().unwrap();
        drop(reader);
        let out = Command::new(BIN).args([command, s(&pack)]).stdout(writer).stderr(Stdio::piped()).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(matches!(out.status.code(), Some(0 | 141)), "{command}: {:?} {err}", out.status);
        assert!(err.is_empty(), "{command}: {err}");
    }
}

#[test]
fn messages_point_the_right_way() {
    let (dir, input) = scratch_with_input();
    for command in ["info", "verify", "unpack"] {
        let mut args = vec![command, s(dir.path())];
        if command == "unpack" {
            args.extend(["-o", "/nonexistent/never"]);
        }
        fails_with(&run(&args), &["is a directory"]);
    }
    fails_with(&run(&["convert", s(&input), "--pack", s(&dir.path().join("p.vtpk"))]), &["vortex-tiler split"]);
    assert_eq!(listing(dir.path()), ["in.png"]);
}

#[cfg(unix)]
#[test]
fn a_fifo_input_is_refused_at_once() {
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("in.png");
    assert!(Command::new("mkfifo").arg(&fifo).status().unwrap().success());
    let started = Instant::now();
    fails_with(&run(&["split", s(&fifo), "--pack", s(&dir.path().join("p.vtpk"))]), &["not a regular file"]);
    assert!(started.elapsed() < Duration::from_secs(10));
}

#[test]
fn settings_from_an_existing_info_json_are_shown_and_never_lose_data() {
    let (dir, _) = scratch_with_input();
    let out = dir.path().join("out");
    ok(&["split", s(&fixture("sample.png")), "-o", s(&out), "--tile-size", "64", "--quiet"]);
    // An RGBA image into a directory that held an RGB JPEG pyramid would lose its alpha.
    let rgba = fixture("rgba8-130x67.png");
    fails_with(&run(&["split", s(&rgba), "-o", s(&out)]), &["info.json", "tileFormat", "--flatten"]);
    let out_json = fs::read_to_string(out.join("info.json")).unwrap();
    assert!(out_json.contains("\"rgb\""), "{out_json}");
    // Settings that lose nothing are taken, and said.
    let again = run(&["split", s(&fixture("sample.png")), "-o", s(&out)]);
    assert!(again.status.success());
    let err = String::from_utf8_lossy(&again.stderr);
    assert!(err.contains("from") && err.contains("info.json") && err.contains("tileSize 64"), "{err}");
}

#[cfg(unix)]
#[test]
fn pack_checks_every_tile_file_against_info_json() {
    let (dir, input) = scratch_with_input();
    let out = dir.path().join("out");
    let small = dir.path().join("small");
    ok(&["split", s(&input), "-o", s(&out), "--tile-size", "64", "--quiet"]);
    ok(&["split", s(&input), "-o", s(&small), "--tile-size", "32", "--quiet"]);
    let tile = out.join("lod00-x0000-y0000.jpg");
    let pack = dir.path().join("p.vtpk");
    let original = fs::read(&tile).unwrap();
    fs::write(&tile, &original[..original.len() / 2]).unwrap();
    fails_with(&run(&["pack", s(&out), "-o", s(&pack)]), &["lod00-x0000-y0000.jpg", "truncated"]);
    fs::copy(small.join("lod00-x0000-y0000.jpg"), &tile).unwrap();
    fails_with(&run(&["pack", s(&out), "-o", s(&pack)]), &["lod00-x0000-y0000.jpg", "32x32", "64x64"]);
    fs::remove_file(&tile).unwrap();
    std::os::unix::fs::symlink("/dev/zero", &tile).unwrap();
    fails_with(&run(&["pack", s(&out), "-o", s(&pack)]), &["lod00-x0000-y0000.jpg", "not a regular file"]);
    fs::remove_file(&tile).unwrap();
    fs::write(&tile, &original).unwrap();
    ok(&["pack", s(&out), "-o", s(&pack), "--quiet"]);
    assert_eq!(listing(dir.path()), ["in.png", "out", "p.vtpk", "small"]);
}

#[test]
fn unpack_refuses_metadata_that_lies() {
    let (dir, input) = scratch_with_input();
    let pack = dir.path().join("p.vtpk");
    ok(&["split", s(&input), "--pack", s(&pack), "--quiet"]);
    let info: serde_json::Value = serde_json::from_slice(vortex_pack::Pack::open(&pack).unwrap().metadata()).unwrap();
    let liar = dir.path().join("liar.vtpk");
    for (field, value) in [
        ("tileCount", serde_json::json!(65536)),
        ("codec", serde_json::json!("png")),
        ("filenameFormat", serde_json::json!("%1$d-%2$d-%3$d.png")),
        ("tileFormat", serde_json::json!("rgba")),
    ] {
        let mut lie = info.clone();
        lie[field] = value;
        crate::common::with_metadata(&pack, &lie.to_string(), &liar);
        fails_with(&run(&["unpack", s(&liar), "-o", s(&dir.path().join("out"))]), &["liar.vtpk", "metadata"]);
    }
    assert_eq!(listing(dir.path()), ["in.png", "liar.vtpk", "p.vtpk"]);
}

#[test]
fn names_from_an_existing_info_json_that_clash_with_a_flag_name_the_file() {
    let (dir, input) = scratch_with_input();
    let out = dir.path().join("out");
    ok(&["split", s(&input), "-o", s(&out), "--quiet"]);
    fails_with(
        &run(&["split", s(&input), "-o", s(&out), "--codec", "png"]),
        &["info.json", "filenameFormat", "--filename-format"],
    );
    ok(&["split", s(&input), "-o", s(&out), "--codec", "png", "--ff", "%1$d/%2$d_%3$d.png", "--quiet"]);
    assert!(out.join("0/0_0.png").is_file());
}

/// A file name holding a terminal escape, a newline or bytes that are not UTF-8 is shown
/// escaped and quoted in every message (the error, the summary), so it can neither recolour
/// nor clear the terminal nor forge a line of output; an ordinary name reads as it is.
#[test]
fn names_with_control_characters_are_shown_escaped() {
    use std::os::unix::ffi::OsStrExt;
    let dir = tempfile::tempdir().unwrap();
    let evil = dir.path().join("red\u{1b}[31m\nerror: forged.png");
    fs::write(&evil, b"not an image").unwrap();
    let out = run(&["split", s(&evil), "-o", s(&dir.path().join("out"))]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(!err.contains('\u{1b}'), "a raw escape reached the terminal: {err:?}");
    assert!(err.contains(r#"red\u{1b}[31m\nerror: forged.png""#), "{err:?}");
    assert_eq!(err.lines().count(), 1, "the name's newline forged a line: {err:?}");

    // A valid image under such a name, into an output named so: the summary is escaped too.
    let png = dir.path().join("blue\u{1b}[2J.png");
    fs::copy(fixture("sample.png"), &png).unwrap();
    let target = dir.path().join("tiles\u{7}");
    let said = ok(&["split", s(&png), "-o", s(&target)]);
    assert!(!said.contains('\u{1b}') && !said.contains('\u{7}'), "{said:?}");
    assert!(said.contains(r#"tiles\u{7}""#), "{said:?}");

    // Bytes that are not UTF-8 show as escapes, not as replacement characters.
    let latin1 = dir.path().join(std::ffi::OsStr::from_bytes(b"caf\xe9.png"));
    fs::write(&latin1, b"not an image").unwrap();
    let out = Command::new(BIN).arg("split").arg(&latin1).arg("-o").arg(dir.path().join("o2")).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains(r"caf\xE9.png"), "{err:?}");

    // An ordinary name is shown as it is, unquoted.
    let plain = dir.path().join("plain name.png");
    fs::write(&plain, b"not an image").unwrap();
    let out = run(&["split", s(&plain), "-o", s(&dir.path().join("o3"))]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains(&format!("{}: ", plain.display())) && !err.contains('"'), "{err:?}");
}
