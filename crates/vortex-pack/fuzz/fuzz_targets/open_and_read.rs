//! Whatever the bytes, opening a pack (in memory, no file per input), reading and decoding
//! every tile and verifying it return errors, never panic, and allocate within the decoding
//! limit. The property is `vortex_pack_fuzz::open_and_read`, shared with `cargo test`.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| vortex_pack_fuzz::open_and_read(data));
