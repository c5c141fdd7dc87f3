//! Typed errors of the tiler library. Each variant carries where it happened (file, row, tile,
//! field) so the command line can print one line a user can act on.

use std::fmt;
use std::io;
use std::path::{Path, PathBuf};

/// A path as a message shows it: as it is when it prints plainly, else quoted with Rust's
/// escapes (`"a\u{1b}[31m.png"`, `"\xFF.tif"`), so that a control character or a terminal
/// escape in a file name never reaches the terminal as such, a newline in one cannot forge a
/// line of output, and a name that is not UTF-8 shows its bytes. Every message that names a
/// file, the library's and the command line's, shows it through this.
pub struct Shown<'a>(&'a Path);

/// [`Shown`] for paths: `path.shown()` where `path.display()` would print it raw.
pub trait ShowPath {
    fn shown(&self) -> Shown<'_>;
}

impl ShowPath for Path {
    fn shown(&self) -> Shown<'_> {
        Shown(self)
    }
}

impl fmt::Display for Shown<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.0.to_str() {
            Some(plain) if !plain.chars().any(char::is_control) => f.write_str(plain),
            _ => write!(f, "{:?}", self.0),
        }
    }
}

impl fmt::Debug for Shown<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Display::fmt(self, f)
    }
}

/// `text` with every control character but the newline written as its escape (`\u{1b}`,
/// `\t`): the last guard of what the command line prints, for a name that reached a message
/// without [`Shown`] (a library's message, an operating system's).
pub fn escape_controls(text: &str) -> std::borrow::Cow<'_, str> {
    if !text.chars().any(|c| c.is_control() && c != '\n') {
        return std::borrow::Cow::Borrowed(text);
    }
    let mut out = String::with_capacity(text.len() + 8);
    for c in text.chars() {
        match c {
            '\n' => out.push(c),
            c if c.is_control() => out.extend(c.escape_debug()),
            c => out.push(c),
        }
    }
    std::borrow::Cow::Owned(out)
}

/// New variants may come in any release: match the ones you act on and keep a `_` arm.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum TilerError {
    /// The file could not be opened or read at all.
    #[error("{}: {source}", path.shown())]
    Io {
        path: PathBuf,
        #[source]
        source: io::Error,
    },

    /// The file is readable but not a valid image of its kind.
    #[error("{}: {message}", path.shown())]
    Decode { path: PathBuf, message: String },

    /// Decoding failed part-way through the image.
    #[error("{}: row {row}: {message}", path.shown())]
    DecodeRow { path: PathBuf, row: u64, message: String },

    /// A valid image this tool cannot handle as asked (format feature, size over a limit).
    #[error("{}: {message}", path.shown())]
    Unsupported { path: PathBuf, message: String },

    /// The image size or tile options make no usable virtual texture.
    #[error("{0}")]
    Geometry(String),

    /// Options that contradict each other or the input.
    #[error("{0}")]
    Options(String),

    /// A member of an `info.json` is missing, malformed or contradicts the command line.
    #[error("{}: {field}: {message}", path.shown())]
    Info { path: PathBuf, field: String, message: String },

    /// Encoding a tile failed.
    #[error("tile (lod {lod}, x {x}, y {y}): {message}")]
    Encode { lod: u32, x: u32, y: u32, message: String },

    /// Reading or writing a pack failed.
    #[error(transparent)]
    Pack(#[from] vortex_pack::PackError),

    /// What the input or the options ask for is over a cap of [`crate::limits::Limits`].
    #[error("{0}")]
    Limit(String),

    /// A shard of a sharded split that does not belong with the others, or is damaged.
    #[error("{}: {message}", path.shown())]
    Shard { path: PathBuf, message: String },

    /// The destination may not be written (see [`crate::output`]).
    #[error(transparent)]
    Output(#[from] OutputError),

    /// The caller asked the run to stop (Ctrl-C).
    #[error("interrupted; nothing was left at the destination")]
    Interrupted,

    /// A thread of the run panicked: a bug, not bad input. The run stopped and left nothing at
    /// the destination.
    #[error("internal error: {0}")]
    Internal(String),

    /// Writing output failed (unwritable directory, full disk, ...).
    #[error("{}: {source}", path.shown())]
    Write {
        path: PathBuf,
        #[source]
        source: io::Error,
    },
}

impl TilerError {
    pub fn io(path: impl Into<PathBuf>, source: io::Error) -> Self {
        TilerError::Io { path: path.into(), source }
    }

    pub fn decode(path: impl Into<PathBuf>, message: impl ToString) -> Self {
        TilerError::Decode { path: path.into(), message: message.to_string() }
    }

    pub(crate) fn unsupported(path: impl Into<PathBuf>, message: impl ToString) -> Self {
        TilerError::Unsupported { path: path.into(), message: message.to_string() }
    }

    /// A thread that panicked (`what`: which one), or a lock it left poisoned.
    pub(crate) fn panicked(what: &str) -> Self {
        TilerError::Internal(format!("{what} panicked"))
    }

    pub fn write(path: impl Into<PathBuf>, source: io::Error) -> Self {
        TilerError::Write { path: path.into(), source }
    }
}

pub type Result<T, E = TilerError> = std::result::Result<T, E>;

/// Why a destination was refused.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum OutputError {
    #[error("{}: is {what}; nothing replaces one: choose a regular path", path.shown())]
    Special { path: PathBuf, what: &'static str },

    #[error("{}: is a symbolic link (to {}); give the real path, or remove the link first", path.shown(), target.shown())]
    Symlink { path: PathBuf, target: PathBuf },

    #[error("{}: is {found} where {product} goes; choose another path", path.shown())]
    WrongType { path: PathBuf, found: &'static str, product: &'static str },

    #[error("{}: {what}, not {product} written by vortex-tiler; {advice}", path.shown())]
    Foreign { path: PathBuf, what: String, product: &'static str, advice: &'static str },

    #[error("{}: is the input {}; write the output somewhere else", path.shown(), input.shown())]
    IsInput { path: PathBuf, input: PathBuf },

    #[error("{}: lies inside the input {}; write the output somewhere else", path.shown(), input.shown())]
    InsideInput { path: PathBuf, input: PathBuf },

    #[error("{}: holds the input {}, which replacing it would delete; write the output somewhere else", path.shown(), input.shown())]
    ContainsInput { path: PathBuf, input: PathBuf },

    #[error("{}: {source}", path.shown())]
    Io {
        path: PathBuf,
        #[source]
        source: io::Error,
    },
}
