//! Compressed strips decoded ahead of the reader, several at once, handed over in pieces.
//!
//! Inflating a Deflate or LZW strip is one thread's work, and one thread decoding strip after
//! strip bound a whole `split` of such a TIFF: 3.5 s (Deflate) and 6 s (LZW) of a 16384² run
//! spent on one core while the other waited (issue 18). Strips are independent, so workers,
//! each with a decoder of its own on the same file, decode strip `s` on worker `s % workers`
//! and the reader takes them in order. The bytes are what one decoder would give, so nothing
//! downstream can tell.
//!
//! A decoder that can stop inside a strip (Deflate is a stream) hands a strip over in pieces of
//! a few rows as it decodes them, and the reader copies rows out of each piece while the rest
//! is decoded: of the strip the reader is at, only a piece or two are held, not the whole strip
//! three times over (the one read from and one being decoded ahead on each worker: 18 MiB of a
//! 16384-texel RGB TIFF in 128-row strips; issue 28). Each other worker may still decode one
//! whole strip ahead of the reader, which is what keeps them busy: the reader reaches worker B's
//! strip only once worker A's is done, and B decoded it meanwhile. When the reader stops taking
//! (the pyramid waits for the encoders), the workers together stop at that much and a few
//! pieces ([`bytes_at_most`]), not at a whole strip each.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, sync_channel};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;

/// Strips' worth of rows each worker decodes ahead of the reader: one keeps every worker busy
/// while the reader takes rows as fast as they come, and holds the least memory.
pub const AHEAD_PER_WORKER: u64 = 1;

/// Bytes of one piece, where a decoder can stop inside a strip (at least one row): small next
/// to a strip (6 MiB of 128 rows of 16384 RGB texels), large enough that handing pieces over
/// costs nothing next to decoding them.
pub const PIECE_BYTES: u64 = 256 << 10;

/// A strip decoder for one worker: [`begin`](Self::begin) a strip, then
/// [`fill`](Self::fill) buffers with its bytes in order, whole rows each.
pub trait StripDecoder: Send {
    fn begin(&mut self, strip: u32) -> Result<(), String>;
    fn fill(&mut self, out: &mut [u8]) -> Result<(), String>;
    /// Bytes the decoder holds of its own between pieces (an LZW window), beyond the pieces.
    fn held_bytes(&self) -> u64 {
        0
    }
}

/// How the strips are cut: the image's rows, rows per strip and per piece, bytes per row.
#[derive(Clone, Copy, Debug)]
pub struct Shape {
    pub height: u64,
    pub strip_rows: u64,
    /// Rows per piece: `strip_rows` where the decoder can only decode a strip whole.
    pub piece_rows: u64,
    pub row_bytes: u64,
}

impl Shape {
    /// Pieces of one whole strip.
    fn pieces_per_strip(&self) -> u64 {
        self.strip_rows.div_ceil(self.piece_rows.max(1))
    }

    /// Rows of a piece for a decoder that stops inside a strip: [`PIECE_BYTES`] of them, at
    /// least one, at most a strip's.
    pub fn rows_per_piece(row_bytes: u64, strip_rows: u64) -> u64 {
        (PIECE_BYTES / row_bytes.max(1)).clamp(1, strip_rows.max(1))
    }
}

/// Pieces the workers may hold together, decoded or being decoded: a strip's worth
/// ([`AHEAD_PER_WORKER`]) on each worker but the one the reader waits for, and two pieces on
/// each (one queued, one being decoded), or a strip's worth on each if that is less (whole
/// strips). Never less than the others' whole strips and one piece, so the worker the reader
/// waits for always has room.
fn pieces_at_most(shape: &Shape, workers: u64) -> u64 {
    let per_worker = AHEAD_PER_WORKER.saturating_mul(shape.pieces_per_strip());
    let others = workers.saturating_sub(1).saturating_mul(per_worker);
    workers.saturating_mul(per_worker).min(others.saturating_add(2 * workers))
}

/// Bytes of pieces [`StripsAhead`] holds at most with `workers` workers: those the workers hold
/// ([`pieces_at_most`]) and the one the reader holds. Where pieces are whole strips: the strips
/// being decoded and the one taken.
pub fn bytes_at_most(shape: &Shape, workers: u64) -> u64 {
    let piece = shape.piece_rows.min(shape.strip_rows).saturating_mul(shape.row_bytes);
    pieces_at_most(shape, workers).saturating_add(1).saturating_mul(piece)
}

/// A piece: its first image row and its rows, or why its strip failed.
type Piece = (u64, Result<Vec<u8>, String>);

/// Buffers for pieces, shared by the workers and the reader, and what they hold in all.
struct Pool {
    spare: Mutex<Vec<Vec<u8>>>,
    /// Bytes of every buffer on this side: spare, queued or being decoded (not the reader's).
    held: AtomicU64,
    /// Pieces the workers may still begin ([`pieces_at_most`] less those decoded or being
    /// decoded and not taken), and whether the reader has gone.
    room: Mutex<(u64, bool)>,
    taken: Condvar,
}

