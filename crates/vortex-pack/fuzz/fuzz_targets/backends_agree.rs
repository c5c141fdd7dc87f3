//! The memory-map and in-memory backends give the same answers for any bytes. The map needs a
//! file: one scratch file per process, rewritten for each input. The property is
//! `vortex_pack_fuzz::backends_agree`, shared with `cargo test`.
#![no_main]

use std::path::PathBuf;
use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;

fn scratch() -> &'static PathBuf {
    static PATH: OnceLock<PathBuf> = OnceLock::new();
    PATH.get_or_init(|| std::env::temp_dir().join(format!("vortex-pack-fuzz-{}.vtpk", std::process::id())))
}

fuzz_target!(|data: &[u8]| vortex_pack_fuzz::backends_agree(data, scratch()));
