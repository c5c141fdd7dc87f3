//! Where a tiled input's files are: a directory, or a zip archive read in place (`vips dzsave
//! NAME.zip`). The Deep Zoom, z/y/x and IIIF readers name their files by `/`-separated paths
//! relative to the store's root and read them through [`TileStore`], so one reader serves both.
//!
//! A zip is indexed once when opened (every entry's name checked: no `..`, no absolute paths,
//! no duplicates); tiles are then read from many threads at once, each read through its own
//! clone of the archive over positioned reads of the one open file, so no lock is held while a
//! tile is inflated.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use zip::ZipArchive;

use crate::error::{Result, TilerError};
use crate::limits::human_bytes;

/// The most bytes one tile file may have: a 4096² 16-bit RGBA tile stored without compression
/// is 128 MiB; anything larger is not a tile, and is refused before it is read.
pub(crate) const MAX_TILE_BYTES: u64 = 256 << 20;

/// The most bytes a descriptor (`.dzi`, `info.json`) may have.
pub(crate) const MAX_DESCRIPTOR_BYTES: u64 = 1 << 20;

/// A directory or a zip archive holding an input's files.
pub(crate) enum TileStore {
    Dir(PathBuf),
    Zip(ZipStore),
}

/// What a path names in a store.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Kind {
    File,
    Dir,
}

/// One entry of a listed directory.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct Entry {
    pub name: String,
    pub kind: Kind,
}

impl TileStore {
    /// A store over the files under `root`.
    pub fn dir(root: &Path) -> TileStore {
        TileStore::Dir(root.to_path_buf())
    }

    /// Opens the zip archive at `path` and indexes its entries.
    pub fn zip(path: &Path) -> Result<TileStore> {
        Ok(TileStore::Zip(ZipStore::open(path)?))
    }

    /// A name for `rel` in errors: the file's path, or `archive.zip:inner/path`.
    pub fn name(&self, rel: &str) -> PathBuf {
        match self {
            TileStore::Dir(root) if rel.is_empty() => root.clone(),
            TileStore::Dir(root) => root.join(rel),
            TileStore::Zip(z) if rel.is_empty() => z.path.clone(),
            TileStore::Zip(z) => PathBuf::from(format!("{}:{rel}", z.path.display())),
        }
    }

    /// Whether `rel` is a file, a directory, or absent (`None`). In a zip, a directory is any
    /// prefix of an entry's name, whether or not the archive lists it.
    pub fn kind(&self, rel: &str) -> Option<Kind> {
        match self {
            TileStore::Dir(root) => {
                let meta = std::fs::metadata(root.join(rel)).ok()?;
                Some(if meta.is_dir() { Kind::Dir } else { Kind::File })
            }
            TileStore::Zip(z) => z.kind(rel),
        }
    }

    /// The entries of directory `rel` (`""` for the root), sorted by name.
    pub fn list(&self, rel: &str) -> Result<Vec<Entry>> {
        match self {
            TileStore::Dir(root) => {
                let dir = if rel.is_empty() { root.clone() } else { root.join(rel) };
                let mut out = Vec::new();
                for entry in std::fs::read_dir(&dir).map_err(|e| TilerError::io(&dir, e))? {
                    let entry = entry.map_err(|e| TilerError::io(&dir, e))?;
                    // Names that are not UTF-8 are no tile of any layout read here.
                    let Ok(name) = entry.file_name().into_string() else { continue };
                    // Followed like `Path::is_dir`: a link to a directory of tiles is one.
                    let kind = if entry.path().is_dir() { Kind::Dir } else { Kind::File };
                    out.push(Entry { name, kind });
                }
                out.sort_by(|a, b| a.name.cmp(&b.name));
                Ok(out)
            }
            TileStore::Zip(z) => z.list(rel),
        }
    }

    /// The bytes of file `rel`, or `None` if there is none; a file over `cap` bytes is an error
    /// before it is read.
    pub fn read(&self, rel: &str, cap: u64) -> Result<Option<Vec<u8>>> {
        match self {
            TileStore::Dir(root) => read_capped(&root.join(rel), cap),
            TileStore::Zip(z) => z.read(rel, cap),
        }
    }
}

