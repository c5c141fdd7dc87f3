//! `split --resume` (docs/resume.md): a real run SIGKILLed half-way, then the same command
//! with `--resume`, gives the bytes of an uninterrupted run and encodes only what was left; a
//! damaged staged tile is made again; a journal of another run is refused, naming what
//! differs; with nothing to resume the run starts afresh. The same for outputs at `s3://`,
//! against moto's S3 server (`common::s3`).

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use crate::common::cli::{BIN, fails_with, run, s, wait_or_kill};
use crate::common::s3::Moto;

/// A 2048 x 1536 PPM: noise (each tile's own bytes), with a flat block (one-colour tiles, and
/// tiles a pack stores once).
fn image(path: &Path) {
    let (w, h) = (2048usize, 1536usize);
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut bytes = format!("P6\n{w} {h}\n255\n").into_bytes();
    for y in 0..h {
        for x in 0..w {
            let flat = (256..768).contains(&x) && (512..1024).contains(&y);
            for c in 0..3u64 {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                bytes.push(if flat { 40 + 60 * c as u8 } else { (state >> 24) as u8 });
            }
        }
    }
    std::fs::write(path, bytes).unwrap();
}

/// The output of a kind: its flags (the last one takes the path), and the tiles it holds
/// (128-texel tiles of 2048 x 1536, no border).
struct Kind {
    flags: &'static [&'static str],
    name: &'static str,
    tiles: u64,
    /// Whether a resumed run keeps exactly the tiles journaled. Identical pages (the flat
    /// block's) merged into one job at the cut are kept only where every one of their places
    /// was journaled: a run killed among them encodes that job again, once, and keeps fewer
    /// tiles than journaled (up to the flat block's 16). With this image and kill point that
    /// happens to IIIF, XYZ and Google (measured: 126 kept of 128 journaled), not to the others.
    keeps_all: bool,
}

/// A pack: 16 x 12 pages, then 8 x 6, 4 x 3, 2 x 2, 1.
const PACK: Kind =
    Kind { flags: &["--border", "0", "--pack"], name: "out.vtpk", tiles: 192 + 48 + 12 + 4 + 1, keeps_all: true };
/// Deep Zoom: the same grid down to one page, then on down to one texel (levels 0 to 11 of
/// 2048 x 1536: 192 + 48 + 12 + 4 + 1 + 1 x 7).
const DZI: Kind = Kind {
    flags: &["--overlap", "0", "--layout", "dzi", "-o"],
    name: "out",
    tiles: 192 + 48 + 12 + 4 + 1 + 7,
    keeps_all: true,
};

/// IIIF, XYZ and Google: the same grid, no levels below one page (16 x 16 pages of the
/// web-mercator square for XYZ and Google, and as many IIIF tiles).
const IIIF: Kind = Kind { flags: &["--layout", "iiif", "-o"], name: "out", tiles: 257, keeps_all: false };
const XYZ: Kind = Kind { flags: &["--layout", "xyz", "-o"], name: "out", tiles: 257, keeps_all: false };
const GOOGLE: Kind = Kind { flags: &["--layout", "google", "-o"], name: "out", tiles: 257, keeps_all: false };

/// The command of a run into `dest`: slow enough per tile (PNG at its best compression, one
/// encoder thread) that the test can stop it half-way.
fn command(input: &Path, kind: &Kind, dest: &Path, extra: &[&str]) -> Vec<String> {
    let mut args: Vec<String> = vec!["split".into(), s(input).into()];
    args.extend(kind.flags.iter().map(|f| f.to_string()));
    args.push(s(dest).into());
    for a in ["--tile-size", "128", "--codec", "png", "--png-compression", "best", "--threads", "1"] {
        args.push(a.into());
    }
    args.extend(extra.iter().map(|a| a.to_string()));
    args
}

/// The uninterrupted run of `kind` on `input`, into `ref/` under the same name, and the command
/// that writes the same output into `dir`: (the reference, the destination, the command).
fn reference_and_command(dir: &Path, input: &Path, kind: &Kind) -> (PathBuf, PathBuf, Vec<String>) {
    std::fs::create_dir_all(dir.join("ref")).unwrap();
    let reference = dir.join("ref").join(kind.name);
    run_ok(&[command(input, kind, &reference, &[]), vec!["-q".into()]].concat());
    let dest = dir.join(kind.name);
    let args = command(input, kind, &dest, &[]);
    (reference, dest, args)
}

