//! FNV-1a, 64 bits: a hash that is the same on every build and machine (unlike the standard
//! library's), for input fingerprints, catalog keys and ETags; not for security. The function
//! of a pack's content hash (docs/pack-format.md), which `vortex-pack` keeps to itself.

/// The offset basis: the hash of no bytes.
const OFFSET: u64 = 0xcbf2_9ce4_8422_2325;

/// `hash` (a hash so far) carried on over `bytes`.
fn fnv1a(hash: u64, bytes: &[u8]) -> u64 {
    bytes.iter().fold(hash, |h, b| (h ^ u64::from(*b)).wrapping_mul(0x0000_0100_0000_01B3))
}

/// The hash of `bytes` (the server's catalog keys and ETags).
#[cfg(any(feature = "serve", test))]
pub(crate) fn hash(bytes: &[u8]) -> u64 {
    fnv1a(OFFSET, bytes)
}

/// FNV-1a as a [`std::hash::Hasher`], for hashing a sequence of parts.
pub(crate) struct Fnv(u64);

impl Default for Fnv {
    fn default() -> Self {
        Fnv(OFFSET)
    }
}

impl std::hash::Hasher for Fnv {
    fn write(&mut self, bytes: &[u8]) {
        self.0 = fnv1a(self.0, bytes);
    }

    fn finish(&self) -> u64 {
        self.0
    }
}

#[cfg(test)]
mod tests {
    use std::hash::Hasher;

    /// The published FNV-1a 64 test vectors (IETF draft-eastlake-fnv), written here so that a
    /// change to the function cannot pass its own test.
    #[test]
    fn the_published_vectors() {
        assert_eq!(super::hash(b""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(super::hash(b"a"), 0xaf63_dc4c_8601_ec8c);
        assert_eq!(super::hash(b"foobar"), 0x8594_4171_f739_67e8);
        let mut parts = super::Fnv::default();
        parts.write(b"foo");
        parts.write(b"bar");
        assert_eq!(parts.finish(), super::hash(b"foobar"));
    }
}
