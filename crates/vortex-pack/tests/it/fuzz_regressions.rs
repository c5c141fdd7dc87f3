//! Every input under `fuzz/regressions/<target>/` through the fuzz target's own checks, on
//! stable: no panic, and the in-memory and memory-mapped backends agree.
//!
//! The `cov-NN-*` files are the fuzz corpus cut down to a few dozen: after a run and
//! `cargo fuzz cmin`, a greedy set cover over the edges each input reaches
//! (`-merge_control_file`, counters off), largest gain first (`NN` is the rank); they reach
//! about 90% of the edges of the whole minimised corpus. A crash the fuzzer finds is fixed and
//! its input kept here under a name that says what it was (`oom-...`, `panic-...`).

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