fn run_ok(args: &[String]) -> (String, String) {
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let out = run(&args);
    let (stdout, stderr) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "{args:?}: {stderr}");
    (stdout.into_owned(), stderr.into_owned())
}

/// The `--json` summary's number `key`.
fn number(json: &str, key: &str) -> u64 {
    let doc: serde_json::Value = serde_json::from_str(json).unwrap_or_else(|e| panic!("{e}: {json}"));
    doc[key].as_u64().unwrap_or_else(|| panic!("no {key} in {json}"))
}

/// Files beside `dest` whose names start with `.NAME.` + `what`.
fn beside(dest: &Path, what: &str) -> Vec<PathBuf> {
    let prefix = format!(".{}.{what}", dest.file_name().unwrap().to_string_lossy());
    let dir = dest.parent().unwrap();
    let mut found: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.file_name().unwrap().to_string_lossy().starts_with(&prefix))
        .collect();
    found.sort();
    found
}

/// The tiles a journal records: its whole lines after the two of its header.
fn recorded(journal: &Path) -> Vec<String> {
    let text = std::fs::read_to_string(journal).unwrap_or_default();
    let lines: Vec<&str> = text.split_inclusive('\n').filter(|l| l.ends_with('\n')).collect();
    lines.iter().skip(2).map(|l| l.trim_end().to_string()).collect()
}

/// Starts `args` (with `--resume`), SIGKILLs it once its journal records half of `total`
/// tiles, and returns the journal, then holding what the run finished.
fn kill_half_way(args: &[String], dest: &Path, total: u64) -> PathBuf {
    stop_half_way(args, dest, total, "-KILL").0
}

/// [`kill_half_way`] with `signal`; also the run's exit status and standard error.
fn stop_half_way(args: &[String], dest: &Path, total: u64, signal: &str) -> (PathBuf, Option<i32>, String) {
    let journal = || beside(dest, "resume-").into_iter().next();
    let mut command = Command::new(BIN);
    command.args(args);
    let (code, stderr) =
        stop_when(command, &|_| until(&|| journal().is_some_and(|j| recorded(&j).len() as u64 >= total / 2)), signal);
    let journal = journal().expect("the stopped run's journal stays");
    let n = recorded(&journal).len() as u64;
    assert!(n >= total / 2 && n < total, "{n} of {total} tiles journaled");
    (journal, code, stderr)
}

/// Waits until `reached` (with a fail-safe deadline, not a timing).
fn until(reached: &dyn Fn() -> bool) {
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(120);
    while !reached() && std::time::Instant::now() < deadline {
        std::thread::sleep(std::time::Duration::from_millis(2));
    }
}

/// Sends `signal` (`-STOP`) to process `pid`.
fn send(pid: u32, signal: &str) {
    assert!(Command::new("kill").args([signal, &pid.to_string()]).status().unwrap().success());
}

/// Waits until more than half the Deep Zoom tiles (and the marker) are in `moto`'s
/// `tiles/run/out/`, counted with the run `pid` stopped, so that it cannot go on while the
/// server answers (its uploads in flight still land, at most 64 of them); it stays stopped.
fn half_in_bucket(moto: &Moto, pid: u32) {
    until(&|| {
        send(pid, "-STOP");
        let half = moto.quick_count("tiles", "run/out/") as u64 > DZI.tiles / 2;
        if !half {
            send(pid, "-CONT");
        }
        half
    })
}

/// Starts `command` with `--resume`, stops it with `signal` once `half_way` (given its process
/// id) returns, and returns its exit status and standard error.
fn stop_when(mut command: Command, half_way: &dyn Fn(u32), signal: &str) -> (Option<i32>, String) {
    let mut child = command
        .arg("--resume")
        .arg("-q")
        .env("NO_COLOR", "1")
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let pid = child.id();
    half_way(pid);
    send(pid, "-STOP");
    let running = child.try_wait().unwrap().is_none();
    assert!(running, "the run finished before it was stopped half-way");
    send(pid, signal);
    send(pid, "-CONT");
    let out = wait_or_kill(pid, "a run stopped half-way", || child.wait_with_output().unwrap());
    assert!(!out.status.success());
    (out.status.code(), String::from_utf8_lossy(&out.stderr).into_owned())
}

