//! The one rule every output follows, whatever the command: nothing the user owns is ever
//! destroyed.
//!
//! Before a command writes anything it [`claim`]s its destination, which checks, before a
//! single byte is written:
//!
//! * what is there now: nothing; a previous output of ours ([`Product`] says how to recognise
//!   one), which the new output replaces once it is complete; or anything else, which is
//!   refused with a message that says what is there and how to proceed. A device node, FIFO,
//!   socket or symbolic link is never replaced, nor a directory where a file goes or a file
//!   where a directory goes. A foreign regular file is replaced only with `--force`.
//! * how it relates to the inputs: an output that is an input (also through a hard link), lies
//!   inside an input directory, or would contain an input when replaced, is refused.
//!
//! Every output is then written under a temporary name in the destination's directory
//! ([`partial_path`], [`write_file`], [`replace_dir`]) and renamed into place only when
//! complete; temporaries that a dead process left behind are found and removed by the next run
//! for the same destination ([`remove_stale`]).

pub(crate) mod ours;
pub(crate) mod staging;

use std::fs;
use std::io;
use std::path::{Component, Path, PathBuf};

pub use crate::error::OutputError;
pub use ours::Product;
// The temporary names, for outputs a caller writes itself (render's frames and report, a
// screenshot) and for clean-up after a signal.
pub use staging::{partial_path, remove_stale, replace_dir, write_file};

fn io_err(path: &Path) -> impl FnOnce(io::Error) -> OutputError + '_ {
    move |source| OutputError::Io { path: path.to_path_buf(), source }
}

/// A destination checked by [`claim`]: safe to write under a temporary name beside it and to
/// rename into place when complete.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Claim {
    /// The destination, as given.
    pub path: PathBuf,
    /// What will be written there.
    pub product: Product,
    /// What the rename will replace: a previous output of ours, or (only with `force`) a
    /// foreign regular file.
    pub replaces: Option<Existing>,
}

/// What a [`Claim`]'s rename will replace.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Existing {
    /// A previous output of ours (or an empty directory).
    Ours,
    /// A foreign regular file, replaced because the user passed `--force`.
    ForcedFile,
}

/// Checks that `dest` may receive `product`, given the command's `inputs` (files or
/// directories it reads). `force` lets a foreign regular file be replaced; nothing else.
pub fn claim(dest: &Path, product: Product, inputs: &[&Path], force: bool) -> Result<Claim, OutputError> {
    check_inputs(dest, inputs)?;
    let replaces = existing(dest, product, force)?;
    Ok(Claim { path: dest.to_path_buf(), product, replaces })
}

/// What is at `dest` now, and whether it may be replaced.
fn existing(dest: &Path, product: Product, force: bool) -> Result<Option<Existing>, OutputError> {
    let meta = match fs::symlink_metadata(dest) {
        Ok(m) => m,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(io_err(dest)(e)),
    };
    let kind = meta.file_type();
    if kind.is_symlink() {
        let target = fs::read_link(dest).unwrap_or_default();
        return Err(OutputError::Symlink { path: dest.to_path_buf(), target });
    }
    if let Some(what) = special_kind(&kind) {
        return Err(OutputError::Special { path: dest.to_path_buf(), what });
    }
    match (product.is_dir(), kind.is_dir()) {
        (true, false) => {
            return Err(OutputError::WrongType { path: dest.to_path_buf(), found: "a file", product: product.noun() });
        }
        (false, true) => {
            return Err(OutputError::WrongType {
                path: dest.to_path_buf(),
                found: "a directory",
                product: product.noun(),
            });
        }
        _ => {}
    }
    match product.recognise(dest) {
        Ok(()) => Ok(Some(Existing::Ours)),
        Err(_) if force && !product.is_dir() => Ok(Some(Existing::ForcedFile)),
        Err(what) => Err(OutputError::Foreign {
            path: dest.to_path_buf(),
            what,
            product: product.noun(),
            advice: if product.is_dir() {
                "choose a new or empty directory"
            } else {
                "pass --force to replace it, or choose another path"
            },
        }),
    }
}

