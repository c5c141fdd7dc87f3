//! Whatever the bytes, opening a pack, reading and decoding every tile and verifying it
//! return errors, never panic, and allocate within the decoding limit.
#![no_main]

use libfuzzer_sys::fuzz_target;
use vortex_pack::{Pack, VerifyOptions, decode_rgba8_limited, verify};

const LIMIT: u64 = 1 << 22;

fuzz_target!(|data: &[u8]| {
    let Some(path) = vortex_pack_fuzz::pack_file(data) else { return };
    let Ok(pack) = Pack::open(&path) else { return };
    let ids: Vec<_> = pack.ids().collect();
    for id in ids {
        let _ = pack.tile(id.lod, id.x, id.y);
        let _ = pack.tile_checked(id.lod, id.x, id.y);
        if let Ok(Some(rgba)) = decode_rgba8_limited(&pack, id.lod, id.x, id.y, LIMIT) {
            let side = pack.description().tile_size as usize;
            assert_eq!(rgba.len(), side * side * 4);
        }
    }
    let _ = pack.ids_in_file_order();
    let report = verify(&pack, VerifyOptions { decode: true, max_decoded_bytes: LIMIT });
    let _ = (report.to_string(), report.to_json());
});
