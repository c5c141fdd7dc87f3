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
    /// The path, ready for `{}` in a message: plain, or quoted and escaped.
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

/// Why a run, a read or a write failed; each variant names where (file, row, tile, field).
///
/// New variants may come in any release: match the ones you act on and keep a `_` arm.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum TilerError {
    /// The file could not be opened or read at all.
    #[error("{}: {source}", path.shown())]
    Io {
        /// The file that could not be read.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: io::Error,
    },

    /// The file is readable but not a valid image of its kind.
    #[error("{}: {message}", path.shown())]
    Decode {
        /// The file (or tile file) that did not decode.
        path: PathBuf,
        /// What was wrong with it, as the decoder said.
        message: String,
    },

    /// Decoding failed part-way through the image.
    #[error("{}: row {row}: {message}", path.shown())]
    DecodeRow {
        /// The image being read.
        path: PathBuf,
        /// The first row of the full-resolution image (0 at the top) that could not be read.
        row: u64,
        /// What the decoder said.
        message: String,
    },

    /// A valid image this tool cannot handle as asked (format feature, size over a limit).
    #[error("{}: {message}", path.shown())]
    Unsupported {
        /// The image.
        path: PathBuf,
        /// Which feature or size it is, and what to do instead where there is something.
        message: String,
    },

    /// The image size or tile options make no usable virtual texture (the message says which).
    #[error("{0}")]
    Geometry(String),

    /// Options that contradict each other or the input; the message names the flags.
    #[error("{0}")]
    Options(String),

    /// A member of an `info.json` is missing, malformed or contradicts the command line.
    #[error("{}: {field}: {message}", path.shown())]
    Info {
        /// The `info.json` read.
        path: PathBuf,
        /// The member's name as the file spells it (`tileSize`, `codec`, ...).
        field: String,
        /// What is wrong with it.
        message: String,
    },

    /// Encoding a tile failed.
    #[error("tile (lod {lod}, x {x}, y {y}): {message}")]
    Encode {
        /// The tile's level of detail, 0 the full resolution.
        lod: u32,
        /// The tile's column in its level's page grid, from 0 at the left.
        x: u32,
        /// The tile's row in its level's page grid, from 0 at the top.
        y: u32,
        /// What the encoder said.
        message: String,
    },

    /// Reading or writing a pack failed.
    #[error(transparent)]
    Pack(#[from] vortex_pack::PackError),

    /// What the input or the options ask for is over a cap of [`crate::limits::Limits`].
    #[error("{0}")]
    Limit(String),

    /// A shard of a sharded split that does not belong with the others, or is damaged.
    #[error("{}: {message}", path.shown())]
    Shard {
        /// The shard's pack.
        path: PathBuf,
        /// What does not match or is damaged.
        message: String,
    },

    /// The destination may not be written (see [`crate::output`]).
    #[error(transparent)]
    Output(#[from] OutputError),

    /// An object-storage destination (`s3://`) could not be used or written.
    #[error(transparent)]
    Store(#[from] StoreError),

    /// A run could not be resumed (`--resume`, see [`crate::resume`]).
    #[error(transparent)]
    Resume(#[from] ResumeError),

    /// The caller asked the run to stop (Ctrl-C).
    #[error("interrupted; nothing was left at the destination")]
    Interrupted,

    /// A bug, not bad input: a thread of the run panicked, or a check of the run's own work
    /// failed (a tile written twice, tiles missing from an output). The run stopped and left
    /// nothing at the destination.
    #[error("internal error: {0}")]
    Internal(String),

    /// Writing output failed (unwritable directory, full disk, ...).
    #[error("{}: {source}", path.shown())]
    Write {
        /// The file or directory being written (often its temporary name).
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: io::Error,
    },
}

impl TilerError {
    /// [`TilerError::Io`]: `path` could not be opened or read.
    pub(crate) fn io(path: impl Into<PathBuf>, source: io::Error) -> Self {
        TilerError::Io { path: path.into(), source }
    }

    /// [`TilerError::Decode`]: `path` is not a valid image of its kind.
    pub(crate) fn decode(path: impl Into<PathBuf>, message: impl ToString) -> Self {
        TilerError::Decode { path: path.into(), message: message.to_string() }
    }

    /// [`TilerError::Unsupported`]: `path` is valid but asks for what this tool does not do.
    pub(crate) fn unsupported(path: impl Into<PathBuf>, message: impl ToString) -> Self {
        TilerError::Unsupported { path: path.into(), message: message.to_string() }
    }

    /// A thread that panicked (`what`: which one), or a lock it left poisoned.
    pub(crate) fn panicked(what: &str) -> Self {
        TilerError::Internal(format!("{what} panicked"))
    }

    /// [`TilerError::Write`]: writing `path` failed with `source`.
    pub fn write(path: impl Into<PathBuf>, source: io::Error) -> Self {
        TilerError::Write { path: path.into(), source }
    }
}

/// The library's result: [`TilerError`] unless a function says otherwise.
pub type Result<T, E = TilerError> = std::result::Result<T, E>;

/// Why a destination was refused (see [`crate::output::claim`]). `path` is always the
/// destination as given; each message says what to do instead.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum OutputError {
    /// The destination is a special file (a device, a FIFO, a socket), which nothing replaces.
    #[error("{}: is {what}; nothing replaces one: choose a regular path", path.shown())]
    Special {
        /// The destination.
        path: PathBuf,
        /// Which kind of special file, as the message says it ("a FIFO").
        what: &'static str,
    },

    /// The destination is a symbolic link: the output is not written through it.
    #[error("{}: is a symbolic link (to {}); give the real path, or remove the link first", path.shown(), target.shown())]
    Symlink {
        /// The destination.
        path: PathBuf,
        /// Where the link points, as it reads.
        target: PathBuf,
    },

    /// A file where the output is a directory, or a directory where it is a file.
    #[error("{}: is {found} where {product} goes; choose another path", path.shown())]
    WrongType {
        /// The destination.
        path: PathBuf,
        /// What is there ("a file", "a directory").
        found: &'static str,
        /// What the run writes, as [`crate::output::Product`] names it.
        product: &'static str,
    },

    /// Something this tool did not write is at the destination; it is left alone.
    #[error("{}: {what}, not {product} written by vortex-tiler; {advice}", path.shown())]
    Foreign {
        /// The destination.
        path: PathBuf,
        /// What was found there.
        what: String,
        /// What the run writes.
        product: &'static str,
        /// What the user can do (another path; `--force` where it applies).
        advice: &'static str,
    },

    /// The destination is one of the run's inputs.
    #[error("{}: is the input {}; write the output somewhere else", path.shown(), input.shown())]
    IsInput {
        /// The destination.
        path: PathBuf,
        /// The input it is.
        input: PathBuf,
    },

    /// The destination lies inside an input directory.
    #[error("{}: lies inside the input {}; write the output somewhere else", path.shown(), input.shown())]
    InsideInput {
        /// The destination.
        path: PathBuf,
        /// The input directory holding it.
        input: PathBuf,
    },

    /// The destination is a directory holding an input, which replacing it would delete.
    #[error("{}: holds the input {}, which replacing it would delete; write the output somewhere else", path.shown(), input.shown())]
    ContainsInput {
        /// The destination.
        path: PathBuf,
        /// The input inside it.
        input: PathBuf,
    },

    /// The destination (or its parent) could not be examined.
    #[error("{}: {source}", path.shown())]
    Io {
        /// The path being examined.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: io::Error,
    },
}

/// Why an object-storage destination could not be used or written.
///
/// New variants may come in any release: match the ones you act on and keep a `_` arm.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum StoreError {
    /// The URL is not one this tool can write to.
    #[error("{url}: {why}")]
    Url {
        /// The URL as given (escaped).
        url: String,
        /// What is wrong with it.
        why: String,
    },
    /// This build has no object-storage client (the `s3` feature is off).
    #[error("{url}: this build cannot write to object storage (build vortex-tiler with the `s3` feature)")]
    NotBuilt {
        /// The URL given.
        url: String,
    },
    /// The format is not written to object storage yet.
    #[error("{url}: {product} cannot be written to object storage yet; write it to a local path and upload it")]
    Unsupported {
        /// The URL given.
        url: String,
        /// The product, as messages name it.
        product: &'static str,
    },
    /// The client could not be set up from the environment (`AWS_*` variables) and the
    /// shared files' profile.
    #[error("{url}: cannot set up the S3 client from the AWS environment and profile: {message}")]
    Client {
        /// The URL given.
        url: String,
        /// The client's reason.
        message: String,
    },
    /// A request failed after its retries: the object, what was asked, the server's reply.
    #[error("s3://{bucket}/{key}: {op} failed: {message}")]
    Request {
        /// The bucket.
        bucket: String,
        /// The object's key (or the prefix listed).
        key: String,
        /// What was asked: `PUT`, `GET`, `LIST`, `DELETE`, a multipart upload's step.
        op: &'static str,
        /// The client's error, the server's reply within it.
        message: String,
    },
    /// The prefix or object holds something that is not a previous output of ours.
    #[error("{url}: holds {what}, not {product} written by vortex-tiler; {advice}")]
    Foreign {
        /// The URL given.
        url: String,
        /// What is there (an object's key, an object without our signature).
        what: String,
        /// What would have been written.
        product: &'static str,
        /// How to proceed.
        advice: &'static str,
    },
    /// Another run is writing the prefix: its marker changed while this run watched it, or it
    /// was written between this run's look and its own write (docs/object-storage.md).
    #[error("{url}: {why}; wait for that run to end, or choose another prefix")]
    Busy {
        /// The prefix.
        url: String,
        /// What showed the other run.
        why: String,
    },
    /// A local file staged for a single-object upload could not be read or written.
    #[error("{url}: staging {}: {source}", path.shown())]
    Staging {
        /// The URL the file goes to.
        url: String,
        /// The local temporary.
        path: std::path::PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
}

/// Why a run could not be resumed (`split --resume`, [`crate::resume`]). Each message names
/// the file or the output and says what to do instead.
///
/// New variants may come in any release: match the ones you act on and keep a `_` arm.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ResumeError {
    /// The journal found beside the output records another run: another input, other
    /// options, another version.
    #[error(
        "{}: the interrupted run it records is not this one: {}; run the command it records, or leave out --resume to start afresh (its staged tiles are then removed)",
        journal.shown(),
        differences.join("; ")
    )]
    Mismatch {
        /// The journal.
        journal: PathBuf,
        /// What differs, a phrase each (`tile size 128, not 256`).
        differences: Vec<String>,
    },
    /// A run that is still going journals the same output.
    #[error("{}: another run (process {pid}) is writing it with --resume; wait for it to end, or stop it first", output.shown())]
    Busy {
        /// The output.
        output: PathBuf,
        /// The other run's process.
        pid: u32,
    },
    /// The journal cannot be read as one.
    #[error("{}: not a journal this vortex-tiler can read ({why}); leave out --resume to start afresh", journal.shown())]
    Unreadable {
        /// The journal.
        journal: PathBuf,
        /// What is wrong with it.
        why: String,
    },
    /// The run cannot be resumed: its output's format, or their number.
    #[error("{}: --resume {why}", output.shown())]
    Unsupported {
        /// The output.
        output: PathBuf,
        /// What cannot be resumed, and what can.
        why: String,
    },
    /// The journal or the staged output could not be read or written.
    #[error("{}: {source}", path.shown())]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: io::Error,
    },
}
