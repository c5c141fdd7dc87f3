//! Packs from the command line: split --pack, pack, unpack, info.

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::common::cli::{BIN, fixture, ok, run, s};

/// Every file under `dir`, relative path -> bytes.
fn files(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push((p.strip_prefix(dir).unwrap().to_path_buf(), std::fs::read(&p).unwrap()));
            }
        }
    }
    out.sort();
    out
}

#[test]
fn split_pack_unpack_equals_split_to_files() {
    let dir = tempfile::tempdir().unwrap();
    for (img, extra) in [
        ("sample.png", &["--border", "4"][..]),
        ("rgba8-130x67.png", &["--tile-size", "32", "--background", "#102030"][..]),
        ("grey-alpha16-97x61.png", &["--tile-size", "16"][..]),
    ] {
        let files_dir = dir.path().join(format!("{img}.files"));
        let pack = dir.path().join(format!("{img}.vtpk"));
        let back = dir.path().join(format!("{img}.back"));
        let input = fixture(img);
        let a = ["split", s(&input), "-q"];
        ok(&[&a[..], &["-o", s(&files_dir)], extra].concat());
        ok(&[&a[..], &["--pack", s(&pack)], extra].concat());
        ok(&["unpack", s(&pack), "-o", s(&back), "-q"]);
        assert!(files(&back) == files(&files_dir), "{img}: unpack(split --pack) differs from split -o");

        // pack then unpack gives the same files back.
        let pack2 = dir.path().join(format!("{img}.2.vtpk"));
        let back2 = dir.path().join(format!("{img}.back2"));
        ok(&["pack", s(&files_dir), "-o", s(&pack2), "-q"]);
        ok(&["unpack", s(&pack2), "-o", s(&back2), "-q"]);
        assert!(files(&back2) == files(&files_dir), "{img}: unpack(pack) differs");
    }
}

#[test]
fn info_describes_the_pack() {
    let dir = tempfile::tempdir().unwrap();
    let pack = dir.path().join("s.vtpk");
    let line = ok(&["split", s(&fixture("sample.png")), "--pack", s(&pack), "--border", "4", "--align", "64K"]);
    // 700 x 500 in 120-texel payloads: 6 x 5, 3 x 3, 2 x 2 and 1 x 1 pages.
    assert!(line.contains("pack: 44 tiles"), "{line}");
    let text = ok(&["info", s(&pack)]);
    assert!(text.contains("700x500") && text.contains("4 levels") && text.contains("jpeg"), "{text}");
    let json: serde_json::Value = serde_json::from_str(&ok(&["info", s(&pack), "--json"])).unwrap();
    assert_eq!(json["tileSize"], 128);
    assert_eq!(json["alignment"], 65536);
    let grids: Vec<(u64, u64)> = json["levels"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| (l["tilesW"].as_u64().unwrap(), l["tilesH"].as_u64().unwrap()))
        .collect();
    assert_eq!(grids, [(6, 5), (3, 3), (2, 2), (1, 1)]);
    assert_eq!(json["metadata"]["codec"], "jpeg");
    let tiles: u64 = json["kinds"].as_object().unwrap().values().map(|k| k["tiles"].as_u64().unwrap()).sum();
    assert_eq!(tiles, 44);
}

#[test]
fn failed_runs_leave_no_pack() {
    let dir = tempfile::tempdir().unwrap();
    let png = std::fs::read(fixture("sample.png")).unwrap();
    let cut = dir.path().join("cut.png");
    std::fs::write(&cut, &png[..png.len() / 2]).unwrap();
    let pack = dir.path().join("out.vtpk");
    let out = run(&["split", s(&cut), "--pack", s(&pack)]);
    assert_eq!(out.status.code(), Some(1));
    let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(left.len(), 1, "only the input is left: {left:?}");

    // A directory with a missing tile cannot be packed; the error names the file.
    let tiles = dir.path().join("tiles");
    ok(&["split", s(&fixture("sample.png")), "-o", s(&tiles), "-q"]);
    std::fs::remove_file(tiles.join("lod00-x0003-y0002.jpg")).unwrap();
    let out = run(&["pack", s(&tiles), "-o", s(&pack)]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("lod00-x0003-y0002.jpg"), "{err}");
    assert!(!pack.exists());
}

