//! Temporary names for outputs being written, and the removal of those a dead run left.
//!
//! An output `DIR/NAME` is written as `DIR/.NAME.partial-PID` (a pack as `DIR/.NAME.tmp-PID`,
//! the pack writer's own name), in the destination's directory so that the final rename never
//! crosses a file system. A run that is killed outright (SIGKILL, power loss) cannot clean up;
//! the next run for the same destination finds temporaries whose PID is no longer alive and
//! removes them (with a resumable run's journal, `.NAME.resume-PID`: a run without `--resume`
//! starts afresh, docs/resume.md). A temporary of a live process, possibly another run
//! writing the same destination, is left alone.

use std::fs;
use std::io;
use std::path::{Path, PathBuf};

/// `dest`'s directory, `.` for a bare name.
pub fn parent_of(dest: &Path) -> PathBuf {
    match dest.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

fn name_of(dest: &Path) -> String {
    dest.file_name().map_or_else(|| "out".into(), |n| n.to_string_lossy().into_owned())
}

/// This process's temporary name for `dest`.
pub fn partial_path(dest: &Path) -> PathBuf {
    parent_of(dest).join(format!(".{}.partial-{}", name_of(dest), std::process::id()))
}

/// An empty staging directory at `staging`: what a run of this process left there removed.
pub fn fresh_dir(staging: &Path) -> io::Result<()> {
    if staging.exists() {
        fs::remove_dir_all(staging)?;
    }
    fs::create_dir_all(staging)
}

/// Writes `bytes` to a temporary name beside `path`, then renames it into place; on any
/// failure the temporary is removed. The caller has claimed `path` (see [`super::claim`]).
pub fn write_file(path: &Path, bytes: &[u8]) -> io::Result<()> {
    let tmp = partial_path(path);
    let result = fs::write(&tmp, bytes).and_then(|()| fs::rename(&tmp, path));
    if result.is_err() {
        let _ = fs::remove_file(&tmp);
    }
    result
}

/// Moves the finished directory `staging` to `dest`. A previous output at `dest` (claimed as
/// ours) is moved aside first and deleted only once the new one is in place; on failure
/// `staging` is removed and the previous output put back.
pub fn replace_dir(staging: &Path, dest: &Path) -> io::Result<()> {
    let old = PathBuf::from(format!("{}.old", staging.display()));
    let had_old = fs::symlink_metadata(dest).is_ok();
    let moved = (|| {
        if had_old {
            fs::rename(dest, &old)?;
        }
        fs::rename(staging, dest).inspect_err(|_| {
            if had_old {
                let _ = fs::rename(&old, dest);
            }
        })
    })();
    if let Err(e) = moved {
        let _ = fs::remove_dir_all(staging);
        return Err(e);
    }
    if had_old {
        fs::remove_dir_all(&old)?;
    }
    Ok(())
}

/// Removes the temporaries of `dest` left by processes that are no longer running; returns
/// what was removed so that the caller can say so.
pub fn remove_stale(dest: &Path) -> io::Result<Vec<PathBuf>> {
    let parent = parent_of(dest);
    let name = name_of(dest);
    let prefix = format!(".{name}.");
    let mut removed = Vec::new();
    let entries = match fs::read_dir(&parent) {
        Ok(e) => e,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(removed),
        Err(e) => return Err(e),
    };
    for entry in entries {
        let entry = entry?;
        let file_name = entry.file_name();
        let pid = file_name.to_str().and_then(|n| {
            n.strip_prefix(&prefix).and_then(partial_pid).or_else(|| vortex_pack::temporary_pid(&name, n))
        });
        let Some(pid) = pid else { continue };
        if pid == std::process::id() || process_alive(pid) != Some(false) {
            continue;
        }
        let path = entry.path();
        let kind = entry.file_type()?;
        if kind.is_dir() {
            fs::remove_dir_all(&path)?;
        } else {
            fs::remove_file(&path)?;
        }
        removed.push(path);
    }
    removed.sort();
    Ok(removed)
}

/// The PID in `partial-PID` or `partial-PID.old`, or a resumable run's journal's `resume-PID`
/// or `resume-PID.new` (its next version, renamed over it: docs/resume.md; a pack writer's `tmp-PID` is [`vortex_pack::temporary_pid`]'s to read).
fn partial_pid(suffix: &str) -> Option<u32> {
    let digits = suffix.strip_prefix("partial-").or_else(|| suffix.strip_prefix("resume-"))?;
    let digits = digits.strip_suffix(".old").or_else(|| digits.strip_suffix(".new")).unwrap_or(digits);
    if digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    digits.parse().ok()
}

/// Whether process `pid` exists: `None` where this system cannot tell (no `/proc`), so that
/// nothing is removed there.
pub(crate) fn process_alive(pid: u32) -> Option<bool> {
    let proc = Path::new("/proc");
    if !proc.join("self").exists() {
        return None;
    }
    Some(proc.join(pid.to_string()).exists())
}

/// A PID that no process has: beyond the kernel's maximum (for tests of dead runs' files).
#[cfg(test)]
pub(crate) fn dead_pid() -> u32 {
    let max: u32 =
        fs::read_to_string("/proc/sys/kernel/pid_max").ok().and_then(|s| s.trim().parse().ok()).unwrap_or(4194304);
    max + 1
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_carry_the_pid() {
        assert_eq!(partial_pid("partial-123"), Some(123));
        assert_eq!(partial_pid("partial-123.old"), Some(123));
        assert_eq!(partial_pid("resume-77"), Some(77), "a resumable run's journal");
        assert_eq!(partial_pid("resume-77.new"), Some(77));
        assert_eq!(partial_pid("tmp-9"), None, "the pack writer's");
        assert_eq!(partial_pid("partial-"), None);
        assert_eq!(partial_pid("partial-12x"), None);
        assert_eq!(partial_pid("backup"), None);
    }

    #[test]
    fn stale_temporaries_of_dead_runs_go_and_others_stay() {
        if process_alive(1).is_none() {
            return;
        }
        let dir = tempfile::tempdir().unwrap();
        let dest = dir.path().join("out");
        let dead = dead_pid();
        let stale_dir = dir.path().join(format!(".out.partial-{dead}"));
        fs::create_dir_all(stale_dir.join("sub")).unwrap();
        fs::write(stale_dir.join("sub/tile.png"), b"x").unwrap();
        let stale_pack = dir.path().join(format!(".out.tmp-{dead}"));
        fs::write(&stale_pack, b"x").unwrap();
        let live = dir.path().join(".out.partial-1");
        fs::write(&live, b"x").unwrap();
        let other = dir.path().join(format!(".other.partial-{dead}"));
        fs::write(&other, b"x").unwrap();
        let mine = partial_path(&dest);
        fs::write(&mine, b"x").unwrap();

        let removed = remove_stale(&dest).unwrap();
        let mut expected = vec![stale_dir.clone(), stale_pack.clone()];
        expected.sort();
        assert_eq!(removed, expected);
        assert!(!stale_dir.exists() && !stale_pack.exists());
        assert!(live.exists() && other.exists() && mine.exists());
    }

    #[test]
    fn replace_dir_swaps_in_the_new_output() {
        let dir = tempfile::tempdir().unwrap();
        let dest = dir.path().join("out");
        fs::create_dir(&dest).unwrap();
        fs::write(dest.join("old.png"), b"old").unwrap();
        let staging = partial_path(&dest);
        fs::create_dir(&staging).unwrap();
        fs::write(staging.join("new.png"), b"new").unwrap();
        replace_dir(&staging, &dest).unwrap();
        assert_eq!(fs::read_dir(&dest).unwrap().count(), 1);
        assert_eq!(fs::read(dest.join("new.png")).unwrap(), b"new");
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 1);
        // A failed move leaves no staging behind.
        let missing = dir.path().join("missing");
        assert!(replace_dir(&missing, &dir.path().join("nowhere/out")).is_err());
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[test]
    fn write_file_leaves_only_the_result() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("report.json");
        write_file(&path, b"{}").unwrap();
        assert_eq!(fs::read(&path).unwrap(), b"{}");
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 1);
        assert!(write_file(&dir.path().join("missing/report.json"), b"{}").is_err());
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 1);
    }
}
