//! Decoding the source on a thread of its own, ahead of the pyramid: a JPEG or PNG source costs
//! as much CPU as the pyramid built from it, and one thread doing both left a core idle while the
//! encoders waited for tiles (issue 18). `rows` reads exactly the rows a pass asks for, in
//! chunks of about [`CHUNK_BYTES`], a few chunks ahead of the caller, and hands them over in
//! order: the rows, and so the output, are the same as read on the caller's thread, and the
//! source is left at the same position. With chunks of 0 rows it reads on the caller's thread
//! (runs short of memory: striped ones). `chunks` hands the chunks themselves over, for a
//! caller that passes them on to another thread; a `Chunk` goes back to the reader when it is
//! dropped, wherever that is. What the source decoded in tasks on the pool meanwhile (a JPEG
//! TIFF's next band) goes to the `decode` stage.

use std::sync::mpsc::{Sender, channel, sync_channel};

use crate::error::{Result, TilerError};
use crate::limits::Part;
use crate::source::{Decoding, RowSource};
use crate::stages::{Stage, StageClock};

use crate::limits::read_ahead::CHUNKS_AHEAD;
pub use crate::limits::read_ahead::CHUNKS_HANDED_ON;

/// Rows read ahead, in order; dropping it gives its memory back to the reader.
pub(crate) struct Chunk<T> {
    rows: Vec<T>,
    back: Sender<Vec<T>>,
}

impl<T> Chunk<T> {
    /// The chunk's rows, one after the other.
    pub fn rows(&self) -> &[T] {
        &self.rows
    }
}

impl<T> Drop for Chunk<T> {
    fn drop(&mut self) {
        // The reader may be gone already: then nobody needs the buffer.
        let _ = self.back.send(std::mem::take(&mut self.rows));
    }
}

/// Reads the next `count` rows of `row_len` samples from `source` on another thread, in chunks
/// of `chunk_rows` (0: on this thread, one row at a time), and calls `each` with every row, in
/// order, on this one. Stops at the first error of either side (the
/// reader then stops after at most the chunk it is reading). The reader's time goes to
/// [`Stage::Read`], the caller's waits for rows to [`Stage::ReadWait`], the source's decoding
/// on the pool to [`Stage::Decode`].
pub(crate) fn rows<T: bytemuck::Pod + Send>(
    source: &mut dyn RowSource,
    count: u64,
    row_len: usize,
    chunk_rows: u64,
    clock: &StageClock,
    mut each: impl FnMut(&[T]) -> Result<()>,
) -> Result<()> {
    if chunk_rows == 0 {
        let mut row = vec![T::zeroed(); row_len];
        let row_bytes = (row_len * size_of::<T>()) as i64;
        clock.memory.add(Part::ReadAhead, row_bytes);
        let decoded = source.decoding();
        let result = (0..count).try_for_each(|_| {
            // Read on this thread: the caller waits for every row.
            clock.time_all(&[Stage::Read, Stage::ReadWait], || source.read_row(bytemuck::cast_slice_mut(&mut row)))?;
            clock.memory.set(Part::Decoder, source.buffer_bytes());
            each(&row)
        });
        count_decoding(clock, source, decoded);
        clock.memory.add(Part::ReadAhead, -row_bytes);
        return result;
    }
    chunks(source, count, row_len, chunk_rows, clock, |chunk: Chunk<T>| {
        chunk.rows().chunks_exact(row_len).try_for_each(&mut each)
    })
}

/// As [`rows`] with chunks of `chunk_rows > 0` rows, handing `each` every chunk whole.
pub(crate) fn chunks<T: bytemuck::Pod + Send>(
    source: &mut dyn RowSource,
    count: u64,
    row_len: usize,
    chunk_rows: u64,
    clock: &StageClock,
    mut each: impl FnMut(Chunk<T>) -> Result<()>,
) -> Result<()> {
    let per_chunk = chunk_rows.max(1);
    let (full_tx, full_rx) = sync_channel::<Result<Vec<T>>>(CHUNKS_AHEAD);
    let (empty_tx, empty_rx) = channel::<Vec<T>>();
    std::thread::scope(|scope| {
        // Returns the bytes of chunks it allocated: all of them live until the pass ends (a chunk
        // comes back to be read into again).
        let reader = std::thread::Builder::new().name("vortex-read".into()).spawn_scoped(scope, move || {
            let (mut left, mut allocated) = (count, 0);
            let decoded = source.decoding();
            while left > 0 {
                let n = left.min(per_chunk);
                // A chunk the caller has finished with, or a new one.
                let mut chunk = empty_rx.try_recv().unwrap_or_default();
                let had = chunk.capacity();
                chunk.resize(n as usize * row_len, T::zeroed());
                let grown = ((chunk.capacity() - had) * size_of::<T>()) as i64;
                clock.memory.add(Part::ReadAhead, grown);
                allocated += grown;
                let read = clock.time(Stage::Read, || {
                    chunk.chunks_exact_mut(row_len).try_for_each(|row| source.read_row(bytemuck::cast_slice_mut(row)))
                });
                clock.memory.set(Part::Decoder, source.buffer_bytes());
                let failed = read.is_err();
                // The caller has stopped if it hung up.
                if full_tx.send(read.map(|()| chunk)).is_err() || failed {
                    break;
                }
                left -= n;
            }
            count_decoding(clock, source, decoded);
            allocated
        });
        let reader =
            reader.map_err(|e| TilerError::Internal(format!("cannot start the source's reading thread: {e}")))?;
        let mut used = Ok(());
        while let Ok(chunk) = clock.time(Stage::ReadWait, || full_rx.recv()) {
            used = chunk.and_then(|rows| each(Chunk { rows, back: empty_tx.clone() }));
            if used.is_err() {
                break;
            }
        }
        // A reader blocked on a full queue sees the hang-up and stops.
        drop(full_rx);
        let allocated = reader.join().unwrap_or_else(|panic| std::panic::resume_unwind(panic));
        clock.memory.add(Part::ReadAhead, -allocated);
        used
    })
}

