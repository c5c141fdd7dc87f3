//! A cheap fingerprint of an input, so that `merge` can tell shards cut from different inputs.
//!
//! Hashing the whole input in every shard would read it N times over (a 16384^2 TIFF is
//! 800 MB), so a file is fingerprinted by its length and a sample of its bytes: the first and
//! last 1 MiB and 64 blocks of 64 KiB spread evenly between them (6 MiB at most, a CRC-32C per
//! block: a few milliseconds); a directory of tiles (`convert`) by the name and length of
//! every file in it. That tells a
//! different or re-exported image from the right one; it is not proof against an edit of a
//! few bytes between the samples, and `merge` says so.

use std::fs::File;
use std::hash::Hasher;
use std::io::{Read, Seek, SeekFrom};
use std::path::Path;

use crate::error::{Result, TilerError};
use crate::fnv::Fnv;

const ENDS: u64 = 1 << 20;
const BLOCKS: u64 = 64;
const BLOCK: u64 = 64 << 10;

/// `len-hash`, both hexadecimal, of the file or directory at `path`.
pub fn fingerprint(path: &Path) -> Result<String> {
    let meta = std::fs::metadata(path).map_err(|e| TilerError::io(path, e))?;
    let mut hash = Fnv::default();
    let len =
        if meta.is_dir() { directory(path, Path::new(""), &mut hash)? } else { file(path, meta.len(), &mut hash)? };
    Ok(format!("{len:x}-{:016x}", hash.finish()))
}

fn file(path: &Path, len: u64, hash: &mut Fnv) -> Result<u64> {
    let mut f = File::open(path).map_err(|e| TilerError::io(path, e))?;
    let mut buf = Vec::new();
    // CRC-32C runs at memory speed; the block's CRC goes into the hash.
    let mut read = |at: u64, n: u64, hash: &mut Fnv| -> std::io::Result<()> {
        buf.resize(n.min(len.saturating_sub(at)) as usize, 0);
        f.seek(SeekFrom::Start(at))?;
        f.read_exact(&mut buf)?;
        hash.write(&crc32c::crc32c(&buf).to_le_bytes());
        Ok(())
    };
    let mut sampled = || -> std::io::Result<()> {
        if len <= 2 * ENDS + BLOCKS * BLOCK {
            return read(0, len, hash);
        }
        read(0, ENDS, hash)?;
        let step = (len - 2 * ENDS) / BLOCKS;
        for i in 0..BLOCKS {
            read(ENDS + i * step, BLOCK, hash)?;
        }
        read(len - ENDS, ENDS, hash)
    };
    sampled().map_err(|e| TilerError::io(path, e))?;
    Ok(len)
}

/// Names (relative to the top, in sorted order) and lengths of every file below `dir`; the
/// total length.
fn directory(dir: &Path, rel: &Path, hash: &mut Fnv) -> Result<u64> {
    let here = dir.join(rel);
    let mut entries: Vec<_> = std::fs::read_dir(&here)
        .map_err(|e| TilerError::io(&here, e))?
        .collect::<std::io::Result<_>>()
        .map_err(|e| TilerError::io(&here, e))?;
    entries.sort_by_key(|e| e.file_name());
    let mut total = 0u64;
    for entry in entries {
        let name = rel.join(entry.file_name());
        let meta = entry.metadata().map_err(|e| TilerError::io(entry.path(), e))?;
        if meta.is_dir() {
            total += directory(dir, &name, hash)?;
        } else {
            hash.write(name.to_string_lossy().as_bytes());
            hash.write(&meta.len().to_le_bytes());
            total += meta.len();
        }
    }
    Ok(total)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_changed_byte_in_a_sampled_block_or_a_new_length_changes_it() {
        let dir = std::env::temp_dir().join(format!("vortex-fp-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("big.bin");
        let mut bytes = vec![7u8; (3 << 20) + 12345];
        std::fs::write(&path, &bytes).unwrap();
        let first = fingerprint(&path).unwrap();
        assert_eq!(fingerprint(&path).unwrap(), first);
        bytes[ENDS as usize + 5] = 8;
        std::fs::write(&path, &bytes).unwrap();
        assert_ne!(fingerprint(&path).unwrap(), first);
        bytes.push(0);
        std::fs::write(&path, &bytes).unwrap();
        assert!(fingerprint(&path).unwrap().starts_with(&format!("{:x}-", bytes.len())));
        assert_ne!(fingerprint(&dir).unwrap(), fingerprint(&path).unwrap());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