#[test]
fn opening_something_else_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let not_pack = dir.path().join("x.vtpk");
    std::fs::write(&not_pack, vec![7u8; 500]).unwrap();
    let out = run(&["info", s(&not_pack)]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1));
    assert!(err.contains("x.vtpk") && err.contains("not a Vortex pack"), "{err}");
}

#[test]
fn packs_are_byte_identical_whatever_the_thread_count() {
    let dir = tempfile::tempdir().unwrap();
    let mut packs = Vec::new();
    for threads in ["1", "2", "3"] {
        let pack = dir.path().join(format!("t{threads}.vtpk"));
        ok(&["split", s(&fixture("sample.png")), "--pack", s(&pack), "--tile-size", "32", "--threads", threads, "-q"]);
        packs.push(std::fs::read(&pack).unwrap());
    }
    assert!(packs[0] == packs[1] && packs[1] == packs[2]);
}

#[test]
fn verify_passes_sound_packs_and_names_every_damaged_tile() {
    let dir = tempfile::tempdir().unwrap();
    let pack = dir.path().join("s.vtpk");
    ok(&["split", s(&fixture("sample.png")), "--pack", s(&pack), "--border", "4", "-q"]);
    let report = ok(&["verify", s(&pack), "--decode"]);
    assert!(report.contains("OK: no problem found"), "{report}");

    // Damage two payloads and one padding byte: all three are reported, exit code 1.
    let mut bytes = std::fs::read(&pack).unwrap();
    let json: serde_json::Value = serde_json::from_str(&ok(&["verify", s(&pack), "--json"])).unwrap();
    assert_eq!(json["ok"], true);
    let len = bytes.len();
    bytes[len - 100] ^= 1;
    bytes[len / 2] ^= 1;
    std::fs::write(&pack, &bytes).unwrap();
    let out = run(&["verify", s(&pack), "--json"]);
    assert_eq!(out.status.code(), Some(1));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let problems = json["problems"].as_array().unwrap();
    assert!(problems.len() >= 2, "{problems:?}");
    assert!(problems.iter().all(|p| p["offset"].is_u64()), "{problems:?}");

    // A truncated pack does not open; verify says so and fails.
    std::fs::write(&pack, &bytes[..len - 1]).unwrap();
    let out = run(&["verify", s(&pack)]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1));
    assert!(err.contains("truncated"), "{err}");
}

#[test]
fn a_killed_write_leaves_nothing_that_opens_as_a_pack() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("big.ppm");
    let mut bytes = b"P6\n3000 3000\n255\n".to_vec();
    bytes.resize(bytes.len() + 3 * 3000 * 3000, 90);
    std::fs::write(&input, bytes).unwrap();
    let pack = dir.path().join("out.vtpk");
    let mut child = Command::new(BIN)
        .args([
            "split",
            s(&input),
            "--pack",
            s(&pack),
            "--codec",
            "png",
            "--png-compression",
            "best",
            "--tile-size",
            "16",
            "-q",
        ])
        .spawn()
        .unwrap();
    let tmp = dir.path().join(format!(".out.vtpk.tmp-{}", child.id()));
    // The child gives no sign that it is part way through but its temporary file growing (it is
    // quiet, and any pipe of its own would change what it does): that file is polled, a bounded
    // number of times, and the child killed wherever it has got to. Nothing below depends on
    // how far: an unfinished pack is refused at any length.
    for _ in 0..4000 {
        if std::fs::metadata(&tmp).is_ok_and(|m| m.len() >= 100_000) || child.try_wait().unwrap().is_some() {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    assert!(Command::new("kill").args(["-KILL", &child.id().to_string()]).status().unwrap().success());
    let status = child.wait_with_output().unwrap().status;
    assert!(!status.success());
    assert!(!pack.exists(), "nothing at the destination");
    // The leftover temporary file starts with zeros and is refused as unfinished.
    let out = run(&["info", s(&tmp)]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1));
    assert!(err.contains("unfinished write"), "{err}");
}
