//! The series' UIDs: a hash of what was converted and how, under a root.
//!
//! Every UID the series holds (study, series, frame of reference, each instance, the
//! dimension organisation, the specimen) is `ROOT.N`, `N` a 128-bit hash of the input's
//! identity (its fingerprint, `shard::fingerprint`), the options that shape the pixels and
//! the UID's role, written in decimal (cut to the digits that keep the UID within DICOM's 64
//! characters). The same input converted with the same options gets the same UIDs, so a
//! re-run writes the same bytes; any other conversion gets others.
//!
//! The default root is `2.25`, ISO/IEC 9834-8's arc for UUIDs, which needs no registration:
//! there `N` is the hash as a UUID (version 8, RFC 9562's custom layout), all 128 bits of it.
//! A site with a root of its own gives it with `--dicom-uid-root`.

use crate::error::{Result, TilerError};
use crate::fnv::Fnv;
use std::hash::Hasher;

/// The root UIDs are made under where `--dicom-uid-root` gives none: the UUID arc.
pub const DEFAULT_ROOT: &str = "2.25";

/// The longest root taken: it leaves 23 digits (76 bits) of hash in a 64-character UID.
const MAX_ROOT: usize = 40;

/// A root as DICOM's UIDs are made: numbers (no leading zero but `0` itself) joined by dots,
/// at most 40 characters so that the hash keeps enough digits.
pub fn check_root(root: &str) -> Result<()> {
    let bad = |why: &str| Err(TilerError::Options(format!("--dicom-uid-root {root:?}: {why}")));
    if root.is_empty() || root.len() > MAX_ROOT {
        return bad(&format!("a root is 1 to {MAX_ROOT} characters, leaving room for the hash in 64"));
    }
    for part in root.split('.') {
        if part.is_empty() || !part.bytes().all(|b| b.is_ascii_digit()) {
            return bad("a UID root is numbers joined by dots, such as 1.2.826.0.1.3680043.10.1234");
        }
        if part.len() > 1 && part.starts_with('0') {
            return bad(&format!("the component {part} has a leading zero, which UIDs do not allow"));
        }
    }
    Ok(())
}

/// The UIDs of one conversion.
pub(super) struct Uids {
    root: String,
    identity: String,
}

impl Uids {
    /// UIDs under `root` (checked) for a conversion described by `identity`.
    pub fn new(root: &str, identity: &str) -> Uids {
        Uids { root: root.to_string(), identity: identity.to_string() }
    }

    /// The UID of `role` ("study", "series", "instance 3", ...).
    pub fn of(&self, role: &str) -> String {
        let hash = hash128(&self.identity, role);
        if self.root == DEFAULT_ROOT {
            // A UUID: version 8 in bits 48..52, variant 0b10 in bits 64..66 (RFC 9562).
            let uuid = (hash & !(0xF << 76) & !(0b11 << 62)) | (0x8 << 76) | (0b10 << 62);
            return format!("{DEFAULT_ROOT}.{uuid}");
        }
        let digits = (64 - self.root.len() - 1).min(38);
        let n = hash % 10u128.pow(digits as u32);
        format!("{}.{n}", self.root)
    }
}

/// 128 bits of FNV-1a over `identity` and `role`: two 64-bit hashes of different starts.
/// Not a cryptographic hash: collisions are what is avoided, not forgeries.
fn hash128(identity: &str, role: &str) -> u128 {
    let half = |seed: u8| {
        let mut h = Fnv::default();
        h.write(&[seed]);
        h.write(identity.as_bytes());
        h.write(&[0]);
        h.write(role.as_bytes());
        h.finish()
    };
    (u128::from(half(1)) << 64) | u128::from(half(2))
}

/// The UID of the program that wrote the files (the File Meta's Implementation Class UID):
/// one UUID for every run.
pub(super) fn implementation() -> String {
    Uids::new(DEFAULT_ROOT, "vortex-tiler").of("implementation")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn valid(uid: &str) -> bool {
        uid.len() <= 64
            && uid.split('.').all(|p| {
                !p.is_empty() && p.bytes().all(|b| b.is_ascii_digit()) && (p.len() == 1 || !p.starts_with('0'))
            })
    }

    #[test]
    fn uids_are_stable_distinct_and_valid() {
        let a = Uids::new(DEFAULT_ROOT, "input-1 options");
        assert_eq!(a.of("series"), a.of("series"), "the same conversion, the same UID");
        assert_ne!(a.of("series"), a.of("study"));
        assert_ne!(a.of("series"), Uids::new(DEFAULT_ROOT, "input-2 options").of("series"));
        for root in [DEFAULT_ROOT, "1.2.826.0.1.3680043.10.1234", "1.2.3.4.5.6.7.8.9.10.11.12.13.14.15.16.1"] {
            check_root(root).unwrap();
            let uids = Uids::new(root, "x");
            for role in ["study", "series", "instance 0", "instance 31"] {
                let uid = uids.of(role);
                assert!(valid(&uid) && uid.starts_with(&format!("{root}.")), "{uid}");
            }
        }
        let uuid = a.of("series");
        let n: u128 = uuid.trim_start_matches("2.25.").parse().unwrap();
        assert_eq!((n >> 76) & 0xF, 8, "UUID version 8");
        assert_eq!((n >> 62) & 0b11, 0b10, "RFC 9562 variant");
        assert!(valid(&implementation()));
    }

    #[test]
    fn roots_are_checked() {
        for (root, why) in [
            ("", "1 to 40"),
            ("1.2.", "numbers joined by dots"),
            ("1.02.3", "leading zero"),
            ("1.2.a", "numbers joined by dots"),
            ("1.2.3.4.5.6.7.8.9.10.11.12.13.14.15.16.17.18", "1 to 40"),
        ] {
            let e = check_root(root).unwrap_err().to_string();
            assert!(e.contains(why), "{root}: {e}");
        }
    }
}
