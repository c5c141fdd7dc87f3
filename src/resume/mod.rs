//! Resuming a run that was killed (`split --resume`, docs/resume.md): the journal a resumable
//! run keeps beside its output, and what a later run checks before it keeps what the killed
//! one wrote.
//!
//! A resumable run stages its output as every run does (`.NAME.partial-PID` for a directory,
//! the pack writer's `.NAME.tmp-PID`), and writes beside it a journal, `.NAME.resume-PID`: a
//! header naming the run ([`Identity`]: the input's fingerprint, the image, every option that
//! changes a byte or the order of the bytes, this build's version), then one line per tile
//! once its bytes are in the staged output ([`Record`]): where it is and a CRC-32C of it. The
//! lines are appended with one `write` each, so a run killed outright (SIGKILL, a time limit)
//! leaves a journal whose every whole line tells of a tile whose bytes the kernel already
//! has; a torn last line is ignored. Nothing is synced: after a power loss a line may tell of
//! bytes that never reached the disk, which the checksum finds.
//!
//! A later run of the same command with `--resume` ([`Journal::start`]) finds the journal of
//! a process that is no longer running, refuses it if it names another run (saying what
//! differs), and takes the journal and the staged output over (renamed to its own process's
//! names, so that the clean-up of dead runs' temporaries leaves them alone). The sink then
//! checks each recorded tile against the bytes staged ([`check_files`] for a directory, the
//! pack writer's `resume` for a pack), removes what is not recorded or does not match
//! ([`prune`]), and rewrites the journal with what it keeps ([`Journal::keep`]); the pipeline
//! runs again from the top and encodes only the tiles not kept. When the output is renamed
//! into place the journal is removed ([`Journal::finish`]).

use std::collections::{HashMap, HashSet};
use std::fs::{self, File, OpenOptions};
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use vortex_pack::{Entry, TileId};

use crate::error::Result;
use crate::output::staging;

pub use crate::error::ResumeError;

/// The first line of every journal: the format and its version.
const MAGIC: &str = "vortex-tiler resume journal 1";

/// How an output is staged beside its destination until it is complete.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum Staging {
    /// A directory, `.NAME.partial-PID` ([`crate::output::partial_path`]).
    Directory,
    /// A pack writer's file, `.NAME.tmp-PID` ([`vortex_pack::temporary_path`]).
    Pack,
}

impl Staging {
    /// Where process `pid` stages `dest`.
    pub fn path(self, dest: &Path, pid: u32) -> PathBuf {
        let name = file_name(dest);
        match self {
            Staging::Directory => staging::parent_of(dest).join(format!(".{name}.partial-{pid}")),
            Staging::Pack => dest.with_file_name(format!(".{name}.tmp-{pid}")),
        }
    }
}

fn file_name(dest: &Path) -> String {
    dest.file_name().map_or_else(|| "out".into(), |n| n.to_string_lossy().into_owned())
}

/// Where process `pid` journals its run writing `dest`: `.NAME.resume-PID` beside it.
pub fn journal_path(dest: &Path, pid: u32) -> PathBuf {
    staging::parent_of(dest).join(format!(".{}.resume-{pid}", file_name(dest)))
}

/// What a run is, as far as its output's bytes go: named values, each of which must be the
/// same for a journal to be resumed (the input's fingerprint, the image's size, the format,
/// every tiling option, this build's version).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Identity(Vec<(String, String)>);

impl Identity {
    /// No values yet.
    pub fn new() -> Identity {
        Identity::default()
    }

    /// This identity and the value `name` has.
    pub fn with(mut self, name: &str, value: impl std::fmt::Display) -> Identity {
        self.0.push((name.to_string(), value.to_string()));
        self
    }

