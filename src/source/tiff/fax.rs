//! CCITT fax strips and tiles (TIFF compressions 3 and 4, as scanned documents are stored),
//! decoded by the `fax` crate (pdf-rs) into 1-bit rows. Its decoders give each line as the
//! positions where the colour changes, starting with white; white is a 0 bit and black a 1
//! bit, as libtiff delivers them (the photometric interpretation then says which is dark).
//!
//! Group 3 one-dimensional (T.4 modified Huffman lines, each after an EOL, as libtiff's
//! `tiffcp -c g3` writes them) and Group 4 go through the crate's decoders. Two-dimensional
//! Group 3 (T4Options bit 0: after each EOL a tag bit says whether the line is coded alone or
//! against the line above, in T.6's modes) and Compression 2 (modified Huffman lines without
//! EOLs, each starting on a byte) are decoded by [`decode_lines`] here, from the crate's code
//! tables. The decoders take widths up to 65535.

use fax::decoder::{DecodeStatus, Group3Decoder, Group4Decoder};
use fax::maps::{Mode, black, mode, white};
use fax::{BitReader, ByteReader};

/// Decodes `raw` into `out`: whole 1-bit rows of `width` texels, as many as `out` holds.
pub(super) fn decode(raw: &[u8], group4: bool, width: u32, out: &mut [u8]) -> Result<(), String> {
    let Ok(width) = u16::try_from(width) else {
        return Err(format!("a fax line {width} texels wide is beyond the decoder's 65535"));
    };
    let row_bytes = (width as usize).div_ceil(8);
    let rows = out.len() / row_bytes;
    let short = |done: usize| format!("the fax data ends after {done} of {rows} rows");
    // The decoders look up to 16 bits ahead and fail on a last code with fewer bits after it;
    // libtiff ends a strip without an end marker, so one is added: an EOL after Group 3 (a
    // line is decoded up to the EOL that follows it), EOFB after Group 4.
    let end: &[u8] = if group4 { &[0x00, 0x10, 0x01] } else { &[0x00, 0x01] };
    let bytes = raw.iter().chain(end).map(|&b| Ok::<u8, std::convert::Infallible>(b));
    if group4 {
        let mut decoder = Group4Decoder::new(bytes, width).map_err(|_| short(0))?;
        for (done, line) in out.chunks_exact_mut(row_bytes).enumerate() {
            match decoder.advance() {
                Ok(DecodeStatus::Incomplete) => fill(decoder.transition(), width, line),
                Ok(DecodeStatus::End) => return Err(short(done)),
                Err(e) => return Err(format!("corrupt Group 4 fax data in row {done}: {e:?}")),
            }
        }
    } else {
        let mut decoder =
            Group3Decoder::new(bytes).map_err(|_| "no EOL code opens the Group 3 fax data".to_string())?;
        for (done, line) in out.chunks_exact_mut(row_bytes).enumerate() {
            match decoder.advance() {
                Ok(_) if decoder.transitions().last() == Some(&width) => fill(decoder.transitions(), width, line),
                Ok(_) if decoder.transitions().is_empty() => return Err(short(done)),
                Ok(_) => return Err(format!("Group 3 fax row {done} does not cover its {width} texels")),
                Err(e) => return Err(format!("corrupt Group 3 fax data in row {done}: {e:?}")),
            }
        }
    }
    Ok(())
}

/// The fax codes [`decode_lines`] reads.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(super) enum Lines {
    /// Compression 2: modified Huffman lines, no EOL, each starting on a byte.
    ModifiedHuffman,
    /// Compression 3 with T4Options bit 0: after each EOL, a tag bit (1: a one-dimensional line,
    /// 0: two-dimensional, against the line above).
    TwoDimensional,
}