impl TileStore {
    /// The first `n` bytes of file `rel` and the file's whole size (a zip entry's declared
    /// uncompressed size), or `None` if there is none: what a tile's header is read from
    /// without reading the tile.
    pub fn read_head(&self, rel: &str, n: u64) -> Result<Option<(Vec<u8>, u64)>> {
        let mut head = Vec::new();
        match self {
            TileStore::Dir(root) => {
                let path = root.join(rel);
                let Some(file) = open_regular(&path)? else { return Ok(None) };
                let len = file.metadata().map_err(|e| TilerError::io(&path, e))?.len();
                file.take(n).read_to_end(&mut head).map_err(|e| TilerError::io(&path, e))?;
                Ok(Some((head, len)))
            }
            TileStore::Zip(z) => {
                let Some(&index) = z.files.get(rel) else { return Ok(None) };
                let name = PathBuf::from(format!("{}:{rel}", z.path.display()));
                let mut archive = z.archive.clone();
                let entry = archive.by_index(index).map_err(|e| zip_error(&name, e))?;
                let len = entry.size();
                entry.take(n).read_to_end(&mut head).map_err(|e| zip_error(&name, e))?;
                Ok(Some((head, len)))
            }
        }
    }
}

/// `dir/name`, or `name` at the root: a path inside a store.
pub fn join(dir: &str, name: &str) -> String {
    if dir.is_empty() { name.to_string() } else { format!("{dir}/{name}") }
}

fn too_big(name: &Path, size: u64, cap: u64) -> TilerError {
    TilerError::unsupported(
        name,
        format!(
            "is {}, more than the {} a tile of this input (or a descriptor) can be",
            human_bytes(size),
            human_bytes(cap)
        ),
    )
}

/// Opens `path` for reading if it is a regular file, `None` if there is none. A FIFO, socket
/// or device is refused: reading one waits for a writer or never ends. It is opened
/// non-blocking (which a FIFO's open would otherwise wait for) and then checked, so nothing
/// swapped in between the check and the open can block either.
pub(crate) fn open_regular(path: &Path) -> Result<Option<File>> {
    use std::os::unix::fs::OpenOptionsExt;
    let file = match std::fs::OpenOptions::new().read(true).custom_flags(libc::O_NONBLOCK).open(path) {
        Ok(f) => f,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(TilerError::io(path, e)),
    };
    if !file.metadata().map_err(|e| TilerError::io(path, e))?.is_file() {
        return Err(TilerError::unsupported(
            path,
            "is not a regular file (a FIFO, socket, device or directory); tiles and descriptors are read from files",
        ));
    }
    Ok(Some(file))
}

/// Reads the file at `path` if it exists and has at most `cap` bytes.
pub(crate) fn read_capped(path: &Path, cap: u64) -> Result<Option<Vec<u8>>> {
    let Some(file) = open_regular(path)? else { return Ok(None) };
    let len = file.metadata().map_err(|e| TilerError::io(path, e))?.len();
    if len > cap {
        return Err(too_big(path, len, cap));
    }
    let mut bytes = Vec::with_capacity(len as usize);
    // The length read is capped too: the file may grow after its size was taken.
    file.take(cap + 1).read_to_end(&mut bytes).map_err(|e| TilerError::io(path, e))?;
    if bytes.len() as u64 > cap {
        return Err(too_big(path, bytes.len() as u64, cap));
    }
    Ok(Some(bytes))
}

/// A zip archive indexed by entry name.
pub(crate) struct ZipStore {
    path: PathBuf,
    /// Parsed once; each read clones it (the central directory is shared, the reader's position
    /// is not).
    archive: ZipArchive<SharedFile>,
    /// File entries (names without a trailing `/`) and their index in the archive.
    files: BTreeMap<String, usize>,
    /// Every directory: each proper prefix of an entry's name, and entries ending in `/`.
    dirs: BTreeMap<String, ()>,
}

impl ZipStore {
    fn open(path: &Path) -> Result<ZipStore> {
        let file = File::open(path).map_err(|e| TilerError::io(path, e))?;
        let len = file.metadata().map_err(|e| TilerError::io(path, e))?.len();
        let reader = SharedFile { file: Arc::new(file), pos: 0, len };
        let archive = ZipArchive::new(reader.clone()).map_err(|e| zip_error(path, e))?;
        if let Some(name) = duplicate_name(reader, archive.central_directory_start()).map_err(|e| zip_error(path, e))? {
            let name = String::from_utf8_lossy(&name).into_owned();
            return Err(TilerError::decode(path, format!("holds the entry \"{}\" twice", name.escape_debug())));
        }
        let mut files = BTreeMap::new();
        let mut dirs = BTreeMap::new();
        for index in 0..archive.len() {
            let raw = archive.name_for_index(index).ok_or_else(|| zip_error(path, "entry out of range"))?;
            let name = raw.map_err(|e| zip_error(path, e))?.into_owned();
            check_name(path, &name)?;
            let (name, is_dir) = match name.strip_suffix('/') {
                Some(dir) => (dir.to_string(), true),
                None => (name, false),
            };
            let mut at = 0;
            while let Some(i) = name[at..].find('/') {
                dirs.insert(name[..at + i].to_string(), ());
                at += i + 1;
            }
            if is_dir {
                dirs.insert(name, ());
            } else if files.insert(name.clone(), index).is_some() {
                return Err(TilerError::decode(path, format!("holds the entry {name} twice")));
            }
        }
        if let Some(both) = files.keys().find(|name| dirs.contains_key(*name)) {
            return Err(TilerError::decode(path, format!("holds {both} both as a file and as a directory")));
        }
        Ok(ZipStore { path: path.to_path_buf(), archive, files, dirs })
    }

