//! Every input under `fuzz/regressions/<target>/` (the fuzz corpus, minimised, and the
//! inputs of crashes once fixed) through the fuzz target's own checks, on stable: no panic,
//! and the in-memory and memory-mapped backends agree.

#[path = "../../fuzz/src/lib.rs"]
mod checks;

use std::path::{Path, PathBuf};

fn inputs(target: &str) -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/regressions").join(target);
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .collect();
    files.sort();
    assert!(!files.is_empty(), "{}: no regression inputs", dir.display());
    files
}

#[test]
fn open_and_read_regressions() {
    for file in inputs("open_and_read") {
        eprintln!("{}", file.display());
        checks::open_and_read(&std::fs::read(&file).unwrap());
    }
}

#[test]
fn backends_agree_regressions() {
    let dir = tempfile::tempdir().unwrap();
    let scratch = dir.path().join("case.vtpk");
    for file in inputs("backends_agree") {
        eprintln!("{}", file.display());
        checks::backends_agree(&std::fs::read(&file).unwrap(), &scratch);
    }
}