    /// What differs between this run and `then`, the interrupted one, a phrase each:
    /// `tile size 128, not 256`.
    pub fn differences(&self, then: &Identity) -> Vec<String> {
        let theirs: HashMap<&str, &str> = then.0.iter().map(|(k, v)| (k.as_str(), v.as_str())).collect();
        let ours: HashMap<&str, &str> = self.0.iter().map(|(k, v)| (k.as_str(), v.as_str())).collect();
        let mut out = Vec::new();
        for (name, now) in &self.0 {
            match theirs.get(name.as_str()) {
                Some(was) if was == now => {}
                Some(was) => out.push(format!("{name} {now}, not {was}")),
                None => out.push(format!("{name} {now}, which it did not record")),
            }
        }
        for (name, was) in &then.0 {
            if !ours.contains_key(name.as_str()) {
                out.push(format!("it recorded {name} {was}, which this run has not"));
            }
        }
        out
    }

    pub(crate) fn to_json(&self) -> serde_json::Value {
        serde_json::Value::Array(self.0.iter().map(|(k, v)| serde_json::json!([k, v])).collect())
    }

    pub(crate) fn from_json(value: &serde_json::Value) -> Option<Identity> {
        let pairs = value.as_array()?.iter().map(|pair| match pair.as_array()?.as_slice() {
            [k, v] => Some((k.as_str()?.to_string(), v.as_str()?.to_string())),
            _ => None,
        });
        pairs.collect::<Option<Vec<_>>>().map(Identity)
    }
}

/// One tile a journal says is in the staged output.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum Record {
    /// A tile file of a directory output: its length and CRC-32C (every file the layout names
    /// for the tile holds these bytes).
    File {
        /// The tile.
        id: TileId,
        /// Bytes of its file.
        len: u64,
        /// CRC-32C of its file.
        crc: u32,
    },
    /// A tile of a pack, as the pack writer entered it (where its payload lies, or its colour).
    Entry {
        /// The tile.
        id: TileId,
        /// Its index entry.
        entry: Entry,
    },
}

impl Record {
    /// A directory's tile file, of `bytes`.
    pub fn file(id: TileId, bytes: &[u8]) -> Record {
        Record::File { id, len: bytes.len() as u64, crc: crc32c::crc32c(bytes) }
    }

    /// The tile it tells of.
    pub fn id(&self) -> TileId {
        match self {
            Record::File { id, .. } | Record::Entry { id, .. } => *id,
        }
    }

    fn line(&self) -> String {
        match self {
            Record::File { id, len, crc } => format!("f {} {} {} {len} {crc:08x}\n", id.lod, id.x, id.y),
            Record::Entry { id, entry } => format!(
                "e {} {} {} {} {:x} {} {:08x}\n",
                id.lod, id.x, id.y, entry.kind, entry.offset_or_value, entry.len, entry.crc
            ),
        }
    }

    fn parse(line: &str) -> Option<Record> {
        let mut words = line.split(' ');
        let kind = words.next()?;
        let mut number = || words.next().and_then(|w| w.parse::<u32>().ok());
        let id = TileId { lod: number()?, x: number()?, y: number()? };
        let rest: Vec<&str> = words.collect();
        let hex32 = |w: &&str| u32::from_str_radix(w, 16).ok();
        match (kind, rest.as_slice()) {
            ("f", [len, crc]) => Some(Record::File { id, len: len.parse().ok()?, crc: hex32(crc)? }),
            ("e", [tile_kind, value, len, crc]) => Some(Record::Entry {
                id,
                entry: Entry {
                    kind: tile_kind.parse().ok()?,
                    offset_or_value: u64::from_str_radix(value, 16).ok()?,
                    len: len.parse().ok()?,
                    crc: hex32(crc)?,
                },
            }),
            _ => None,
        }
    }
}

/// The journal of this run, `.NAME.resume-PID` beside its output. Dropped, it stays: that is
/// what a later `--resume` reads; [`finish`](Self::finish) removes it once the output is in
/// place.
#[derive(Debug)]
pub struct Journal {
    path: PathBuf,
    header: String,
    file: Mutex<File>,
}