/// Adds what `source` decoded on the pool since `before` to [`Stage::Decode`]: the tasks' CPU
/// time, and their wall time over the pool's threads (as the encoders' is).
fn count_decoding(clock: &StageClock, source: &dyn RowSource, before: Decoding) {
    let decoded = source.decoding().since(before);
    if decoded != Decoding::default() {
        clock.add(Stage::Decode, decoded.wall / rayon::current_num_threads().max(1) as u32);
        clock.add_cpu(Stage::Decode, decoded.cpu);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::limits::read_ahead::{CHUNK_BYTES, bytes, rows_per_chunk};
    use crate::pixel::{Channels, Depth, PixelLayout};
    use crate::source::ImageHeader;

    /// Rows whose every byte is the row number; fails at row `fail_at`.
    struct Counting {
        width: u32,
        next: u32,
        fail_at: u32,
    }

    impl RowSource for Counting {
        fn header(&self) -> ImageHeader {
            ImageHeader { width: self.width, height: 1000, layout: PixelLayout::new(Channels::Rgb, Depth::U8) }
        }
        fn read_row(&mut self, row: &mut [u8]) -> Result<()> {
            if self.next == self.fail_at {
                return Err(TilerError::Options(format!("row {} is bad", self.next)));
            }
            row.fill(self.next as u8);
            self.next += 1;
            Ok(())
        }
        fn describe(&self) -> String {
            "counting".into()
        }
    }

    #[test]
    fn rows_come_in_order_and_the_source_stops_where_asked() {
        // Rows of 3 MiB: one per chunk; rows of 30 bytes: thousands per chunk.
        for width in [1 << 20, 10] {
            let clock = StageClock::default();
            // On this thread too.
            for chunk in [rows_per_chunk(width as u64 * 3), 0] {
                let mut source = Counting { width, next: 5, fail_at: u32::MAX };
                let mut seen = Vec::new();
                rows::<u8>(&mut source, 7, width as usize * 3, chunk, &clock, |row| {
                    assert!(row.iter().all(|&b| b == row[0]));
                    seen.push(row[0]);
                    Ok(())
                })
                .unwrap();
                assert_eq!(seen, [5, 6, 7, 8, 9, 10, 11]);
                assert_eq!(source.next, 12, "no row read past the pass");
            }
        }
    }

    #[test]
    fn errors_on_either_side_stop_both() {
        let mut source = Counting { width: 10, next: 0, fail_at: 3 };
        let clock = StageClock::default();
        let mut seen = 0;
        let e = rows::<u8>(&mut source, 100, 30, 16, &clock, |_| {
            seen += 1;
            Ok(())
        })
        .unwrap_err();
        assert!(e.to_string().contains("row 3 is bad"), "{e}");
        assert_eq!(seen, 0, "the failed chunk is not handed over");

        let mut source = Counting { width: 1 << 20, next: 0, fail_at: u32::MAX };
        let e = rows::<u8>(&mut source, 100, 3 << 20, 1, &clock, |row| match row[0] {
            2 => Err(TilerError::Interrupted),
            _ => Ok(()),
        })
        .unwrap_err();
        assert!(matches!(e, TilerError::Interrupted));
        assert!(source.next <= 3 + CHUNKS_AHEAD as u32 + 1, "the reader stopped soon after: {}", source.next);
    }

    #[test]
    fn sixteen_bit_rows_keep_their_samples() {
        let mut source = Counting { width: 4, next: 1, fail_at: u32::MAX };
        let clock = StageClock::default();
        let mut rows_seen = Vec::new();
        rows::<u16>(&mut source, 2, 6, 1, &clock, |row| {
            rows_seen.push(row.to_vec());
            Ok(())
        })
        .unwrap();
        assert_eq!(rows_seen, [vec![0x0101u16; 6], vec![0x0202; 6]]);
        assert_eq!(rows_per_chunk(12), CHUNK_BYTES / 12);
        let held = CHUNKS_AHEAD as u64 + 2 + CHUNKS_HANDED_ON;
        // One row a chunk when a row is over a chunk, and the sums made of those handed on.
        assert!(bytes(3 << 20, 3) > held * (3 << 20), "{}", bytes(3 << 20, 3));
    }
}