/// Every file under `dir`, by its path relative to it, with its bytes.
fn files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    fn walk(dir: &Path, root: &Path, out: &mut Vec<(String, Vec<u8>)>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                walk(&p, root, out);
            } else {
                out.push((p.strip_prefix(root).unwrap().display().to_string(), std::fs::read(&p).unwrap()));
            }
        }
    }
    let mut out = Vec::new();
    walk(dir, dir, &mut out);
    out.sort();
    out
}

fn same_output(a: &Path, b: &Path) {
    if a.is_dir() {
        let (fa, fb) = (files(a), files(b));
        assert_eq!(fa.len(), fb.len(), "{} and {} hold other files", a.display(), b.display());
        for ((na, ba), (nb, bb)) in fa.iter().zip(&fb) {
            assert_eq!(na, nb);
            assert!(ba == bb, "{na} differs");
        }
    } else {
        assert!(std::fs::read(a).unwrap() == std::fs::read(b).unwrap(), "{} differs from {}", a.display(), b.display());
    }
}

/// Killed half-way, resumed: the uninterrupted run's bytes; the resumed run keeps every tile
/// the journal recorded and encodes at most what was left; nothing stays beside the output.
fn killed_and_resumed(kind: &Kind) {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in.ppm");
    image(&input);
    // In a folder of its own, under the same name.
    std::fs::create_dir(dir.path().join("ref")).unwrap();
    let reference = dir.path().join("ref").join(kind.name);
    let (json, _) = run_ok(&[command(&input, kind, &reference, &[]), vec!["--json".into()]].concat());
    let (whole_encoded, tiles) = (number(&json, "encoded"), number(&json, "tiles"));
    assert_eq!(tiles, kind.tiles);

    let dest = dir.path().join(kind.name);
    let args = command(&input, kind, &dest, &[]);
    let journal = kill_half_way(&args, &dest, kind.tiles);
    let at_kill = recorded(&journal).len() as u64;
    let (json, stderr) = run_ok(&[args.clone(), vec!["--resume".into(), "--json".into()]].concat());
    assert!(stderr.contains("resuming the interrupted run"), "{stderr}");
    same_output(&dest, &reference);
    let (kept, encoded) = (number(&json, "kept"), number(&json, "encoded"));
    assert_eq!(number(&json, "tiles"), kind.tiles);
    // Every tile journaled before the kill is whole: kept, not encoded again (but where it
    // shares a job with one that was not journaled: see `Kind::keeps_all`).
    match kind.keeps_all {
        true => assert_eq!(kept, at_kill, "{json}"),
        false => assert!(kept <= at_kill && kept + 16 >= at_kill, "kept {kept} of {at_kill} journaled: {json}"),
    }
    // What the resumed run encoded: at most what was left (the one-colour tiles need none),
    // and so (half the tiles were left, none of them one-colour) little more than half of
    // what an uninterrupted run encodes.
    assert!(encoded <= kind.tiles - kept && encoded <= whole_encoded, "{json}");
    assert!(encoded * 100 <= whole_encoded * 60, "encoded {encoded} of {whole_encoded}");
    assert!(beside(&dest, "").is_empty(), "left beside the output: {:?}", beside(&dest, ""));
}

#[test]
fn a_killed_pack_is_resumed_byte_for_byte() {
    killed_and_resumed(&PACK);
}

#[test]
fn a_killed_deep_zoom_is_resumed_byte_for_byte() {
    killed_and_resumed(&DZI);
}

#[test]
fn a_killed_iiif_output_is_resumed_byte_for_byte() {
    killed_and_resumed(&IIIF);
}

#[test]
fn a_killed_xyz_output_is_resumed_byte_for_byte() {
    killed_and_resumed(&XYZ);
}

#[test]
fn a_killed_google_output_is_resumed_byte_for_byte() {
    killed_and_resumed(&GOOGLE);
}

