//! The original tool's positional printf-like file name patterns, e.g.
//! `lod%1$02s-x%2$04s-y%3$04s.jpg` (argument 1 = LOD, 2 = x, 3 = y).
//!
//! A conversion is `%[N$][0][width](s|d|i|u)`; `%%` is a literal percent sign. Without `N$`,
//! conversions take the arguments in order. `/` in a pattern makes subdirectories.

use std::fmt::Write;

#[derive(Clone, Debug, PartialEq, Eq)]
enum Piece {
    Literal(String),
    Arg { index: usize, width: usize, zero: bool },
}

/// The widest a number may be padded: far more digits than a `u32` has, far fewer than the
/// 255 bytes of a file name part.
const MAX_WIDTH: usize = 32;

/// The thesis's default names, with the codec's extension.
pub const DEFAULT_FILENAME_STEM: &str = "lod%1$02s-x%2$04s-y%3$04s";

/// A parsed pattern.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FilenameFormat {
    source: String,
    pieces: Vec<Piece>,
}

impl FilenameFormat {
    /// Parses `pattern` whose conversions may refer to `arg_count` arguments; every argument
    /// must be used so that no two tiles share a name.
    pub fn parse(pattern: &str, arg_count: usize) -> Result<FilenameFormat, String> {
        let mut pieces = Vec::new();
        let mut literal = String::new();
        let mut next_arg = 0;
        let mut chars = pattern.char_indices().peekable();
        while let Some((at, c)) = chars.next() {
            if c != '%' {
                literal.push(c);
                continue;
            }
            let mut spec = String::new();
            let conversion = loop {
                match chars.next() {
                    Some((_, '%')) if spec.is_empty() => break '%',
                    Some((_, c @ ('s' | 'd' | 'i' | 'u'))) => break c,
                    Some((_, c)) if c.is_ascii_digit() || c == '$' => spec.push(c),
                    _ => {
                        return Err(format!("bad conversion at byte {at} of '{pattern}' (expected e.g. %1$04s or %d)"));
                    }
                }
            };
            if conversion == '%' {
                literal.push('%');
                continue;
            }
            let (index, flags) = match spec.split_once('$') {
                Some((n, rest)) => {
                    let n: usize = n
                        .parse()
                        .map_err(|_| format!("bad argument number in '%{spec}{conversion}' of '{pattern}'"))?;
                    if n == 0 || n > arg_count {
                        return Err(format!(
                            "'%{spec}{conversion}' in '{pattern}' refers to argument {n}, but there are {arg_count}"
                        ));
                    }
                    (n - 1, rest)
                }
                None => {
                    next_arg += 1;
                    if next_arg > arg_count {
                        return Err(format!("'{pattern}' has more than {arg_count} conversions"));
                    }
                    (next_arg - 1, spec.as_str())
                }
            };
            if flags.contains('$') {
                return Err(format!("bad conversion '%{spec}{conversion}' in '{pattern}'"));
            }
            let zero = flags.starts_with('0');
            let width: usize = if flags.is_empty() {
                0
            } else {
                flags.parse().map_err(|_| format!("bad width in '%{spec}{conversion}'"))?
            };
            if width > MAX_WIDTH {
                return Err(format!(
                    "width {width} in '%{spec}{conversion}' is more than {MAX_WIDTH}: a file name part holds at most 255 bytes"
                ));
            }
            if !literal.is_empty() {
                pieces.push(Piece::Literal(std::mem::take(&mut literal)));
            }
            pieces.push(Piece::Arg { index, width, zero });
        }
        if !literal.is_empty() {
            pieces.push(Piece::Literal(literal));
        }
        for i in 0..arg_count {
            if !pieces.iter().any(|p| matches!(p, Piece::Arg { index, .. } if *index == i)) {
                return Err(format!("'{pattern}' never uses argument {}: tiles would share file names", i + 1));
            }
        }
        if pattern.starts_with('/') || pattern.split('/').any(|part| part == "..") {
            return Err(format!("'{pattern}' must stay inside the output directory"));
        }
        Ok(FilenameFormat { source: pattern.to_string(), pieces })
    }

    /// The pattern as it was parsed, as `info.json`'s `filenameFormat` writes it.
    pub fn as_str(&self) -> &str {
        &self.source
    }