impl Pool {
    /// Waits for room for one more piece; `false` once the reader has gone.
    fn reserve(&self) -> bool {
        let Ok(mut room) = self.room.lock() else { return false };
        while room.0 == 0 && !room.1 {
            room = match self.taken.wait(room) {
                Ok(room) => room,
                Err(_) => return false,
            };
        }
        if room.1 {
            return false;
        }
        room.0 -= 1;
        true
    }

    /// A piece taken (`stop`: the reader gone): room for another.
    fn release(&self, stop: bool) {
        if let Ok(mut room) = self.room.lock() {
            room.0 += 1;
            room.1 |= stop;
        }
        self.taken.notify_all();
    }

    /// A spare buffer of `len` bytes, or a new one.
    fn take(&self, len: usize) -> Vec<u8> {
        let spare = self.spare.lock().map(|mut s| s.pop()).unwrap_or_default();
        let mut buffer = spare.unwrap_or_default();
        let had = buffer.capacity();
        // Exactly: a short last piece's buffer grown by doubling would outgrow the bound.
        buffer.clear();
        buffer.reserve_exact(len);
        buffer.resize(len, 0);
        self.held.fetch_add((buffer.capacity() - had) as u64, Ordering::Relaxed);
        buffer
    }

    fn give(&self, buffer: Vec<u8>) {
        self.held.fetch_add(buffer.capacity() as u64, Ordering::Relaxed);
        if let Ok(mut spare) = self.spare.lock() {
            spare.push(buffer);
        }
    }
}

struct Worker {
    pieces: Option<Receiver<Piece>>,
    thread: Option<JoinHandle<()>>,
}

/// Workers decoding strips from a first one on, the reader taking their pieces in order.
pub struct StripsAhead {
    workers: Vec<Worker>,
    shape: Shape,
    /// The strip the workers began at: worker `i` decodes strips `first + i`, `first + i + n`, ...
    first: u64,
    /// The first image row of the next piece the reader takes.
    next_row: u64,
    pool: Arc<Pool>,
}

impl StripsAhead {
    /// Starts one worker per decoder, decoding from strip `first` on.
    pub fn start(decoders: Vec<Box<dyn StripDecoder>>, first: u32, shape: Shape) -> std::io::Result<StripsAhead> {
        let count = decoders.len();
        let room = Mutex::new((pieces_at_most(&shape, count as u64), false));
        let pool = Arc::new(Pool { spare: Mutex::default(), held: AtomicU64::new(0), room, taken: Condvar::new() });
        let strips = shape.height.div_ceil(shape.strip_rows.max(1));
        // Queued pieces beside the one being decoded: a strip's worth in all, per worker.
        let queue = (AHEAD_PER_WORKER * shape.pieces_per_strip()).saturating_sub(1) as usize;
        let mut workers = Vec::with_capacity(count);
        for (i, mut decoder) in decoders.into_iter().enumerate() {
            let (send, pieces) = sync_channel::<Piece>(queue);
            let pool = Arc::clone(&pool);
            let mine = (first as u64 + i as u64..strips).step_by(count);
            let thread = std::thread::Builder::new().name(format!("vortex-tiff-{i}")).spawn(move || {
                // The decoder's own bytes counted in `pool.held` so far.
                let mut counted = 0u64;
                for strip in mine {
                    let start = strip * shape.strip_rows;
                    let end = (start + shape.strip_rows).min(shape.height);
                    let mut begun = decoder.begin(strip as u32);
                    for row in (start..end).step_by(shape.piece_rows.max(1) as usize) {
                        if !pool.reserve() {
                            return;
                        }
                        let rows = shape.piece_rows.min(end - row);
                        let mut buffer = pool.take((rows * shape.row_bytes) as usize);
                        let piece = begun.clone().and_then(|()| decoder.fill(&mut buffer)).map(|()| buffer);
                        let own = decoder.held_bytes();
                        pool.held.fetch_add(own.wrapping_sub(counted), Ordering::Relaxed);
                        counted = own;
                        begun = piece.as_ref().map(|_| ()).map_err(Clone::clone);
                        // A reader that hung up stops the worker; a failed strip stops it too
                        // (the reader stops at the first error).
                        if send.send((row, piece)).is_err() || begun.is_err() {
                            return;
                        }
                    }
                }
            })?;
            workers.push(Worker { pieces: Some(pieces), thread: Some(thread) });
        }
        Ok(StripsAhead { workers, shape, first: first as u64, next_row: first as u64 * shape.strip_rows, pool })
    }

    /// The first image row of the next piece the reader can take.
    pub fn next_row(&self) -> u64 {
        self.next_row
    }

    /// Bytes of the pieces decoded or being decoded and not taken, and of the spare ones.
    pub fn held_bytes(&self) -> u64 {
        self.pool.held.load(Ordering::Relaxed)
    }