    fn kind(&self, rel: &str) -> Option<Kind> {
        if rel.is_empty() || self.dirs.contains_key(rel) {
            Some(Kind::Dir)
        } else if self.files.contains_key(rel) {
            Some(Kind::File)
        } else {
            None
        }
    }

    fn list(&self, rel: &str) -> Result<Vec<Entry>> {
        if self.kind(rel) != Some(Kind::Dir) {
            return Err(TilerError::decode(
                PathBuf::from(format!("{}:{rel}", self.path.display())),
                "is no directory in the archive",
            ));
        }
        let prefix = if rel.is_empty() { String::new() } else { format!("{rel}/") };
        // Direct children only: names under the prefix without a further '/'.
        let children = |keys: &mut dyn Iterator<Item = &String>, kind: Kind| -> Vec<Entry> {
            keys.take_while(|k| k.starts_with(&prefix))
                .map(|k| &k[prefix.len()..])
                .filter(|rest| !rest.is_empty() && !rest.contains('/'))
                .map(|name| Entry { name: name.to_string(), kind })
                .collect()
        };
        let mut out = children(&mut self.files.range(prefix.clone()..).map(|(k, _)| k), Kind::File);
        out.extend(children(&mut self.dirs.range(prefix.clone()..).map(|(k, _)| k), Kind::Dir));
        out.sort_by(|a, b| a.name.cmp(&b.name));
        Ok(out)
    }

    fn read(&self, rel: &str, cap: u64) -> Result<Option<Vec<u8>>> {
        let Some(&index) = self.files.get(rel) else { return Ok(None) };
        let name = PathBuf::from(format!("{}:{rel}", self.path.display()));
        let mut archive = self.archive.clone();
        let entry = archive.by_index(index).map_err(|e| zip_error(&name, e))?;
        if entry.size() > cap {
            return Err(too_big(&name, entry.size(), cap));
        }
        let mut bytes = Vec::with_capacity(entry.size() as usize);
        // Capped as it inflates too: the stored size is only a claim.
        entry.take(cap + 1).read_to_end(&mut bytes).map_err(|e| zip_error(&name, e))?;
        if bytes.len() as u64 > cap {
            return Err(too_big(&name, bytes.len() as u64, cap));
        }
        Ok(Some(bytes))
    }
}

/// The first name the central directory at `start` lists twice. The zip crate indexes entries
/// by name and keeps the last of a name, so two tiles of one name would be read as one with
/// no word said; this walks the directory's headers (46 bytes and the name, extra field and
/// comment each) to find them.
fn duplicate_name(reader: SharedFile, start: u64) -> std::io::Result<Option<Vec<u8>>> {
    let mut reader = std::io::BufReader::new(reader);
    reader.seek(SeekFrom::Start(start))?;
    let mut seen = std::collections::HashSet::new();
    let mut header = [0u8; 46];
    loop {
        match reader.read_exact(&mut header) {
            Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => return Ok(None),
            other => other?,
        }
        if header[..4] != *b"PK\x01\x02" {
            return Ok(None);
        }
        let field = |at: usize| u16::from_le_bytes([header[at], header[at + 1]]);
        let mut name = vec![0u8; field(28) as usize];
        reader.read_exact(&mut name)?;
        reader.seek_relative(field(30) as i64 + field(32) as i64)?;
        if !seen.insert(name.clone()) {
            return Ok(Some(name));
        }
    }
}

