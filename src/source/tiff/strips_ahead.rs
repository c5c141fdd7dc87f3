//! Compressed strips decoded ahead of the reader, several at once.
//!
//! Inflating a Deflate or LZW strip is one thread's work, and one thread decoding strip after
//! strip bound a whole `split` of such a TIFF: 3.5 s (Deflate) and 6 s (LZW) of a 16384² run
//! spent on one core while the other waited (issue 18). Strips are independent, so workers,
//! each with a decoder of its own on the same file, decode strip `s` on worker `s % workers`,
//! a few strips ahead of the one the reader takes; the reader takes them in order. The bytes
//! are what one decoder would give, so nothing downstream can tell.

use std::sync::mpsc::{Receiver, Sender, channel};
use std::thread::JoinHandle;

/// Strips each worker decodes ahead of the one the reader waits for: one keeps every worker
/// busy while the reader takes strips as fast as they come, and holds the least memory.
pub const AHEAD_PER_WORKER: u32 = 1;

/// What a worker decodes a strip with: `decode(strip, buffer)` fills `buffer` (sized by the
/// caller for that strip) or says why it cannot.
pub type DecodeStrip = Box<dyn FnMut(u32, &mut Vec<u8>) -> Result<(), String> + Send>;

/// A decoded strip, or why it failed.
type Decoded = (u32, Result<Vec<u8>, String>);

struct Worker {
    /// Strips to decode, each with a buffer to fill (recycled from the reader).
    requests: Option<Sender<(u32, Vec<u8>)>>,
    done: Receiver<Decoded>,
    thread: Option<JoinHandle<()>>,
}

/// Workers decoding strips `next..count` in order, [`AHEAD_PER_WORKER`] each ahead of the reader.
pub struct StripsAhead {
    workers: Vec<Worker>,
    /// The next strip the reader takes, and one past the last one requested.
    next: u32,
    requested: u32,
    count: u32,
    /// Bytes of strip `s` (the last strip may be shorter).
    strip_bytes: Box<dyn Fn(u32) -> usize + Send>,
    /// Buffers the reader handed back, for the next requests.
    spare: Vec<Vec<u8>>,
}

impl StripsAhead {
    /// Starts one worker per decoder, decoding from strip `first` of `count`.
    pub fn start(
        decoders: Vec<DecodeStrip>,
        first: u32,
        count: u32,
        strip_bytes: Box<dyn Fn(u32) -> usize + Send>,
    ) -> std::io::Result<StripsAhead> {
        let mut workers = Vec::with_capacity(decoders.len());
        for (i, mut decode) in decoders.into_iter().enumerate() {
            let (requests, jobs) = channel::<(u32, Vec<u8>)>();
            let (finished, done) = channel::<Decoded>();
            let thread = std::thread::Builder::new().name(format!("vortex-tiff-{i}")).spawn(move || {
                for (strip, mut buffer) in jobs {
                    let result = decode(strip, &mut buffer).map(|()| buffer);
                    if finished.send((strip, result)).is_err() {
                        return;
                    }
                }
            })?;
            workers.push(Worker { requests: Some(requests), done, thread: Some(thread) });
        }
        let mut ahead = StripsAhead { workers, next: first, requested: first, count, strip_bytes, spare: Vec::new() };
        let depth = ahead.workers.len() as u32 * AHEAD_PER_WORKER;
        while ahead.requested < count.min(first.saturating_add(depth)) {
            ahead.request();
        }
        Ok(ahead)
    }

    /// The next strip the reader can take.
    pub fn next(&self) -> u32 {
        self.next
    }

    /// Strips requested and not taken yet: decoding or decoded, each in a buffer of its own.
    pub fn in_flight(&self) -> u32 {
        self.requested.saturating_sub(self.next)
    }

    /// Takes strip [`next`](Self::next), waiting for its worker, and asks for one more. `spare`
    /// is a buffer the reader is done with.
    pub fn take(&mut self, spare: Vec<u8>) -> Result<Vec<u8>, String> {
        let strip = self.next;
        let worker = &self.workers[strip as usize % self.workers.len()];
        let (decoded, result) = worker.done.recv().map_err(|_| format!("the worker decoding strip {strip} stopped"))?;
        debug_assert_eq!(decoded, strip, "a worker answers its strips in order");
        self.next += 1;
        self.spare.push(spare);
        if self.requested < self.count {
            self.request();
        }
        result
    }

    fn request(&mut self) {
        let strip = self.requested;
        let mut buffer = self.spare.pop().unwrap_or_default();
        buffer.resize((self.strip_bytes)(strip), 0);
        let worker = &self.workers[strip as usize % self.workers.len()];
        if let Some(requests) = &worker.requests {
            // A worker that stopped is noticed by `take`, which finds its results closed.
            let _ = requests.send((strip, buffer));
        }
        self.requested += 1;
    }
}

impl Drop for StripsAhead {
    /// Stops the workers: each finishes the strip it is decoding, if any, and exits.
    fn drop(&mut self) {
        for worker in &mut self.workers {
            worker.requests = None;
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

    /// A "decoder" that writes the strip's index into every byte, after a delay that makes
    /// later strips finish first.
    fn fake(delay_ms: impl Fn(u32) -> u64 + Send + 'static) -> DecodeStrip {
        Box::new(move |strip, buffer: &mut Vec<u8>| {
            std::thread::sleep(std::time::Duration::from_millis(delay_ms(strip)));
            buffer.fill(strip as u8);
            if strip == 13 { Err("strip 13 is corrupt".into()) } else { Ok(()) }
        })
    }

    #[test]
    fn strips_come_in_order_whatever_order_they_finish_in() {
        let decoders = (0..3).map(|_| fake(|s| (7 - s % 7) as u64)).collect();
        let mut ahead = StripsAhead::start(decoders, 2, 13, Box::new(|s| if s == 12 { 3 } else { 5 })).unwrap();
        let mut spare = Vec::new();
        for s in 2..13 {
            assert_eq!(ahead.next(), s);
            let strip = ahead.take(spare).unwrap();
            assert_eq!(strip, vec![s as u8; if s == 12 { 3 } else { 5 }]);
            spare = strip;
        }
    }

    #[test]
    fn a_failed_strip_is_reported_for_that_strip() {
        let decoders = (0..2).map(|_| fake(|_| 0)).collect();
        let mut ahead = StripsAhead::start(decoders, 12, 20, Box::new(|_| 4)).unwrap();
        assert!(ahead.take(Vec::new()).is_ok());
        assert_eq!(ahead.take(Vec::new()), Err("strip 13 is corrupt".to_string()));
        drop(ahead); // joins the workers, which still have strips queued
    }
}
