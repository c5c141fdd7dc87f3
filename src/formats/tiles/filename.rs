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

/// Why a file-name pattern was refused: the pattern and what is wrong with it.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("'{pattern}': {why}")]
pub struct PatternError {
    /// The pattern as given.
    pub pattern: String,
    /// What is wrong with it.
    pub why: Refused,
}

/// What is wrong with a file-name pattern ([`PatternError`]); each message names the pattern
/// or its conversion.
///
/// New variants may come in any release: match the ones you act on and keep a `_` arm.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum Refused {
    /// A `%` starts no conversion this syntax has.
    #[error("bad conversion at byte {at} (expected e.g. %1$04s or %d)")]
    Conversion {
        /// Where the `%` is, in bytes from the pattern's start.
        at: usize,
    },
    /// The `N` of `%N$` is no number.
    #[error("bad argument number in '{conversion}'")]
    ArgumentNumber {
        /// The conversion, as written.
        conversion: String,
    },
    /// The `N` of `%N$` names no argument.
    #[error("'{conversion}' refers to argument {n}, but there are {count}")]
    NoSuchArgument {
        /// The conversion, as written.
        conversion: String,
        /// The argument it names.
        n: usize,
        /// How many there are.
        count: usize,
    },
    /// More conversions without `N$` than there are arguments.
    #[error("has more than {count} conversions")]
    TooManyConversions {
        /// How many arguments there are.
        count: usize,
    },
    /// A second `$` in a conversion.
    #[error("bad conversion '{conversion}'")]
    Flags {
        /// The conversion, as written.
        conversion: String,
    },
    /// The width is no number.
    #[error("bad width in '{conversion}'")]
    Width {
        /// The conversion, as written.
        conversion: String,
    },
    /// A width past what a file name part holds.
    #[error("width {width} in '{conversion}' is more than {}: a file name part holds at most 255 bytes", MAX_WIDTH)]
    TooWide {
        /// The conversion, as written.
        conversion: String,
        /// Its width.
        width: usize,
    },
    /// An argument no conversion uses: two tiles would get one name.
    #[error("never uses argument {n}: tiles would share file names")]
    Unused {
        /// The argument, counted from 1.
        n: usize,
    },
    /// An absolute path, or one with `..`.
    #[error("must stay inside the output directory")]
    Outside,
}

/// A parsed pattern.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FilenameFormat {
    source: String,
    pieces: Vec<Piece>,
}

impl FilenameFormat {
    /// Parses `pattern` whose conversions may refer to `arg_count` arguments; every argument
    /// must be used so that no two tiles share a name.
    pub fn parse(pattern: &str, arg_count: usize) -> Result<FilenameFormat, PatternError> {
        let refused = |why: Refused| PatternError { pattern: pattern.to_string(), why };
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
                    _ => return Err(refused(Refused::Conversion { at })),
                }
            };
            if conversion == '%' {
                literal.push('%');
                continue;
            }
            let (index, flags) = match spec.split_once('$') {
                Some((n, rest)) => {
                    let conversion = format!("%{spec}{conversion}");
                    let Ok(n) = n.parse::<usize>() else {
                        return Err(refused(Refused::ArgumentNumber { conversion }));
                    };
                    if n == 0 || n > arg_count {
                        return Err(refused(Refused::NoSuchArgument { conversion, n, count: arg_count }));
                    }
                    (n - 1, rest)
                }
                None => {
                    next_arg += 1;
                    if next_arg > arg_count {
                        return Err(refused(Refused::TooManyConversions { count: arg_count }));
                    }
                    (next_arg - 1, spec.as_str())
                }
            };
            let whole = || format!("%{spec}{conversion}");
            if flags.contains('$') {
                return Err(refused(Refused::Flags { conversion: whole() }));
            }
            let zero = flags.starts_with('0');
            let width: usize = match flags.is_empty() {
                true => 0,
                false => flags.parse().map_err(|_| refused(Refused::Width { conversion: whole() }))?,
            };
            if width > MAX_WIDTH {
                return Err(refused(Refused::TooWide { conversion: whole(), width }));
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
                return Err(refused(Refused::Unused { n: i + 1 }));
            }
        }
        if pattern.starts_with('/') || pattern.split('/').any(|part| part == "..") {
            return Err(refused(Refused::Outside));
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
    fn refuses_bad_patterns_saying_why() {
        let conversion = |c: &str| c.to_string();
        for (bad, why) in [
            ("x%02s.png", Refused::Unused { n: 2 }),
            ("%4$s%2$s%3$s", Refused::NoSuchArgument { conversion: conversion("%4$s"), n: 4, count: 3 }),
            ("%q", Refused::Conversion { at: 0 }),
            ("%1$s-%2$s-%3$s-%s%s%s%s", Refused::TooManyConversions { count: 3 }),
            ("../%s%s%s", Refused::Outside),
            ("/abs/%s%s%s", Refused::Outside),
            ("%1$2$s%s%s", Refused::Flags { conversion: conversion("%1$2$s") }),
            ("%$s%s%s", Refused::ArgumentNumber { conversion: conversion("%$s") }),
            ("%1$99999999999999999999d%s%s", Refused::Width { conversion: conversion("%1$99999999999999999999d") }),
            ("%1$65536d-%2$d-%3$d.png", Refused::TooWide { conversion: conversion("%1$65536d"), width: 65536 }),
            ("%1$33d-%2$d-%3$d", Refused::TooWide { conversion: conversion("%1$33d"), width: 33 }),
        ] {
            let e = FilenameFormat::parse(bad, 3).unwrap_err();
            assert_eq!(e, PatternError { pattern: bad.into(), why }, "{bad}");
            assert!(e.to_string().starts_with(&format!("'{bad}': ")), "{e}");
        }
    }
}
