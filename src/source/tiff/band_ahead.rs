//! The next band of a tiled or stripped source decoded on the rayon pool while the reader
//! hands out the rows of this one (issue 45).
//!
//! A JPEG TIFF's reader decodes a band (a row of tiles, a group of strips) only when its first
//! row is asked for, and the rows read ahead (`source::read_ahead`) are a few dozen of the
//! band's hundreds: while a band was decoded the pyramid soon had no rows, and while the
//! pyramid took the band's rows nothing was decoded, so the encoders waited on both in turn.
//! With the next band decoding beside the pyramid, both cores have work. It costs a second
//! band of decoded texels, which the source counts in `most_buffer_bytes` before anything is
//! allocated; the bytes are the same, since each chunk is decoded alone into its own buffer.
//!
//! A band is named by a key (its first chunk row and the chunk columns decoded): one that is
//! not the band asked for next (a seek, other columns) is waited for and its buffers reused.

use std::ops::Range;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::mpsc::{Receiver, sync_channel};

/// Which chunks a band holds: its first chunk row (and image row) and the chunk columns decoded.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(super) struct Key {
    pub first_chunk_row: u32,
    pub first_row: u64,
    pub columns: Range<u32>,
}

/// A band's decoded chunks, or the image row where the first failed chunk starts and why.
pub(super) type Decoded = (Vec<Vec<u8>>, Result<(), (u64, String)>);

/// At most one band decoding on the pool.
#[derive(Default)]
pub(super) struct BandAhead {
    pending: Option<Pending>,
}

struct Pending {
    key: Key,
    /// The capacity of its buffers, sized before it started.
    bytes: u64,
    done: Receiver<Decoded>,
}

impl BandAhead {
    /// Whether a band can be decoded ahead on this thread: not on one of the pool's threads,
    /// whose wait for it could hold up the very thread that would decode it.
    pub fn possible() -> bool {
        rayon::current_thread_index().is_none()
    }

    /// Starts `decode` on `buffers` (already sized: `bytes` of capacity) for the band `key` on
    /// the pool. A band still pending is waited for first and dropped.
    pub fn start(
        &mut self,
        key: Key,
        mut buffers: Vec<Vec<u8>>,
        bytes: u64,
        decode: impl FnOnce(&mut [Vec<u8>]) -> Result<(), (u64, String)> + Send + 'static,
    ) {
        drop(self.wait());
        let (send, done) = sync_channel(1);
        let first_row = key.first_row;
        rayon::spawn(move || {
            // A panic on the pool would end the process: it is the band's error instead.
            let decoded = catch_unwind(AssertUnwindSafe(|| decode(&mut buffers)));
            let result = decoded.unwrap_or_else(|_| Err((first_row, "internal: its decoding panicked".into())));
            // The reader may have gone; then nobody needs the band.
            let _ = send.send((buffers, result));
        });
        self.pending = Some(Pending { key, bytes, done });
    }

    /// The band `key` if it is the one pending, once decoded; otherwise `Err` with the
    /// buffers of whatever was pending (waited for), to reuse.
    pub fn take(&mut self, key: &Key) -> Result<Decoded, Vec<Vec<u8>>> {
        let matches = self.pending.as_ref().is_some_and(|p| p.key == *key);
        match (self.wait(), matches) {
            (Some(decoded), true) => Ok(decoded),
            (decoded, _) => Err(decoded.map(|(buffers, _)| buffers).unwrap_or_default()),
        }
    }

    /// Bytes of the pending band's buffers.
    pub fn bytes(&self) -> u64 {
        self.pending.as_ref().map_or(0, |p| p.bytes)
    }

    /// Waits for the pending band, if any.
    fn wait(&mut self) -> Option<Decoded> {
        self.pending.take().and_then(|p| p.done.recv().ok())
    }
}

impl Drop for BandAhead {
    /// Waits for the band being decoded, so that its memory is given back with the source's.
    fn drop(&mut self) {
        drop(self.wait());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn key(row: u32) -> Key {
        Key { first_chunk_row: row, first_row: row as u64 * 8, columns: 0..2 }
    }

    #[test]
    fn the_band_started_is_the_band_taken_and_another_gives_its_buffers_back() {
        let mut ahead = BandAhead::default();
        assert!(BandAhead::possible());
        ahead.start(key(3), vec![vec![0; 4]; 2], 8, |band| {
            band.iter_mut().for_each(|chunk| chunk.fill(3));
            Ok(())
        });
        assert_eq!(ahead.bytes(), 8);
        let (band, result) = ahead.take(&key(3)).unwrap();
        assert_eq!((band, result), (vec![vec![3; 4]; 2], Ok(())));
        assert_eq!(ahead.bytes(), 0);

        ahead.start(key(4), vec![vec![0; 4]; 2], 8, |_| Err((99, "broken".into())));
        let spare = ahead.take(&key(5)).unwrap_err();
        assert_eq!(spare.len(), 2, "the buffers of the band not asked for come back");
        assert!(ahead.take(&key(4)).unwrap_err().is_empty(), "nothing pending");

        ahead.start(key(4), vec![Vec::new()], 0, |_| Err((99, "broken".into())));
        assert_eq!(ahead.take(&key(4)).unwrap().1, Err((99, "broken".to_string())));
        ahead.start(key(6), vec![Vec::new()], 0, |_| panic!("a decoder's bug"));
        assert_eq!(ahead.take(&key(6)).unwrap().1, Err((48, "internal: its decoding panicked".to_string())));
    }
}