/// What an interrupted run left, taken over by this one ([`Journal::start`]).
#[derive(Debug)]
#[non_exhaustive]
pub struct Interrupted {
    /// Its staged output, now under this process's staging name.
    pub staging: PathBuf,
    /// The tiles its journal says it finished, in the order it finished them (for a pack, the
    /// order they were added in).
    pub records: Vec<Record>,
    /// Its journal's name, as found (for messages).
    pub journal: PathBuf,
}

/// A journal found beside the output.
struct Found {
    path: PathBuf,
    staged: PathBuf,
    records: Vec<Record>,
}

impl Journal {
    /// Starts this run's journal for `dest`, staged as `staging`, made as `identity` says.
    /// Where a run that is no longer running left a journal and its staged output, they are
    /// taken over and returned, once its identity is found to be this run's; a journal of
    /// another run is refused ([`ResumeError::Mismatch`], naming what differs), as is one of a
    /// run still going ([`ResumeError::Busy`]). A journal whose staged output is gone (its
    /// output was finished, or removed) is removed. `None`: nothing to resume, the run starts
    /// afresh.
    pub fn start(dest: &Path, staging: Staging, identity: &Identity) -> Result<(Journal, Option<Interrupted>)> {
        let me = std::process::id();
        let ours = journal_path(dest, me);
        let mut found: Option<Found> = None;
        for (pid, path) in journals(dest)? {
            if pid == me {
                continue;
            }
            if staging::process_alive(pid) != Some(false) {
                return Err(ResumeError::Busy { output: dest.to_path_buf(), pid }.into());
            }
            let (then, staged, records) = read(&path)?;
            let differences = identity.differences(&then);
            if !differences.is_empty() {
                return Err(ResumeError::Mismatch { journal: path, differences }.into());
            }
            // The staging it names, else its process's: a run killed while taking another's
            // over has renamed the staging but not yet rewritten the journal.
            let staged = [staged, staging.path(dest, pid)].into_iter().find(|p| p.exists());
            let Some(staged) = staged else {
                fs::remove_file(&path).map_err(|e| ResumeError::Io { path: path.clone(), source: e })?;
                continue;
            };
            // Two interrupted runs (one killed while resuming the other, say): the one that
            // got further is taken; the other's files are a dead run's, which the clean-up removes.
            if found.as_ref().is_none_or(|f| f.records.len() < records.len()) {
                found = Some(Found { path, staged, records });
            }
        }
        let header = header(dest, staging, identity);
        let Some(found) = found else {
            let journal = Journal::create(ours, header)?;
            journal.keep(&[])?;
            return Ok((journal, None));
        };
        // Ours from here on: the journal first (it still names the staging it found), then the
        // staging; a kill between the two leaves a journal whose staging is its process's.
        let staged = staging.path(dest, me);
        let failed = |path: &Path| {
            let path = path.to_path_buf();
            move |e| ResumeError::Io { path, source: e }
        };
        fs::rename(&found.path, &ours).map_err(failed(&found.path))?;
        if found.staged != staged {
            fs::rename(&found.staged, &staged).map_err(failed(&found.staged))?;
        }
        let journal = Journal::create(ours, header)?;
        Ok((journal, Some(Interrupted { staging: staged, records: found.records, journal: found.path })))
    }

    fn create(path: PathBuf, header: String) -> Result<Journal> {
        let file = OpenOptions::new()
            .create(true)
            .append(true)
            .open(&path)
            .map_err(|e| ResumeError::Io { path: path.clone(), source: e })?;
        Ok(Journal { path, header, file: Mutex::new(file) })
    }

    /// This journal's file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Rewrites the journal: its header, then `records`, what this run keeps of an interrupted
    /// one's (nothing for a fresh run). Written beside it and renamed over it, so that a kill
    /// on the way leaves the one or the other.
    pub fn keep(&self, records: &[Record]) -> Result<()> {
        let mut text = self.header.clone();
        for r in records {
            text.push_str(&r.line());
        }
        let next = PathBuf::from(format!("{}.new", self.path.display()));
        let mut file = self.file.lock().unwrap_or_else(|p| p.into_inner());
        let replaced = fs::write(&next, text.as_bytes())
            .and_then(|()| fs::rename(&next, &self.path))
            .and_then(|()| OpenOptions::new().append(true).open(&self.path));
        match replaced {
            Ok(reopened) => {
                *file = reopened;
                Ok(())
            }
            Err(e) => {
                let _ = fs::remove_file(&next);
                Err(ResumeError::Io { path: self.path.clone(), source: e }.into())
            }
        }
    }