    /// The file name for `args`.
    pub fn format(&self, args: &[u32]) -> String {
        let mut out = String::new();
        for p in &self.pieces {
            match p {
                Piece::Literal(s) => out.push_str(s),
                // Writing to a String cannot fail.
                Piece::Arg { index, width, zero: true } => drop(write!(out, "{:0width$}", args[*index])),
                Piece::Arg { index, width, zero: false } => drop(write!(out, "{:width$}", args[*index])),
            }
        }
        out
    }

    /// The arguments that would give `name`, or `None` if it does not match the pattern (or
    /// gives one argument two values).
    pub(crate) fn match_name(&self, name: &str) -> Option<Vec<u32>> {
        let mut args: Vec<Option<u32>> = vec![None; self.arg_count()];
        let mut rest = name;
        for p in &self.pieces {
            match p {
                Piece::Literal(l) => rest = rest.strip_prefix(l.as_str())?,
                Piece::Arg { index, .. } => {
                    let trimmed = rest.trim_start_matches(' ');
                    let digits = trimmed.bytes().take_while(u8::is_ascii_digit).count();
                    if digits == 0 {
                        return None;
                    }
                    let value: u32 = trimmed[..digits].parse().ok()?;
                    if args[*index].is_some_and(|v| v != value) {
                        return None;
                    }
                    args[*index] = Some(value);
                    rest = &trimmed[digits..];
                }
            }
        }
        if !rest.is_empty() {
            return None;
        }
        args.into_iter().collect()
    }

    fn arg_count(&self) -> usize {
        self.pieces
            .iter()
            .filter_map(|p| if let Piece::Arg { index, .. } = p { Some(index + 1) } else { None })
            .max()
            .unwrap_or(0)
    }

    /// The file extension (after the last '.'), lower-cased.
    pub fn extension(&self) -> Option<String> {
        match self.pieces.last() {
            Some(Piece::Literal(s)) => s.rsplit_once('.').map(|(_, e)| e.to_ascii_lowercase()),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn original_default() {
        let f = FilenameFormat::parse("lod%1$02s-x%2$04s-y%3$04s.jpg", 3).unwrap();
        assert_eq!(f.format(&[3, 12, 7]), "lod03-x0012-y0007.jpg");
        assert_eq!(f.extension().as_deref(), Some("jpg"));
    }

    #[test]
    fn sequential_and_reordered() {
        let f = FilenameFormat::parse("x%02s-y%02s.png", 2).unwrap();
        assert_eq!(f.format(&[5, 123]), "x05-y123.png");
        let f = FilenameFormat::parse("%1$d/%3$d/%2$d.jpg", 3).unwrap();
        assert_eq!(f.format(&[4, 10, 20]), "4/20/10.jpg");
        let f = FilenameFormat::parse("100%%-%s-%s-%s", 3).unwrap();
        assert_eq!(f.format(&[1, 2, 3]), "100%-1-2-3");
    }

    #[test]
    fn names_match_back() {
        let f = FilenameFormat::parse("x%02s-y%02s.png", 2).unwrap();
        assert_eq!(f.match_name("x05-y123.png"), Some(vec![5, 123]));
        assert_eq!(f.match_name("x5-y1.png"), Some(vec![5, 1]));
        assert_eq!(f.match_name("x05-y12.jpg"), None);
        assert_eq!(f.match_name("y05-x12.png"), None);
        let f = FilenameFormat::parse("%1$d/%3$d/%2$d.jpg", 3).unwrap();
        assert_eq!(f.match_name(&f.format(&[4, 10, 20])), Some(vec![4, 10, 20]));
    }

    #[test]
    fn refuses_bad_patterns() {
        for bad in
            ["x%02s.png", "%4$s%2$s%3$s", "%q", "%1$s-%2$s-%3$s-%s%s%s%s", "../%s%s%s", "/abs/%s%s%s", "%1$2$s%s%s"]
        {
            assert!(FilenameFormat::parse(bad, 3).is_err(), "{bad} was accepted");
        }
        for wide in ["%1$65536d-%2$d-%3$d.png", "%1$33d-%2$d-%3$d"] {
            assert!(FilenameFormat::parse(wide, 3).unwrap_err().contains("width"), "{wide}");
        }
    }
}
