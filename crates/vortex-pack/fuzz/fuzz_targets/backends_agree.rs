//! The memory map and the read-into-memory backends give the same answers for any file.
#![no_main]

use libfuzzer_sys::fuzz_target;
use vortex_pack::{Pack, VerifyOptions, verify};

fuzz_target!(|data: &[u8]| {
    let Some(path) = vortex_pack_fuzz::pack_file(data) else { return };
    match (Pack::open(&path), Pack::open_read(&path)) {
        (Ok(a), Ok(b)) => {
            assert_eq!(a.file(), b.file());
            assert_eq!(a.header(), b.header());
            assert_eq!(a.levels(), b.levels());
            assert_eq!(a.metadata(), b.metadata());
            let ids: Vec<_> = a.ids().collect();
            assert!(ids.iter().copied().eq(b.ids()));
            for id in ids {
                let ta = a.tile_checked(id.lod, id.x, id.y).map_err(|e| e.to_string());
                let tb = b.tile_checked(id.lod, id.x, id.y).map_err(|e| e.to_string());
                assert_eq!(ta, tb);
            }
            assert_eq!(a.ids_in_file_order(), b.ids_in_file_order());
            let opts = VerifyOptions::default();
            assert_eq!(verify(&a, opts), verify(&b, opts));
        }
        (Err(a), Err(b)) => assert_eq!(a.to_string(), b.to_string()),
        (a, b) => panic!("the backends disagree: {:?} / {:?}", a.err(), b.err()),
    }
});