    /// Records a tile whose bytes are in the staged output: one line, one `write`.
    pub fn record(&self, record: Record) -> Result<()> {
        let line = record.line();
        let file = self.file.lock().unwrap_or_else(|p| p.into_inner());
        (&*file).write_all(line.as_bytes()).map_err(|e| ResumeError::Io { path: self.path.clone(), source: e }.into())
    }

    /// Removes the journal: the output it was for is in place.
    pub fn finish(self) -> Result<()> {
        fs::remove_file(&self.path).map_err(|e| ResumeError::Io { path: self.path.clone(), source: e }.into())
    }
}

/// The header lines of a journal.
fn header(dest: &Path, staging: Staging, identity: &Identity) -> String {
    let staged = staging.path(dest, std::process::id());
    let head = serde_json::json!({
        "output": dest.display().to_string(),
        "staged": file_name(&staged),
        "identity": identity.to_json(),
    });
    format!("{MAGIC}\n{head}\n")
}

/// The journals of runs writing `dest`: their process ids and files.
fn journals(dest: &Path) -> Result<Vec<(u32, PathBuf)>> {
    let parent = staging::parent_of(dest);
    let prefix = format!(".{}.resume-", file_name(dest));
    let entries = match fs::read_dir(&parent) {
        Ok(entries) => entries,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(ResumeError::Io { path: parent, source: e }.into()),
    };
    let mut found = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|e| ResumeError::Io { path: parent.clone(), source: e })?;
        let name = entry.file_name();
        let pid = (name.to_str().and_then(|n| n.strip_prefix(&prefix)))
            .filter(|d| !d.is_empty() && d.bytes().all(|b| b.is_ascii_digit()))
            .and_then(|d| d.parse::<u32>().ok());
        if let Some(pid) = pid {
            found.push((pid, entry.path()));
        }
    }
    found.sort();
    Ok(found)
}

/// A journal's identity, the staged output it names and its records; the records stop at the
/// first line that is not whole (a run killed while writing it).
fn read(path: &Path) -> Result<(Identity, PathBuf, Vec<Record>)> {
    let unreadable = |why: &str| ResumeError::Unreadable { journal: path.to_path_buf(), why: why.to_string() };
    let bytes = fs::read(path).map_err(|e| ResumeError::Io { path: path.to_path_buf(), source: e })?;
    let text = String::from_utf8_lossy(&bytes);
    let mut lines = text.split_inclusive('\n');
    if lines.next().map(str::trim_end) != Some(MAGIC) {
        return Err(unreadable("it does not start as a journal of this version does").into());
    }
    let head: serde_json::Value = match lines.next() {
        Some(line) if line.ends_with('\n') => serde_json::from_str(line).map_err(|e| unreadable(&e.to_string()))?,
        _ => return Err(unreadable("its header is cut short").into()),
    };
    let identity = Identity::from_json(&head["identity"]).ok_or_else(|| unreadable("its header names no run"))?;
    let staged = head["staged"].as_str().filter(|s| !s.contains('/') && s.starts_with('.'));
    let staged = staged.ok_or_else(|| unreadable("its header names no staged output"))?;
    let staged = staging::parent_of(path).join(staged);
    let mut records = Vec::new();
    for line in lines {
        let Some(whole) = line.strip_suffix('\n') else { break };
        match Record::parse(whole) {
            Some(r) => records.push(r),
            None => break,
        }
    }
    Ok((identity, staged, records))
}