    /// Takes the next piece, waiting for its worker: its first image row and its rows. `spare`
    /// is a piece the reader is done with.
    pub fn take(&mut self, spare: Vec<u8>) -> Result<(u64, Vec<u8>), String> {
        self.pool.give(spare);
        let strip = self.next_row / self.shape.strip_rows.max(1);
        let worker = &self.workers[((strip - self.first) % self.workers.len() as u64) as usize];
        let stopped = || format!("the worker decoding strip {strip} stopped");
        let (row, piece) = worker.pieces.as_ref().ok_or_else(stopped)?.recv().map_err(|_| stopped())?;
        debug_assert_eq!(row, self.next_row, "a worker sends its pieces in order");
        self.pool.release(false);
        let piece = piece?;
        self.pool.held.fetch_sub(piece.capacity() as u64, Ordering::Relaxed);
        self.next_row += (piece.len() as u64 / self.shape.row_bytes.max(1)).max(1);
        Ok((row, piece))
    }
}

impl Drop for StripsAhead {
    /// Stops the workers: each finishes the piece it is decoding, if any, and exits.
    fn drop(&mut self) {
        self.pool.release(true);
        for worker in &mut self.workers {
            worker.pieces = None;
        }
        for worker in &mut self.workers {
            if let Some(thread) = worker.thread.take() {
                let _ = thread.join();
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A "decoder" whose every byte is its row's number, after a delay that makes later strips
    /// finish first; strip 13 is corrupt.
    struct Fake<D> {
        row_bytes: usize,
        strip_rows: u64,
        row: u64,
        delay_ms: D,
    }

    impl<D: Fn(u32) -> u64 + Send> StripDecoder for Fake<D> {
        fn begin(&mut self, strip: u32) -> Result<(), String> {
            std::thread::sleep(std::time::Duration::from_millis((self.delay_ms)(strip)));
            self.row = strip as u64 * self.strip_rows;
            if strip == 13 { Err("strip 13 is corrupt".into()) } else { Ok(()) }
        }

        fn fill(&mut self, out: &mut [u8]) -> Result<(), String> {
            for row in out.chunks_exact_mut(self.row_bytes) {
                row.fill(self.row as u8);
                self.row += 1;
            }
            Ok(())
        }
    }

    fn fakes(
        n: usize,
        strip_rows: u64,
        delay_ms: impl Fn(u32) -> u64 + Send + Copy + 'static,
    ) -> Vec<Box<dyn StripDecoder>> {
        (0..n).map(|_| Box::new(Fake { row_bytes: 2, strip_rows, row: 0, delay_ms }) as Box<dyn StripDecoder>).collect()
    }

    #[test]
    fn rows_come_in_order_whatever_order_strips_finish_in() {
        // 63 rows in strips of 5 (the last of 3), pieces of 2 rows and of whole strips.
        for piece_rows in [2, 5] {
            let shape = Shape { height: 63, strip_rows: 5, piece_rows, row_bytes: 2 };
            let mut ahead = StripsAhead::start(fakes(3, 5, |s| (7 - s % 7) as u64), 2, shape).unwrap();
            let mut spare = Vec::new();
            let mut rows = Vec::new();
            while ahead.next_row() < 63 {
                let (first, piece) = ahead.take(spare).unwrap();
                assert_eq!(first, rows.len() as u64 + 10);
                assert!(piece.len() <= piece_rows as usize * 2);
                rows.extend(piece.chunks_exact(2).map(|r| r[0]));
                assert!(ahead.held_bytes() <= bytes_at_most(&shape, 3), "within the bound");
                spare = piece;
            }
            assert_eq!(rows, (10..63).collect::<Vec<u8>>());
        }
    }

    #[test]
    fn a_failed_strip_is_reported_for_that_strip() {
        let shape = Shape { height: 100, strip_rows: 4, piece_rows: 4, row_bytes: 2 };
        let mut ahead = StripsAhead::start(fakes(2, 4, |_| 0), 12, shape).unwrap();
        assert!(ahead.take(Vec::new()).is_ok());
        assert_eq!(ahead.take(Vec::new()), Err("strip 13 is corrupt".to_string()));
        drop(ahead); // joins the workers, which may be blocked on a full queue
    }

    #[test]
    fn the_bound_counts_a_strip_per_worker_and_the_reader_s_piece() {
        let strips = Shape { height: 1000, strip_rows: 128, piece_rows: 128, row_bytes: 10 };
        assert_eq!(bytes_at_most(&strips, 2), 3 * 1280, "two strips decoding, one taken");
        let pieces = Shape { piece_rows: Shape::rows_per_piece(49152, 128), row_bytes: 49152, ..strips };
        assert_eq!(pieces.piece_rows, 5);
        // 26 pieces of 5 rows a strip (the last of 3) on one worker, two on each, one taken.
        assert_eq!(bytes_at_most(&pieces, 2), (26 + 4 + 1) * 5 * 49152);
        assert_eq!(bytes_at_most(&pieces, 4), (3 * 26 + 8 + 1) * 5 * 49152);
    }
}