/// SIGTERM (what Slurm sends at a time limit, before SIGKILL) stops a resumable run cleanly,
/// and it keeps what it staged and its journal, and says so; `--resume` goes on from them.
#[test]
fn a_run_stopped_by_sigterm_keeps_its_tiles_for_resume() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in.ppm");
    image(&input);
    let (reference, dest, args) = reference_and_command(dir.path(), &input, &PACK);
    let (journal, code, stderr) = stop_half_way(&args, &dest, PACK.tiles, "-TERM");
    assert_eq!(code, Some(143), "{stderr}");
    assert!(stderr.contains("run the same command with --resume") && !stderr.contains("panicked"), "{stderr}");
    assert!(stderr.contains("error: interrupted; what was finished stays for --resume"), "{stderr}");
    assert_eq!(beside(&dest, "tmp-").len(), 1, "the staged pack stays");
    let at_stop = recorded(&journal).len() as u64;
    let (json, _) = run_ok(&[args, vec!["--resume".into(), "--json".into()]].concat());
    same_output(&dest, &reference);
    assert_eq!(number(&json, "kept"), at_stop, "{json}");
}

/// A staged tile damaged after the kill is found by its checksum and made again: for a pack,
/// it and every tile the killed run stored after it (a pack's payloads lie in order); for a
/// directory, that tile.
#[test]
fn a_damaged_staged_tile_is_made_again() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in.ppm");
    image(&input);
    for kind in [&PACK, &DZI] {
        let (reference, dest, args) = reference_and_command(dir.path(), &input, kind);
        let journal = kill_half_way(&args, &dest, kind.tiles);
        let records = recorded(&journal);
        let staged = beside(&dest, if kind.name.ends_with(".vtpk") { "tmp-" } else { "partial-" });
        let [staged] = staged.as_slice() else { panic!("one staged output: {staged:?}") };
        // The 10th recorded tile with bytes of its own.
        let words: Vec<Vec<&str>> = records.iter().map(|r| r.split(' ').collect()).collect();
        let damaged_at = if kind.name.ends_with(".vtpk") {
            // e LOD X Y KIND OFFSET LEN CRC: a payload's first byte.
            let mut seen = std::collections::HashSet::new();
            let (k, w) = (words.iter().enumerate())
                .filter(|(_, w)| w[0] == "e" && w[6] != "0" && seen.insert(w[5]))
                .nth(9)
                .unwrap();
            let offset = u64::from_str_radix(w[5], 16).unwrap();
            let mut bytes = std::fs::read(staged).unwrap();
            bytes[offset as usize] ^= 0x5a;
            std::fs::write(staged, bytes).unwrap();
            k as u64
        } else {
            // f LOD X Y LEN CRC: Deep Zoom names its files after the input; its level of LOD 0 is
            // the deepest (11 for 2048 px).
            let w = &words[9];
            let (lod, x, y): (u32, u32, u32) = (w[1].parse().unwrap(), w[2].parse().unwrap(), w[3].parse().unwrap());
            let file = staged.join(format!("in_files/{}/{x}_{y}.png", 11 - lod));
            assert!(file.exists(), "{}", file.display());
            std::fs::write(&file, b"damaged").unwrap();
            records.len() as u64 - 1
        };
        let (json, _) = run_ok(&[args.clone(), vec!["--resume".into(), "--json".into()]].concat());
        same_output(&dest, &reference);
        assert_eq!(number(&json, "kept"), damaged_at, "{}: {json}", kind.name);
    }
}

