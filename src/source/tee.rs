//! One read of a source for several pyramids at once ([`tee`]): each branch is a
//! [`RowSource`] of the same rows, read and decoded once. A row is kept until every branch has
//! read it; a branch that runs `window` rows ahead of the slowest waits for it. Branches read
//! on threads of their own, each the producer of its own pipeline, so no branch waits for
//! anything but rows (no cycle: the slowest branch never waits for the others).

use std::collections::VecDeque;
use std::sync::{Arc, Condvar, Mutex, MutexGuard};

use super::stored::StoredTiles;
use super::{ImageHeader, RowSource};
use crate::error::{Result, TilerError};

/// `branches` sources of `source`'s rows, in order, from one read of it; at most `window`
/// rows (at least 1) held for the branches behind.
pub(crate) fn tee(source: Box<dyn RowSource>, branches: usize, window: usize) -> Vec<Box<dyn RowSource>> {
    let header = source.header();
    let describe = source.describe();
    let stored = source.stored_tiles();
    let decoder = source.most_buffer_bytes();
    let row_bytes = header.width as usize * header.layout.bytes_per_pixel();
    let window = window.max(1);
    let shared = Arc::new(Shared {
        state: Mutex::new(State {
            source,
            rows: VecDeque::with_capacity(window),
            first: 0,
            next: vec![0; branches],
            spare: Vec::new(),
            failed: false,
        }),
        turn: Condvar::new(),
        window,
        row_bytes,
    });
    // Each branch's plan counts the decoder's buffers as its own (as a run of its own would:
    // `Plan::write` checks the plans with the source before the tee); the window is set
    // aside from the budget the branches share ([`window_bytes`]).
    let held = decoder;
    (0..branches)
        .map(|index| {
            Box::new(Branch {
                shared: Arc::clone(&shared),
                index,
                header,
                describe: describe.clone(),
                stored: stored.clone(),
                held,
            }) as Box<dyn RowSource>
        })
        .collect()
}

/// Bytes the rows of `window` rows of `header`'s image take.
pub(crate) fn window_bytes(header: &ImageHeader, window: usize) -> u64 {
    (window as u64).saturating_mul(header.width as u64 * header.layout.bytes_per_pixel() as u64)
}

struct Shared {
    state: Mutex<State>,
    /// Signalled when a row is read or freed, or a branch leaves.
    turn: Condvar,
    window: usize,
    row_bytes: usize,
}

struct State {
    source: Box<dyn RowSource>,
    /// Rows read that some branch has still to read, oldest first.
    rows: VecDeque<Vec<u8>>,
    /// The index of `rows[0]`.
    first: u64,
    /// The next row each branch reads; `u64::MAX` for a branch that has left.
    next: Vec<u64>,
    /// Freed rows' buffers, for the next rows.
    spare: Vec<Vec<u8>>,
    /// Whether reading the source failed.
    failed: bool,
}

impl State {
    /// Frees the rows every branch has read.
    fn trim(&mut self) {
        while !self.rows.is_empty() && self.next.iter().all(|&n| n > self.first) {
            if let Some(row) = self.rows.pop_front() {
                self.spare.push(row);
            }
            self.first += 1;
        }
    }
}

struct Branch {
    shared: Arc<Shared>,
    index: usize,
    header: ImageHeader,
    describe: String,
    stored: Option<Arc<dyn StoredTiles>>,
    held: u64,
}

impl Branch {
    fn lock(&self) -> MutexGuard<'_, State> {
        self.shared.state.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }
}

impl RowSource for Branch {
    fn header(&self) -> ImageHeader {
        self.header
    }

    fn read_row(&mut self, row: &mut [u8]) -> Result<()> {
        let shared = Arc::clone(&self.shared);
        let mut s = self.lock();
        loop {
            let at = s.next[self.index];
            if let Some(held) = at.checked_sub(s.first).and_then(|k| s.rows.get(k as usize)) {
                if held.len() != row.len() {
                    return Err(TilerError::Internal("a shared source row was asked with another width".into()));
                }
                row.copy_from_slice(held);
                s.next[self.index] += 1;
                s.trim();
                shared.turn.notify_all();
                return Ok(());
            }
            // The branch that read the failing row reports its error; the others stop.
            if s.failed {
                return Err(TilerError::Interrupted);
            }
            if s.rows.len() < shared.window {
                let mut next = s.spare.pop().unwrap_or_else(|| vec![0; shared.row_bytes]);
                if let Err(e) = s.source.read_row(&mut next) {
                    s.failed = true;
                    shared.turn.notify_all();
                    return Err(e);
                }
                s.rows.push_back(next);
                continue;
            }
            s = shared.turn.wait(s).unwrap_or_else(|poisoned| poisoned.into_inner());
        }
    }

    fn describe(&self) -> String {
        self.describe.clone()
    }

    fn most_buffer_bytes(&self) -> u64 {
        self.held
    }

    fn buffer_bytes(&self) -> u64 {
        self.held
    }

    fn stored_tiles(&self) -> Option<Arc<dyn StoredTiles>> {
        self.stored.clone()
    }
}

/// A branch that leaves (its run finished or failed) holds no row back.
impl Drop for Branch {
    fn drop(&mut self) {
        let mut s = self.lock();
        s.next[self.index] = u64::MAX;
        s.trim();
        self.shared.turn.notify_all();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pixel::{Channels, Depth, PixelLayout};

    /// Rows whose bytes are their index, and a count of reads.
    struct Counting {
        rows: u32,
        read: Arc<Mutex<u32>>,
    }

    impl RowSource for Counting {
        fn header(&self) -> ImageHeader {
            ImageHeader { width: 3, height: self.rows, layout: PixelLayout::new(Channels::Grey, Depth::U8) }
        }
        fn read_row(&mut self, row: &mut [u8]) -> Result<()> {
            let mut read = self.read.lock().unwrap();
            row.fill(*read as u8);
            *read += 1;
            Ok(())
        }
        fn describe(&self) -> String {
            "counting".into()
        }
    }

    #[test]
    fn every_branch_reads_every_row_once_read() {
        let read = Arc::new(Mutex::new(0));
        let branches = tee(Box::new(Counting { rows: 50, read: Arc::clone(&read) }), 3, 4);
        let got: Vec<Vec<u8>> = std::thread::scope(|scope| {
            let runs: Vec<_> = branches
                .into_iter()
                .enumerate()
                .map(|(k, mut branch)| {
                    scope.spawn(move || {
                        let mut seen = Vec::new();
                        let mut row = [0u8; 3];
                        for _ in 0..50 {
                            branch.read_row(&mut row).unwrap();
                            seen.push(row[0]);
                            // Branches of different speeds: the window makes the fast one wait.
                            if k == 1 {
                                std::thread::yield_now();
                            }
                        }
                        seen
                    })
                })
                .collect();
            runs.into_iter().map(|r| r.join().unwrap()).collect()
        });
        let want: Vec<u8> = (0..50).collect();
        assert!(got.iter().all(|g| *g == want), "{got:?}");
        assert_eq!(*read.lock().unwrap(), 50, "each row decoded once");
    }

    #[test]
    fn a_branch_that_leaves_holds_no_one_back() {
        let read = Arc::new(Mutex::new(0));
        let mut branches = tee(Box::new(Counting { rows: 20, read }), 2, 2);
        let mut rest = branches.pop().unwrap();
        drop(branches);
        let mut row = [0u8; 3];
        for k in 0..20 {
            rest.read_row(&mut row).unwrap();
            assert_eq!(row[0], k);
        }
    }
}