#[cfg(unix)]
fn special_kind(kind: &fs::FileType) -> Option<&'static str> {
    use std::os::unix::fs::FileTypeExt;
    if kind.is_block_device() || kind.is_char_device() {
        Some("a device node")
    } else if kind.is_fifo() {
        Some("a FIFO")
    } else if kind.is_socket() {
        Some("a socket")
    } else {
        None
    }
}

#[cfg(not(unix))]
fn special_kind(kind: &fs::FileType) -> Option<&'static str> {
    (!kind.is_file() && !kind.is_dir()).then_some("not a regular file or directory")
}

/// Refuses an output that is an input, lies inside one, or contains one.
fn check_inputs(dest: &Path, inputs: &[&Path]) -> Result<(), OutputError> {
    let dest_abs = resolve(dest).map_err(io_err(dest))?;
    for input in inputs {
        // An input that cannot be resolved is reported by the command that opens it.
        let Ok(input_abs) = fs::canonicalize(input) else { continue };
        let input = input.to_path_buf();
        if dest_abs == input_abs || same_file(dest, &input_abs) {
            return Err(OutputError::IsInput { path: dest.to_path_buf(), input });
        }
        if dest_abs.starts_with(&input_abs) {
            return Err(OutputError::InsideInput { path: dest.to_path_buf(), input });
        }
        if input_abs.starts_with(&dest_abs) {
            return Err(OutputError::ContainsInput { path: dest.to_path_buf(), input });
        }
    }
    Ok(())
}

/// Whether `a` and `b` are one file under two names (hard links).
#[cfg(unix)]
fn same_file(a: &Path, b: &Path) -> bool {
    use std::os::unix::fs::MetadataExt;
    match (fs::metadata(a), fs::metadata(b)) {
        (Ok(a), Ok(b)) => a.dev() == b.dev() && a.ino() == b.ino(),
        _ => false,
    }
}

#[cfg(not(unix))]
fn same_file(_: &Path, _: &Path) -> bool {
    false
}