/// A journal of another run is refused, naming what differs, and left as it is; a run without
/// `--resume` starts afresh and removes it; `--resume` with nothing to resume starts afresh.
#[test]
fn another_runs_journal_is_refused_and_nothing_to_resume_starts_afresh() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in.ppm");
    image(&input);
    let (reference, dest, args) = reference_and_command(dir.path(), &input, &PACK);
    let journal = kill_half_way(&args, &dest, PACK.tiles);
    let before = std::fs::read(&journal).unwrap();

    // Other options, another input.
    let mut other = args.clone();
    let at = other.iter().position(|a| a == "128").unwrap();
    other[at] = "64".into();
    other.push("--resume".into());
    let out = run(&other.iter().map(String::as_str).collect::<Vec<_>>());
    fails_with(&out, &[".out.vtpk.resume-", "tile size 64, not 128", "leave out --resume"]);
    let moved = dir.path().join("moved.ppm");
    std::fs::copy(&input, &moved).unwrap();
    let mut bytes = std::fs::read(&moved).unwrap();
    let last = bytes.len() - 1;
    bytes[last] ^= 1;
    std::fs::write(&moved, bytes).unwrap();
    let another = [command(&moved, &PACK, &dest, &[]), vec!["--resume".into()]].concat();
    let out = run(&another.iter().map(String::as_str).collect::<Vec<_>>());
    fails_with(&out, &["input fingerprint"]);
    assert_eq!(std::fs::read(&journal).unwrap(), before, "a refusal changes nothing");
    assert_eq!(beside(&dest, "tmp-").len(), 1);

    // Without --resume: afresh, the killed run's files removed (and said so).
    let (_, stderr) = run_ok(&args);
    assert!(stderr.contains("--resume would have gone on"), "{stderr}");
    same_output(&dest, &reference);
    assert!(beside(&dest, "").is_empty());

    // --resume with nothing to resume: afresh, journaled, the journal gone once done.
    std::fs::remove_file(&dest).unwrap();
    let (_, stderr) = run_ok(&[args.clone(), vec!["--resume".into()]].concat());
    assert!(stderr.contains("nothing to resume: starting afresh"), "{stderr}");
    same_output(&dest, &reference);
    assert!(beside(&dest, "").is_empty());
}

/// What `--resume` does not take is refused before anything is written, naming it.
#[test]
fn resume_refuses_what_it_cannot_resume() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in.ppm");
    image(&input);
    let d = |n: &str| dir.path().join(n);
    for (args, needles) in [
        (vec!["--pmtiles", s(&d("a.pmtiles"))], vec!["a.pmtiles", "cannot resume a pmtiles output"]),
        (vec!["-o", s(&d("z")), "--layout", "ome-zarr"], vec!["cannot resume a ome-zarr output", "--layout dzi, iiif"]),
        (vec!["-o", s(&d("a")), "--pack", s(&d("b.vtpk"))], vec!["one output; this one writes 2"]),
        (vec!["--pack", s(&d("s.vtpk")), "--shard", "0/2"], vec!["a shard is made again whole"]),
    ] {
        let mut all = vec!["split", s(&input), "--resume"];
        all.extend(args);
        let out = run(&all);
        fails_with(&out, &needles);
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1, "{all:?} wrote something");
    }
    // --help teaches it.
    let help =
        String::from_utf8_lossy(&run(&["split", "--help"]).stdout).split_whitespace().collect::<Vec<_>>().join(" ");
    assert!(help.contains("--resume") && help.contains("docs/resume.md") && help.contains("starts afresh"), "{help}");
}

/// The arguments as `&str`s.
fn strs(args: &[String]) -> Vec<&str> {
    args.iter().map(String::as_str).collect()
}

/// Every object under `prefix/` of `bucket`, downloaded: its name under the prefix and bytes.
fn download(moto: &Moto, bucket: &str, prefix: &str) -> Vec<(String, Vec<u8>)> {
    let dir = tempfile::tempdir().unwrap();
    moto.boto(&["get", bucket, &format!("{prefix}/"), s(dir.path())]);
    files(dir.path())
}