/// Refuses entry names that would leave the archive's root if extracted (`..`, absolute
/// paths, drive letters), or that are not plain `/`-separated names: no layout read here makes
/// them, so an archive holding one was not written by a tiler.
fn check_name(archive: &Path, name: &str) -> Result<()> {
    let bad = |why: &str| TilerError::decode(archive, format!("entry \"{}\" {why}", name.escape_debug()));
    if name.starts_with('/') || name.starts_with('\\') || name.as_bytes().get(1) == Some(&b':') {
        return Err(bad("is an absolute path"));
    }
    if name.split(['/', '\\']).any(|part| part == "..") {
        return Err(bad("leaves the archive's root ('..')"));
    }
    if name.contains('\\') || name.contains('\0') {
        return Err(bad("holds a backslash or a NUL"));
    }
    Ok(())
}

fn zip_error(path: &Path, e: impl std::fmt::Display) -> TilerError {
    TilerError::decode(path, format!("not a readable zip archive: {e}"))
}

/// A reader over a shared open file with its own position: positioned reads (pread), so that
/// clones read at once from many threads without a lock or a shared seek offset.
#[derive(Clone)]
struct SharedFile {
    file: Arc<File>,
    pos: u64,
    len: u64,
}

impl Read for SharedFile {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = read_at(&self.file, buf, self.pos)?;
        self.pos += n as u64;
        Ok(n)
    }
}

impl Seek for SharedFile {
    fn seek(&mut self, to: SeekFrom) -> std::io::Result<u64> {
        let pos = match to {
            SeekFrom::Start(p) => Some(p),
            SeekFrom::End(d) => self.len.checked_add_signed(d),
            SeekFrom::Current(d) => self.pos.checked_add_signed(d),
        };
        self.pos = pos.ok_or_else(|| std::io::Error::new(std::io::ErrorKind::InvalidInput, "seek before the start"))?;
        Ok(self.pos)
    }
}

#[cfg(unix)]
fn read_at(file: &File, buf: &mut [u8], pos: u64) -> std::io::Result<usize> {
    std::os::unix::fs::FileExt::read_at(file, buf, pos)
}

