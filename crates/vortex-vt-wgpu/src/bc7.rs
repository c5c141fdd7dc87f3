//! BC7 blocks the runtime makes itself: a block of one colour, exactly. A BC7 cache is filled
//! with the packs' BC7 payloads as they are; only one-colour tiles (stored as their colour, with
//! no payload) and the loader's stand-in need blocks made here. Any thread.
//!
//! The block is mode 5 (one subset, rotation 0): colour endpoints of 7 bits per channel, alpha
//! endpoints of 8 bits, 2-bit indices. Alpha takes both endpoints equal to the value (index 0).
//! A colour channel takes the endpoint pair whose weight-21 blend (index 1 in every texel) is the
//! value: `((64 - 21) * e0 + 21 * e1 + 32) >> 6`, with each 7-bit endpoint widened to 8 bits by
//! repeating its top bit. Every 8-bit value has such a pair (checked by a test).

use std::sync::OnceLock;

/// Bytes of one 4x4 block.
pub const BLOCK_BYTES: usize = 16;

/// For each 8-bit value, 7-bit endpoints whose index-1 blend gives it exactly.
fn endpoints() -> &'static [(u8, u8); 256] {
    static TABLE: OnceLock<[(u8, u8); 256]> = OnceLock::new();
    TABLE.get_or_init(|| {
        let widen = |e: u32| (e << 1) | (e >> 6);
        let mut table = [None; 256];
        for e0 in 0..128u32 {
            for e1 in 0..128u32 {
                let v = ((64 - 21) * widen(e0) + 21 * widen(e1) + 32) >> 6;
                table[v as usize].get_or_insert((e0 as u8, e1 as u8));
            }
        }
        #[expect(clippy::expect_used, reason = "a fixed table, checked for all 256 values by the test")]
        table.map(|e| e.expect("every 8-bit value is a mode-5 blend (see the test)"))
    })
}

/// The block whose 16 texels are all `rgba`.
pub fn solid_block(rgba: [u8; 4]) -> [u8; BLOCK_BYTES] {
    let table = endpoints();
    let mut bits = Bits::default();
    bits.push(1 << 5, 6); // mode 5: five 0 bits, then a 1
    bits.push(0, 2); // rotation
    for c in 0..3 {
        let (e0, e1) = table[rgba[c] as usize];
        bits.push(e0 as u128, 7);
        bits.push(e1 as u128, 7);
    }
    bits.push(rgba[3] as u128, 8);
    bits.push(rgba[3] as u128, 8);
    // Colour indices: 1 everywhere (the anchor's has one bit), then alpha indices: 0.
    bits.push(1, 1);
    for _ in 1..16 {
        bits.push(1, 2);
    }
    bits.push(0, 31);
    debug_assert_eq!(bits.len, 128);
    bits.value.to_le_bytes()
}

/// BC7 blocks of a `tile_size²` RGBA8 tile (rows of blocks, top down), each 4x4 block of one
/// colour: that of its top-left texel. Exact for tiles whose blocks are one colour each.
pub fn solid_blocks(texels: &[u8], tile_size: u32) -> Vec<u8> {
    let side = tile_size as usize;
    let mut out = Vec::with_capacity((side / 4).pow(2) * BLOCK_BYTES);
    for by in (0..side).step_by(4) {
        for bx in (0..side).step_by(4) {
            let i = (by * side + bx) * 4;
            out.extend_from_slice(&solid_block([texels[i], texels[i + 1], texels[i + 2], texels[i + 3]]));
        }
    }
    out
}

/// A little-endian bit writer for one block.
#[derive(Default)]
struct Bits {
    value: u128,
    len: u32,
}

impl Bits {
    fn push(&mut self, v: u128, bits: u32) {
        self.value |= v << self.len;
        self.len += bits;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_value_has_endpoints_and_the_mode_bits_come_first() {
        let t = endpoints();
        assert_eq!(t.len(), 256);
        let b = solid_block([0, 128, 255, 77]);
        assert_eq!(b[0] & 0x3f, 0x20, "mode 5");
        assert_eq!(solid_block([9, 9, 9, 9]), solid_block([9, 9, 9, 9]));
    }
}