/// Decodes `raw` into `out` (whole 1-bit rows of `width` texels) line by line.
pub(super) fn decode_lines(raw: &[u8], lines: Lines, width: u32, out: &mut [u8]) -> Result<(), String> {
    let Ok(width) = u16::try_from(width) else {
        return Err(format!("a fax line {width} texels wide is beyond the decoder's 65535"));
    };
    let row_bytes = (width as usize).div_ceil(8);
    let rows = out.len() / row_bytes;
    // Codes are looked up a fixed number of bits ahead: zeros after the data let the last one
    // be read (and read as no code, never as data, should the data end early).
    let bytes = raw.iter().chain(&[0u8; 4]).map(|&b| Ok::<u8, std::convert::Infallible>(b));
    let Ok(mut reader) = ByteReader::new(bytes);
    let (mut above, mut line) = (Vec::new(), Vec::new());
    for (row, texels) in out.chunks_exact_mut(row_bytes).enumerate() {
        let bad = |what: &str| format!("{what} in fax row {row} of {rows}: corrupt or cut-short data");
        let two_d = match lines {
            Lines::ModifiedHuffman => {
                let pad = reader.bits_to_byte_boundary();
                if row > 0 && pad > 0 {
                    let Ok(()) = reader.consume(pad);
                }
                false
            }
            Lines::TwoDimensional => {
                // An EOL: at least 11 zero bits (more where lines are byte-aligned), then a 1.
                let mut zeros = 0;
                while reader.peek(1) == Some(0) && zeros < 64 {
                    let Ok(()) = reader.consume(1);
                    zeros += 1;
                }
                if zeros < 11 || reader.peek(2).is_none() {
                    return Err(bad("no EOL"));
                }
                let Ok(()) = reader.consume(1);
                let tag = reader.peek(1);
                let Ok(()) = reader.consume(1);
                tag == Some(0)
            }
        };
        line.clear();
        let coded = match two_d {
            false => one_dimensional(&mut reader, width, &mut line),
            true if row == 0 => None,
            true => two_dimensional(&mut reader, width, &above, &mut line),
        };
        coded.ok_or_else(|| bad(if two_d { "a bad two-dimensional line" } else { "a bad run length" }))?;
        fill(&line, width, texels);
        std::mem::swap(&mut above, &mut line);
    }
    Ok(())
}

/// One run of white or black: make-up codes (64 and over) summed up to the terminating code.
fn run(reader: &mut impl BitReader, black: bool) -> Option<u16> {
    let mut sum = 0u16;
    loop {
        let n = if black { black::decode(reader)? } else { white::decode(reader)? };
        sum = sum.checked_add(n)?;
        if n < 64 {
            return Some(sum);
        }
    }
}

/// A line of runs, white first, until `width` is covered; its colour changes into `changes`.
fn one_dimensional(reader: &mut impl BitReader, width: u16, changes: &mut Vec<u16>) -> Option<()> {
    let (mut at, mut black) = (0u16, false);
    while at < width {
        at = at.checked_add(run(reader, black)?).filter(|&a| a <= width)?;
        changes.push(at);
        black = !black;
    }
    Some(())
}

/// A line coded against the line above (`above`: its colour changes, white first), in T.4's
/// two-dimensional modes (T.6's): a0 the position reached (-1 before the line), b1 the next
/// change above, after a0, to the colour opposite a0's, b2 the change after b1.
fn two_dimensional(reader: &mut impl BitReader, width: u16, above: &[u16], changes: &mut Vec<u16>) -> Option<()> {
    let width32 = width as i32;
    let (mut a0, mut black) = (-1i32, false);
    while a0 < width32 {
        // Changes to black are the even ones of `above`, to white the odd ones.
        let b1_at = (0..above.len()).find(|&i| above[i] as i32 > a0 && (i % 2 == 0) != black);
        let b1 = b1_at.map_or(width32, |i| (above[i] as i32).min(width32));
        let b2 = b1_at.and_then(|i| above.get(i + 1)).map_or(width32, |&b| (b as i32).min(width32));
        match mode::decode(reader)? {
            Mode::Pass => a0 = b2,
            Mode::Horizontal => {
                let a1 = a0.max(0) + run(reader, black)? as i32;
                let a2 = a1 + run(reader, !black)? as i32;
                if a2 > width32 {
                    return None;
                }
                changes.extend([a1 as u16, a2 as u16]);
                a0 = a2;
            }
            Mode::Vertical(delta) => {
                let a1 = b1 + delta as i32;
                if a1 < a0.max(0) || a1 > width32 {
                    return None;
                }
                changes.push(a1 as u16);
                (a0, black) = (a1, !black);
            }
            Mode::Extension | Mode::EOF => return None,
        }
    }
    Some(())
}

/// One row of 1-bit texels from its colour changes (white first): black runs set to 1.
fn fill(changes: &[u16], width: u16, row: &mut [u8]) {
    row.fill(0);
    let mut start = 0usize;
    let mut black = false;
    let ends = changes.iter().map(|&c| (c as usize).min(width as usize)).chain(std::iter::once(width as usize));
    for end in ends {
        if black {
            for x in start..end.max(start) {
                row[x / 8] |= 0x80 >> (x % 8);
            }
        }
        start = start.max(end);
        black = !black;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn runs_become_bits() {
        let mut row = [0u8; 2];
        fill(&[3, 9, 12], 13, &mut row);
        // white 0-2, black 3-8, white 9-11, black 12.
        assert_eq!(row, [0b0001_1111, 0b1000_1000]);
        fill(&[], 13, &mut row);
        assert_eq!(row, [0, 0]);
    }
}
