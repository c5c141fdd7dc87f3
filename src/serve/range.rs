//! `Range: bytes=...` for the pack file: one range per request (as PMTiles clients send), so a
//! client can read a pack's header, index and tiles over HTTP.
//!
//! `a-b`, `a-` and `-n` are served as 206. A range that starts past the end (or `-0`) is 416
//! with `Content-Range: bytes */LEN`; several ranges (`a-b,c-d`) are refused with 416 too
//! rather than sent as multipart; a malformed byte range is 400. A range in another unit than
//! bytes is ignored, as RFC 9110 (14.2) asks: the whole file, 200.

/// Why a `Range` header is not served.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum RangeError {
    /// `bytes=` not followed by one well-formed range (400).
    Malformed,
    /// Well formed, but no byte of it is in the file (416).
    Unsatisfiable,
    /// More than one range (416: multipart answers are not made).
    Multiple,
}

/// The first and last byte (inclusive) that `header` asks for in a file of `len` bytes;
/// `None` for a range in another unit (to be ignored).
pub fn parse(header: &str, len: u64) -> Result<Option<(u64, u64)>, RangeError> {
    let Some((unit, spec)) = header.trim().split_once('=') else {
        return Err(RangeError::Malformed);
    };
    // Range units are case-insensitive (RFC 9110, 14.1).
    if !unit.trim().eq_ignore_ascii_case("bytes") {
        return Ok(None);
    }
    byte_range(spec.trim(), len).map(Some)
}

fn byte_range(spec: &str, len: u64) -> Result<(u64, u64), RangeError> {
    if spec.contains(',') {
        return Err(RangeError::Multiple);
    }
    let (first, last) = spec.split_once('-').ok_or(RangeError::Malformed)?;
    let number = |s: &str| -> Result<u64, RangeError> {
        let s = s.trim();
        if s.is_empty() || !s.bytes().all(|b| b.is_ascii_digit()) {
            return Err(RangeError::Malformed);
        }
        // More digits than a u64 holds is still a well-formed (huge) position.
        Ok(s.parse().unwrap_or(u64::MAX))
    };
    match (first.trim().is_empty(), last.trim().is_empty()) {
        (true, true) => Err(RangeError::Malformed),
        (true, false) => {
            let n = number(last)?;
            if n == 0 || len == 0 {
                return Err(RangeError::Unsatisfiable);
            }
            Ok((len - n.min(len), len - 1))
        }
        (false, open) => {
            let a = number(first)?;
            let b = if open { u64::MAX } else { number(last)? };
            if b < a {
                return Err(RangeError::Malformed);
            }
            if a >= len {
                return Err(RangeError::Unsatisfiable);
            }
            Ok((a, b.min(len - 1)))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_three_forms() {
        assert_eq!(parse("bytes=0-99", 1000), Ok(Some((0, 99))));
        assert_eq!(parse("bytes=900-2000", 1000), Ok(Some((900, 999))));
        assert_eq!(parse("bytes=10-", 1000), Ok(Some((10, 999))));
        assert_eq!(parse("bytes=-100", 1000), Ok(Some((900, 999))));
        assert_eq!(parse("bytes=-5000", 1000), Ok(Some((0, 999))));
        assert_eq!(parse("bytes=0-99999999999999999999999", 1000), Ok(Some((0, 999))));
        assert_eq!(parse("Bytes=0-1", 1000), Ok(Some((0, 1))));
    }

    #[test]
    fn other_units_are_ignored() {
        assert_eq!(parse("items=0-1", 1000), Ok(None));
        assert_eq!(parse("lines=whatever", 1000), Ok(None));
    }

    #[test]
    fn refusals() {
        assert_eq!(parse("bytes=1000-", 1000), Err(RangeError::Unsatisfiable));
        assert_eq!(parse("bytes=-0", 1000), Err(RangeError::Unsatisfiable));
        assert_eq!(parse("bytes=0-1,5-6", 1000), Err(RangeError::Multiple));
        for bad in ["bytes=", "bytes=-", "bytes=5-1", "bytes=a-b", "0-1", "bytes=1", "bytes=+1-2", "bytes=0x1-2"] {
            assert_eq!(parse(bad, 1000), Err(RangeError::Malformed), "{bad}");
        }
    }
}