/// Deep Zoom at an `s3://` prefix, SIGKILLed once half its tiles are in the bucket, then the
/// same command with `--resume` as on another machine (on what the bucket holds: the input
/// copied elsewhere, another TMPDIR): the
/// objects are the uninterrupted local run's files byte for byte, every tile uploaded before
/// the kill is kept, the marker no longer names the run; a run of other options is refused
/// before anything is written or deleted.
#[test]
fn a_killed_deep_zoom_in_a_bucket_is_resumed_byte_for_byte() {
    let Some(moto) = Moto::start("the s3:// Deep Zoom --resume test") else { return };
    moto.boto(&["mb", "tiles"]);
    let (dir, tmp) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let input = dir.path().join("in.ppm");
    image(&input);
    std::fs::create_dir(dir.path().join("ref")).unwrap();
    let reference = dir.path().join("ref").join(DZI.name);
    let (json, _) = run_ok(&[command(&input, &DZI, &reference, &[]), vec!["--json".into()]].concat());
    let (whole_encoded, whole_bytes) = (number(&json, "encoded"), number(&json, "bytes"));

    let args = command(&input, &DZI, Path::new("s3://tiles/run/out"), &[]);
    stop_when(moto.command(&strs(&args), tmp.path()), &|pid| half_in_bucket(&moto, pid), "-KILL");
    let listed = moto.boto(&["keys", "tiles", "run/out/"]);
    let at_kill = listed.iter().filter(|k| !k.ends_with("/.vortex-tiler")).count() as u64;
    assert!((DZI.tiles / 2..DZI.tiles).contains(&at_kill), "{at_kill} of {} tiles uploaded", DZI.tiles);

    // Other options: refused, naming what differs, and nothing in the bucket changes.
    let mut other = args.clone();
    let at = other.iter().position(|a| a == "128").unwrap();
    other[at] = "64".into();
    other.push("--resume".into());
    let out = moto.run(&strs(&other), tmp.path());
    fails_with(&out, &["s3://tiles/run/out/.vortex-tiler", "tile size 64, not 128", "leave out --resume"]);
    assert_eq!(moto.boto(&["keys", "tiles", "run/out/"]), listed, "a refusal changes nothing");

    // As on another machine: the input elsewhere (the same file), another TMPDIR.
    let elsewhere = dir.path().join("elsewhere");
    std::fs::create_dir(&elsewhere).unwrap();
    std::fs::copy(&input, elsewhere.join("in.ppm")).unwrap();
    let args = command(&elsewhere.join("in.ppm"), &DZI, Path::new("s3://tiles/run/out"), &["--resume", "--json"]);
    let other_tmp = tempfile::tempdir().unwrap();
    let out = moto.run(&strs(&args), other_tmp.path());
    let (json, stderr) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success() && stderr.contains("resuming the interrupted run"), "{stderr}");
    let (kept, encoded, uploaded) = (number(&json, "kept"), number(&json, "encoded"), number(&json, "uploadedBytes"));
    assert_eq!(number(&json, "tiles"), DZI.tiles);
    // Every tile uploaded before the kill is whole (a PUT is): kept, neither encoded nor sent again.
    assert_eq!(kept, at_kill, "{json}");
    assert!(encoded <= DZI.tiles - kept && encoded * 100 <= whole_encoded * 60, "{json}");
    assert!(uploaded * 100 <= whole_bytes * 60, "uploaded {uploaded} of {whole_bytes} bytes");

    let mut bucket = download(&moto, "tiles", "run/out");
    let at = bucket.iter().position(|(name, _)| name == ".vortex-tiler").expect("the marker");
    let marker = String::from_utf8(bucket.remove(at).1).unwrap();
    assert!(marker.contains("\"state\":\"complete\"") && !marker.contains("\"run\""), "{marker}");
    let local = files(&reference);
    assert_eq!(bucket.len(), local.len(), "the bucket holds other objects than the local run's files");
    for ((name, bytes), (local_name, local_bytes)) in bucket.iter().zip(&local) {
        assert_eq!(name, local_name);
        assert!(bytes == local_bytes, "{name} differs");
    }
    // Nothing else anywhere in the bucket, nothing in either TMPDIR.
    assert_eq!(moto.boto(&["keys", "tiles", ""]).len(), local.len() + 1);
    for tmp in [tmp.path(), other_tmp.path()] {
        assert_eq!(std::fs::read_dir(tmp).unwrap().count(), 0, "TMPDIR keeps files");
    }
}

