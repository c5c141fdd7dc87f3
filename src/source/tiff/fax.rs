//! CCITT fax strips and tiles (TIFF compressions 3 and 4, as scanned documents are stored),
//! decoded by the `fax` crate (pdf-rs) into 1-bit rows. Its decoders give each line as the
//! positions where the colour changes, starting with white; white is a 0 bit and black a 1
//! bit, as libtiff delivers them (the photometric interpretation then says which is dark).
//!
//! Group 3 here is the one-dimensional code (T.4 modified Huffman lines, each after an EOL,
//! as libtiff's `tiffcp -c g3` writes them); two-dimensional Group 3 is refused when the file
//! is opened ([`super::kinds`]). The decoders take widths up to 65535.

use fax::decoder::{DecodeStatus, Group3Decoder, Group4Decoder};

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