#[cfg(windows)]
fn read_at(file: &File, buf: &mut [u8], pos: u64) -> std::io::Result<usize> {
    std::os::windows::fs::FileExt::seek_read(file, buf, pos)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use std::io::Write;
    use zip::write::SimpleFileOptions;

    /// Writes a zip of `(name, bytes)` entries, deflated where `deflate` says.
    pub(crate) fn write_zip(path: &Path, entries: &[(&str, &[u8])], deflate: bool) {
        let mut w = zip::ZipWriter::new(File::create(path).unwrap());
        let method = if deflate { zip::CompressionMethod::Deflated } else { zip::CompressionMethod::Stored };
        for (name, bytes) in entries {
            if let Some(dir) = name.strip_suffix('/') {
                w.add_directory(dir, SimpleFileOptions::default()).unwrap();
            } else {
                w.start_file(*name, SimpleFileOptions::default().compression_method(method)).unwrap();
                w.write_all(bytes).unwrap();
            }
        }
        w.finish().unwrap();
    }

    fn names(entries: Vec<Entry>) -> Vec<(String, Kind)> {
        entries.into_iter().map(|e| (e.name, e.kind)).collect()
    }

    #[test]
    fn a_zip_lists_and_reads_like_a_directory() {
        let tmp = tempfile::tempdir().unwrap();
        let files: [(&str, &[u8]); 4] =
            [("g/2/0/0.png", b"a"), ("g/2/0/1.png", b"bb"), ("g/2/1/0.png", b"ccc"), ("g/blank.png", b"d")];
        let dir = tmp.path().join("dir");
        for (name, bytes) in files {
            let p = dir.join(name);
            std::fs::create_dir_all(p.parent().unwrap()).unwrap();
            std::fs::write(p, bytes).unwrap();
        }
        for deflate in [false, true] {
            let zip = tmp.path().join(format!("t{deflate}.zip"));
            write_zip(&zip, &files, deflate);
            for store in [TileStore::dir(&dir), TileStore::zip(&zip).unwrap()] {
                assert_eq!(
                    names(store.list("").unwrap()),
                    [("g".to_string(), Kind::Dir)],
                    "{}",
                    store.name("").display()
                );
                assert_eq!(
                    names(store.list("g").unwrap()),
                    [("2".to_string(), Kind::Dir), ("blank.png".to_string(), Kind::File)]
                );
                assert_eq!(names(store.list("g/2").unwrap()).len(), 2);
                assert_eq!(store.kind("g/2/1"), Some(Kind::Dir));
                assert_eq!(store.kind("g/2/1/0.png"), Some(Kind::File));
                assert_eq!(store.kind("g/2/1/9.png"), None);
                assert_eq!(store.read("g/2/1/0.png", 10).unwrap().unwrap(), b"ccc");
                assert_eq!(store.read("g/2/1/9.png", 10).unwrap(), None);
                let e = store.read("g/2/1/0.png", 2).unwrap_err().to_string();
                assert!(e.contains("g/2/1/0.png") && e.contains("more than"), "{e}");
            }
        }
        let store = TileStore::zip(&tmp.path().join("tfalse.zip")).unwrap();
        assert!(store.name("g/2/0/0.png").to_string_lossy().ends_with("tfalse.zip:g/2/0/0.png"));
    }

    #[test]
    fn reads_from_many_threads_at_once() {
        use rayon::prelude::*;
        let tmp = tempfile::tempdir().unwrap();
        let blobs: Vec<(String, Vec<u8>)> = (0..64u32)
            .map(|i| (format!("t/{i}.bin"), crate::source::tiled::noise(1000 + i as usize * 37, i)))
            .collect();
        let entries: Vec<(&str, &[u8])> = blobs.iter().map(|(n, b)| (n.as_str(), b.as_slice())).collect();
        let zip = tmp.path().join("a.zip");
        write_zip(&zip, &entries, true);
        let store = TileStore::zip(&zip).unwrap();
        (0..640usize).into_par_iter().for_each(|i| {
            let (name, bytes) = &blobs[i % 64];
            assert!(store.read(name, 1 << 20).unwrap().unwrap() == *bytes, "{name}");
        });
    }

    #[test]
    fn hostile_entry_names_are_refused() {
        let tmp = tempfile::tempdir().unwrap();
        let cases = [
            ("../evil.png", "'..'"),
            ("a/../../evil.png", "'..'"),
            ("/etc/passwd", "absolute"),
            ("C:/x.png", "absolute"),
            ("a\\b.png", "backslash"),
        ];
        for (name, expected) in cases {
            let zip = tmp.path().join("h.zip");
            // The writer refuses some names itself; write them raw through a stored entry.
            let mut w = zip::ZipWriter::new(File::create(&zip).unwrap());
            w.start_file("ok.png", SimpleFileOptions::default()).unwrap();
            w.write_all(b"x").unwrap();
            w.start_file(name, SimpleFileOptions::default()).unwrap();
            w.write_all(b"x").unwrap();
            w.finish().unwrap();
            let e = TileStore::zip(&zip).err().expect("refused").to_string();
            assert!(e.contains("h.zip") && e.contains(expected), "{name}: {e}");
        }
    }

    #[test]
    fn duplicate_entry_names_are_refused() {
        // The writer refuses a second entry of a name; write two names of one length, then make
        // the second the first's in the central directory (and its local header).
        let tmp = tempfile::tempdir().unwrap();
        let zip = tmp.path().join("dup.zip");
        write_zip(&zip, &[("t/0_0.png", b"first"), ("t/0_1.png", b"second"), ("t/1_0.png", b"x")], false);
        let mut bytes = std::fs::read(&zip).unwrap();
        while let Some(at) = bytes.windows(9).position(|w| w == b"t/0_1.png") {
            bytes[at..at + 9].copy_from_slice(b"t/0_0.png");
        }
        std::fs::write(&zip, bytes).unwrap();
        let e = TileStore::zip(&zip).err().expect("refused").to_string();
        assert!(e.contains("dup.zip") && e.contains("\"t/0_0.png\" twice"), "{e}");
    }

    #[test]
    fn broken_archives_name_the_file() {
        let tmp = tempfile::tempdir().unwrap();
        let zip = tmp.path().join("broken.zip");
        std::fs::write(&zip, b"PK\x03\x04 not really").unwrap();
        let e = TileStore::zip(&zip).err().unwrap().to_string();
        assert!(e.contains("broken.zip") && e.contains("zip"), "{e}");
        let e = TileStore::zip(&tmp.path().join("none.zip")).err().unwrap().to_string();
        assert!(e.contains("none.zip"), "{e}");
    }

    #[test]
    fn an_oversized_entry_is_refused_before_it_is_read() {
        let tmp = tempfile::tempdir().unwrap();
        let zip = tmp.path().join("big.zip");
        let zeros = vec![0u8; 1 << 20];
        write_zip(&zip, &[("big.png", &zeros)], true);
        let store = TileStore::zip(&zip).unwrap();
        let e = store.read("big.png", 1000).unwrap_err().to_string();
        assert!(e.contains("big.zip:big.png") && e.contains("1.0 MiB"), "{e}");
    }
}