/// A pack at `s3://`, staged on this machine: SIGKILLed once its journal (beside the staged
/// pack, under TMPDIR) records half the tiles, then resumed: the object is the uninterrupted
/// local run's pack byte for byte, the journaled tiles are kept, and nothing stays in TMPDIR,
/// the bucket or its multipart uploads.
#[test]
fn a_killed_pack_in_a_bucket_is_resumed_byte_for_byte() {
    let Some(moto) = Moto::start("the s3:// pack --resume test") else { return };
    moto.boto(&["mb", "tiles"]);
    let (dir, tmp) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let input = dir.path().join("in.ppm");
    image(&input);
    std::fs::create_dir(dir.path().join("ref")).unwrap();
    let reference = dir.path().join("ref").join(PACK.name);
    let (json, _) = run_ok(&[command(&input, &PACK, &reference, &[]), vec!["--json".into()]].concat());
    let whole_encoded = number(&json, "encoded");

    let args = command(&input, &PACK, Path::new("s3://tiles/run/out.vtpk"), &[]);
    let journal = || {
        let staged = std::fs::read_dir(tmp.path()).ok()?.map(|e| e.unwrap().path());
        let mut staged = staged.filter(|p| p.file_name().unwrap().to_string_lossy().starts_with("vortex-s3-resume-"));
        beside(&staged.next()?.join(PACK.name), "resume-").into_iter().next()
    };
    let half_way = |_| until(&|| journal().is_some_and(|j| recorded(&j).len() as u64 >= PACK.tiles / 2));
    stop_when(moto.command(&strs(&args), tmp.path()), &half_way, "-KILL");
    let at_kill = recorded(&journal().expect("the killed run's journal stays")).len() as u64;
    assert!((PACK.tiles / 2..PACK.tiles).contains(&at_kill), "{at_kill} of {} tiles journaled", PACK.tiles);
    assert!(moto.boto(&["keys", "tiles", ""]).is_empty(), "a killed run's pack is visible");

    let out = moto.run(&strs(&[args, vec!["--resume".into(), "--json".into()]].concat()), tmp.path());
    let (json, stderr) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success() && stderr.contains("resuming the interrupted run"), "{stderr}");
    let (kept, encoded) = (number(&json, "kept"), number(&json, "encoded"));
    assert_eq!(kept, at_kill, "{json}");
    assert!(encoded <= PACK.tiles - kept && encoded * 100 <= whole_encoded * 60, "{json}");
    let pack = std::fs::read(&reference).unwrap();
    assert_eq!(number(&json, "uploadedBytes"), pack.len() as u64, "{json}");

    let got = tempfile::tempdir().unwrap();
    assert_eq!(moto.boto(&["get", "tiles", "run/out.vtpk", s(got.path())]), ["run/out.vtpk"]);
    assert!(std::fs::read(got.path().join(PACK.name)).unwrap() == pack, "the object differs from the local pack");
    assert_eq!(moto.boto(&["keys", "tiles", ""]), ["run/out.vtpk"]);
    assert!(moto.boto(&["uploads", "tiles"]).is_empty(), "a multipart upload was left open");
    assert_eq!(std::fs::read_dir(tmp.path()).unwrap().count(), 0, "TMPDIR keeps files");
}

/// SIGTERM (Slurm's first signal at a time limit) stops a `--resume` run at an `s3://` prefix
/// cleanly, and what it uploaded stays under the prefix (the marker still says `writing`), and
/// it says so; `--resume` then keeps those tiles. Without `--resume` the same prefix is cleared
/// and made afresh.
#[test]
fn a_deep_zoom_in_a_bucket_stopped_by_sigterm_keeps_its_tiles_for_resume() {
    let Some(moto) = Moto::start("the s3:// SIGTERM --resume test") else { return };
    moto.boto(&["mb", "tiles"]);
    let (dir, tmp) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let input = dir.path().join("in.ppm");
    image(&input);
    let args = command(&input, &DZI, Path::new("s3://tiles/run/out"), &[]);
    let (code, stderr) = stop_when(moto.command(&strs(&args), tmp.path()), &|pid| half_in_bucket(&moto, pid), "-TERM");
    assert_eq!(code, Some(143), "{stderr}");
    assert!(stderr.contains("stay under the prefix") && !stderr.contains("panicked"), "{stderr}");
    assert!(stderr.contains("error: interrupted; what was finished stays for --resume"), "{stderr}");
    let listed = moto.boto(&["keys", "tiles", "run/out/"]);
    let tiles = listed.iter().filter(|k| !k.ends_with("/.vortex-tiler")).count() as u64;
    assert!(tiles > DZI.tiles / 2, "{tiles} tiles stayed");

    let out = moto.run(&strs(&[args.clone(), vec!["--resume".into(), "--json".into()]].concat()), tmp.path());
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(number(&String::from_utf8_lossy(&out.stdout), "kept"), tiles);
    // Without --resume: afresh.
    let out = moto.run(&strs(&[args, vec!["--json".into()]].concat()), tmp.path());
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(number(&String::from_utf8_lossy(&out.stdout), "kept"), 0);
}