/// Of `records` (a directory's tile files), those whose files under `staging` are whole: every
/// name `names` gives the tile holds `len` bytes of CRC `crc`. A later record of a tile
/// replaces an earlier one. In the order given.
pub fn check_files(staging: &Path, records: &[Record], names: &dyn Fn(TileId) -> Vec<String>) -> Vec<Record> {
    let last: HashMap<TileId, usize> = records.iter().enumerate().map(|(k, r)| (r.id(), k)).collect();
    let whole = |name: &str, len: u64, crc: u32| {
        let path = staging.join(name);
        fs::metadata(&path).is_ok_and(|m| m.is_file() && m.len() == len)
            && fs::read(&path).is_ok_and(|bytes| crc32c::crc32c(&bytes) == crc)
    };
    (records.iter().enumerate())
        .filter(|(k, r)| match r {
            Record::File { id, len, crc } => last[id] == *k && names(*id).iter().all(|n| whole(n.as_str(), *len, *crc)),
            Record::Entry { .. } => false,
        })
        .map(|(_, r)| *r)
        .collect()
}

/// Removes every file under `staging` whose name (relative, '/'-separated) `keep` does not
/// hold; returns how many went.
pub fn prune(staging: &Path, keep: &HashSet<String>) -> Result<u64> {
    fn walk(dir: &Path, prefix: &str, keep: &HashSet<String>, removed: &mut u64) -> io::Result<()> {
        for entry in fs::read_dir(dir)? {
            let entry = entry?;
            let name = format!("{prefix}{}", entry.file_name().to_string_lossy());
            let kind = entry.file_type()?;
            if kind.is_dir() {
                walk(&entry.path(), &format!("{name}/"), keep, removed)?;
            } else if !keep.contains(&name) {
                fs::remove_file(entry.path())?;
                *removed += 1;
            }
        }
        Ok(())
    }
    let mut removed = 0;
    walk(staging, "", keep, &mut removed).map_err(|e| ResumeError::Io { path: staging.to_path_buf(), source: e })?;
    Ok(removed)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn id(lod: u32, x: u32, y: u32) -> TileId {
        TileId { lod, x, y }
    }

    #[test]
    fn records_read_back_as_written() {
        let records = [
            Record::file(id(0, 3, 4), b"tile"),
            Record::Entry {
                id: id(2, 0, 1),
                entry: Entry { offset_or_value: 0x0012_3456_789a, len: 77, crc: 5, kind: 3 },
            },
            Record::Entry { id: id(1, 1, 1), entry: Entry { offset_or_value: 0xffee, len: 0, crc: 0, kind: 1 } },
        ];
        for r in records {
            let line = r.line();
            assert_eq!(Record::parse(line.trim_end()), Some(r), "{line}");
        }
        for bad in ["", "f 1 2", "f 1 2 3 4", "x 1 2 3 4 5", "f 1 2 3 4 zz", "e 1 2 3 4 5 6"] {
            assert_eq!(Record::parse(bad), None, "{bad}");
        }
    }

    #[test]
    fn differences_name_each_value() {
        let then = Identity::new().with("tile size", 256).with("input", "a").with("border", 1);
        let now = Identity::new().with("tile size", 128).with("input", "a").with("codec", "png");
        let d = now.differences(&then);
        assert_eq!(
            d,
            vec![
                "tile size 128, not 256".to_string(),
                "codec png, which it did not record".to_string(),
                "it recorded border 1, which this run has not".to_string()
            ]
        );
        assert!(then.differences(&then).is_empty());
        assert_eq!(Identity::from_json(&then.to_json()), Some(then));
    }

    /// A dead run's journal and staging are taken over, a torn last line dropped; another
    /// run's journal is refused naming what differs; one without its staging is removed.
    #[test]
    fn a_dead_runs_journal_is_taken_over_or_refused() {
        if staging::process_alive(1).is_none() {
            return;
        }
        let dir = tempfile::tempdir().unwrap();
        let dest = dir.path().join("out");
        let me = Identity::new().with("tile size", 256);
        let dead = staging::dead_pid();
        // Nothing to resume: a fresh journal, header only.
        let (journal, found) = Journal::start(&dest, Staging::Directory, &me).unwrap();
        assert!(found.is_none());
        journal.record(Record::file(id(0, 0, 0), b"a")).unwrap();
        // As a killed run leaves it: under a dead process's names, a line cut short.
        let theirs = journal_path(&dest, dead);
        let mut text = fs::read_to_string(journal.path()).unwrap();
        text = text.replace(&format!("partial-{}", std::process::id()), &format!("partial-{dead}"));
        text.push_str("f 0 1 0 5 0000");
        fs::write(&theirs, &text).unwrap();
        fs::remove_file(journal.path()).unwrap();
        drop(journal);
        let staged = Staging::Directory.path(&dest, dead);
        fs::create_dir(&staged).unwrap();

        let other = Identity::new().with("tile size", 128);
        let e = Journal::start(&dest, Staging::Directory, &other).unwrap_err().to_string();
        assert!(e.contains("tile size 128, not 256") && e.contains(".out.resume-"), "{e}");
        assert!(theirs.exists() && staged.exists(), "a refusal changes nothing");

        let (journal, found) = Journal::start(&dest, Staging::Directory, &me).unwrap();
        let found = found.unwrap();
        assert_eq!(found.records, vec![Record::file(id(0, 0, 0), b"a")]);
        assert_eq!(found.staging, Staging::Directory.path(&dest, std::process::id()));
        assert!(found.staging.is_dir() && !staged.exists() && !theirs.exists());
        assert_eq!(journal.path(), journal_path(&dest, std::process::id()));
        journal.finish().unwrap();
        fs::remove_dir(&found.staging).unwrap();

        // A journal whose staging is gone is stale: removed, nothing to resume.
        fs::write(&theirs, &text).unwrap();
        let (journal, found) = Journal::start(&dest, Staging::Directory, &me).unwrap();
        assert!(found.is_none() && !theirs.exists());
        journal.finish().unwrap();
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 0);
    }

    #[test]
    fn a_journal_of_a_live_run_or_not_a_journal_is_refused() {
        if staging::process_alive(1).is_none() {
            return;
        }
        let dir = tempfile::tempdir().unwrap();
        let dest = dir.path().join("out.vtpk");
        fs::write(journal_path(&dest, 1), "x").unwrap();
        let e = Journal::start(&dest, Staging::Pack, &Identity::new()).unwrap_err().to_string();
        assert!(e.contains("process 1"), "{e}");
        fs::remove_file(journal_path(&dest, 1)).unwrap();
        fs::write(journal_path(&dest, staging::dead_pid()), "not a journal\n").unwrap();
        let e = Journal::start(&dest, Staging::Pack, &Identity::new()).unwrap_err().to_string();
        assert!(e.contains(".out.vtpk.resume-") && e.contains("not a journal"), "{e}");
    }

    #[test]
    fn files_are_kept_only_whole_and_the_rest_pruned() {
        let dir = tempfile::tempdir().unwrap();
        let staged = dir.path();
        fs::create_dir(staged.join("0")).unwrap();
        fs::write(staged.join("0/a"), b"good").unwrap();
        fs::write(staged.join("0/b"), b"damaged").unwrap();
        fs::write(staged.join("0/c"), b"not recorded").unwrap();
        fs::write(staged.join("0/d"), b"ret").unwrap();
        let names = |id: TileId| vec![["0/a", "0/b", "0/c", "0/d"][id.x as usize].to_string()];
        let records = [
            Record::file(id(0, 0, 0), b"good"),
            Record::file(id(0, 1, 0), b"damages"),
            Record::file(id(0, 3, 0), b"old"),
            Record::file(id(0, 3, 0), b"ret"),
        ];
        let kept = check_files(staged, &records, &names);
        assert_eq!(kept, vec![records[0], records[3]]);
        let keep: HashSet<String> = kept.iter().flat_map(|r| names(r.id())).collect();
        assert_eq!(prune(staged, &keep).unwrap(), 2);
        assert!(staged.join("0/a").exists() && staged.join("0/d").exists());
        assert!(!staged.join("0/b").exists() && !staged.join("0/c").exists());
    }
}
