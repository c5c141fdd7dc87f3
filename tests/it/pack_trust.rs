//! What a pack's readers trust: nothing the index's checksum does not vouch for. One index entry
//! overwritten by another's (tile (3, 0) of LOD 0 given (4, 0)'s entry, the index CRC left as
//! it was, as bit rot or a bad patch would) reads as a valid entry pointing at a payload whose
//! own CRC passes; only the index CRC tells. Every command that reads a local pack must refuse
//! it at open (`convert`, `unpack`, `info`, `serve`, `render`), none may put (4, 0)'s pixels at
//! (3, 0), and `verify` reports it among its problems.

use std::path::{Path, PathBuf};

use vortex_pack::{Pack, TileId};

use crate::common::cli::{fails_with, fixture, ok, run, s, wait_or_kill};
use crate::common::server;

/// What every refusal says: the file and the section.
const INDEX: &str = "level table or index checksum mismatch";

/// sample.png (700 x 500) as a pack of 64-texel PNG pages (11 x 8 at LOD 0), with the entry of
/// page (3, 0) replaced by page (4, 0)'s and nothing else changed.
fn damaged_pack(dir: &Path) -> PathBuf {
    let pack = dir.join("damaged.vtpk");
    let args = ["--tile-size", "64", "--border", "0", "--codec", "png", "-q"];
    ok(&[&["split", s(&fixture("sample.png")), "--pack", s(&pack)][..], &args].concat());
    let (three, four) = {
        let p = Pack::open(&pack).unwrap();
        let at = |x| p.layout().entry_offset(p.position(TileId::new(0, x, 0)).unwrap()) as usize;
        // The two pages differ, so the swap would show.
        assert_ne!(p.tile(TileId::new(0, 3, 0)).unwrap(), p.tile(TileId::new(0, 4, 0)).unwrap());
        (at(3), at(4))
    };
    let mut bytes = std::fs::read(&pack).unwrap();
    let entry = vortex_pack::format::ENTRY_LEN;
    bytes.copy_within(four..four + entry, three);
    std::fs::write(&pack, &bytes).unwrap();
    pack
}

#[test]
fn the_library_refuses_a_swapped_entry_at_open_by_every_backend() {
    let dir = tempfile::tempdir().unwrap();
    let pack = damaged_pack(dir.path());
    let bytes = std::fs::read(&pack).unwrap();
    for opened in [Pack::open(&pack), Pack::open_read(&pack), Pack::from_bytes(&pack, bytes)] {
        let e = opened.err().expect("a pack whose index fails its checksum opens").to_string();
        assert!(e.contains(INDEX) && e.contains("damaged.vtpk"), "{e}");
    }
}

#[test]
fn convert_and_unpack_refuse_a_swapped_entry() {
    let dir = tempfile::tempdir().unwrap();
    let pack = damaged_pack(dir.path());
    for (command, out) in [("convert", "converted"), ("unpack", "unpacked")] {
        let out = dir.path().join(out);
        fails_with(&run(&[command, s(&pack), "-o", s(&out)]), &["damaged.vtpk", INDEX]);
        assert!(!out.exists(), "{command} left {}", out.display());
    }
    fails_with(&run(&["info", s(&pack)]), &["damaged.vtpk", INDEX]);
}

#[test]
fn verify_still_reports_a_swapped_entry_with_everything_else() {
    let dir = tempfile::tempdir().unwrap();
    let pack = damaged_pack(dir.path());
    let out = run(&["verify", s(&pack), "--json"]);
    assert_eq!(out.status.code(), Some(1), "{}", String::from_utf8_lossy(&out.stderr));
    // A full report (the tiles counted, every problem listed), not the open's one error.
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(json["tiles"].as_u64().unwrap() > 88, "{json}");
    let problems = json["problems"].as_array().unwrap();
    assert!(
        problems.iter().any(|p| p["section"] == "index" && p["message"].as_str().unwrap().contains(INDEX)),
        "{json}"
    );
}

#[test]
fn serve_refuses_a_swapped_entry_instead_of_serving_the_wrong_page() {
    let dir = tempfile::tempdir().unwrap();
    let pack = damaged_pack(dir.path());
    let (mut child, first) = server::spawn(&[s(&pack), "--addr", "127.0.0.1:0"]);
    if first.starts_with("serving") {
        let _ = child.kill();
        let _ = child.wait();
        panic!("serve started on a pack whose index fails its checksum: {first}");
    }
    let pid = child.id();
    let out = wait_or_kill(pid, "serve of a damaged pack", move || child.wait_with_output().unwrap());
    fails_with(&out, &["damaged.vtpk", INDEX]);
}

#[test]
fn render_refuses_a_swapped_entry_before_drawing() {
    let dir = tempfile::tempdir().unwrap();
    let pack = damaged_pack(dir.path());
    let frames = dir.path().join("frames");
    let out =
        run(&["render", "--pack", s(&pack), "--frames", s(&frames), "--size", "64x48", "--frame-count", "2", "-q"]);
    // The pack is opened before the GPU is looked for: this holds with or without an adapter.
    fails_with(&out, &["damaged.vtpk", INDEX]);
    assert!(!frames.exists());
}