/// `path` made absolute with every existing ancestor's symbolic links resolved, for a path
/// that need not exist yet: the nearest existing ancestor is canonicalised and the rest
/// appended (`..` in the rest is applied textually).
fn resolve(path: &Path) -> io::Result<PathBuf> {
    let absolute = if path.is_absolute() { path.to_path_buf() } else { std::env::current_dir()?.join(path) };
    let mut existing = absolute.as_path();
    let mut rest = Vec::new();
    loop {
        match fs::canonicalize(existing) {
            Ok(mut resolved) => {
                for c in rest.iter().rev() {
                    match c {
                        Component::ParentDir => {
                            resolved.pop();
                        }
                        Component::Normal(n) => resolved.push(n),
                        _ => {}
                    }
                }
                return Ok(resolved);
            }
            Err(_) => {
                let Some(parent) = existing.parent() else { return Ok(absolute) };
                if let Some(last) = existing.components().next_back() {
                    rest.push(last);
                }
                existing = parent;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn refused(dest: &Path, product: Product, inputs: &[&Path], force: bool) -> String {
        claim(dest, product, inputs, force).unwrap_err().to_string()
    }

    #[test]
    fn absent_destination_is_claimed() {
        let dir = tempfile::tempdir().unwrap();
        let dest = dir.path().join("new/deeper/out.vtpk");
        let c = claim(&dest, Product::Pack, &[], false).unwrap();
        assert_eq!(c.replaces, None);
    }

    #[test]
    fn output_that_is_the_input_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("in.png");
        fs::write(&input, b"\x89PNG").unwrap();
        let e = refused(&input, Product::Pack, &[&input], true);
        assert!(e.contains("is the input"), "{e}");
        // The same file through another spelling of its path, and through a hard link.
        let other = dir.path().join(".").join("sub/../in.png");
        fs::create_dir(dir.path().join("sub")).unwrap();
        assert!(refused(&other, Product::Pack, &[&input], true).contains("is the input"));
        let link = dir.path().join("hard.vtpk");
        fs::hard_link(&input, &link).unwrap();
        assert!(refused(&link, Product::Pack, &[&input], true).contains("is the input"));
    }

    #[test]
    fn output_containing_or_inside_an_input_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out");
        fs::create_dir(&out).unwrap();
        let input = out.join("source.png");
        fs::write(&input, b"x").unwrap();
        fs::write(out.join("info.json"), "{}").unwrap();
        let e = refused(&out, Product::TileDir, &[&input], false);
        assert!(e.contains("holds the input"), "{e}");
        // Without the input among the inputs, the directory is still not ours.
        let e = refused(&out, Product::TileDir, &[], false);
        assert!(e.contains("source.png") && e.contains("not one of its tiles"), "{e}");
        let tiles = dir.path().join("tiles");
        fs::create_dir(&tiles).unwrap();
        let e = refused(&tiles.join("out.vtpk"), Product::Pack, &[&tiles], false);
        assert!(e.contains("lies inside the input"), "{e}");
    }

    #[test]
    fn a_previous_tile_directory_is_ours() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out");
        fs::create_dir_all(out.join("0")).unwrap();
        fs::write(out.join("info.json"), r#"{"lodCount":2,"filenameFormat":"%1$d/%2$d_%3$d.png"}"#).unwrap();
        fs::write(out.join("0/1_0.png"), b"x").unwrap();
        assert_eq!(claim(&out, Product::TileDir, &[], false).unwrap().replaces, Some(Existing::Ours));
        fs::write(out.join("0/readme.txt"), b"x").unwrap();
        assert!(refused(&out, Product::TileDir, &[], false).contains("0/readme.txt"));
        fs::remove_file(out.join("0/readme.txt")).unwrap();
        fs::write(out.join("5_0_0.png"), b"x").unwrap();
        assert!(refused(&out, Product::TileDir, &[], false).contains("5_0_0.png"));
        // Files of the original tool have no filenameFormat: the default stem, any image type.
        let old = dir.path().join("old");
        fs::create_dir(&old).unwrap();
        fs::write(old.join("info.json"), r#"{"tileSize":128,"tileCount":2,"lodCount":2}"#).unwrap();
        fs::write(old.join("lod01-x0000-y0000.jpg"), b"x").unwrap();
        assert!(claim(&old, Product::TileDir, &[], false).is_ok());
        fs::write(old.join("lod01-x0000-y0000.txt"), b"x").unwrap();
        assert!(claim(&old, Product::TileDir, &[], false).is_err());
    }

    #[cfg(unix)]
    #[test]
    fn links_and_device_nodes_are_never_replaced() {
        let dir = tempfile::tempdir().unwrap();
        let e = refused(Path::new("/dev/null"), Product::Pack, &[], true);
        assert!(e.contains("device node"), "{e}");
        let target = dir.path().join("target.vtpk");
        fs::write(&target, b"x").unwrap();
        let link = dir.path().join("link.vtpk");
        std::os::unix::fs::symlink(&target, &link).unwrap();
        let e = refused(&link, Product::Pack, &[], true);
        assert!(e.contains("symbolic link"), "{e}");
    }

    #[test]
    fn foreign_files_need_force_and_directories_never_take_it() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("notes.txt");
        fs::write(&file, b"my notes").unwrap();
        let e = refused(&file, Product::Pack, &[], false);
        assert!(e.contains("--force") && e.contains("not a pack"), "{e}");
        assert_eq!(claim(&file, Product::Pack, &[], true).unwrap().replaces, Some(Existing::ForcedFile));
        let e = refused(&file, Product::TileDir, &[], true);
        assert!(e.contains("a file where"), "{e}");
        let e = refused(dir.path(), Product::Pack, &[], true);
        assert!(e.contains("a directory where"), "{e}");
        let e = refused(dir.path(), Product::TileDir, &[], true);
        assert!(e.contains("notes.txt") && !e.contains("--force"), "{e}");
    }

    #[test]
    fn resolve_handles_missing_tails() {
        let dir = tempfile::tempdir().unwrap();
        let base = fs::canonicalize(dir.path()).unwrap();
        assert_eq!(resolve(&dir.path().join("a/b/../c")).unwrap(), base.join("a/c"));
    }
}
