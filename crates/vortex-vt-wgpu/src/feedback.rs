//! Feedback: which pages the frame's fragments want. The application's fragment shader calls
//! `vt_feedback` (`shaders/vt.wgsl`), which writes the feedback word
//! (`vortex_vt::feedback::encode`) of the page the fragment samples into a storage buffer of one
//! word per block of `block x block` pixels ([`FeedbackBuffer`]); only one pixel per block, the
//! frame's *elected* pixel, writes. The elected pixel moves every frame in the order of an
//! ordered-dither matrix ([`elected`]), so that in any `block²` consecutive frames every pixel of
//! a block is heard once: a page seen only by a thin sliver or at the frame's edge is still asked
//! for, within `block²` frames. The LOD is the one
//! `vortex_vt::feedback::lod_for` gives for the fragment's footprint plus the residency's bias.
//!
//! After the frame, the buffer is copied into one of a small ring of mappable buffers and reset
//! to [`NO_REQUEST`](vortex_vt::feedback::NO_REQUEST); the CPU picks up the words of an earlier frame when the GPU is done with
//! them and never waits: [`FeedbackReadback::try_read`] never blocks, and a frame whose copy
//! finds every buffer of the ring still in flight is skipped.

use std::sync::{Arc, Mutex, MutexGuard, PoisonError};

use crate::params::FeedbackLayout;
use crate::readback::{Readback, ReadbackError};

/// The storage buffer `vt_feedback` writes: one word per block of the frame.
#[derive(Debug)]
pub struct FeedbackBuffer {
    buffer: wgpu::Buffer,
    /// The buffer's bytes when nothing asked: made once, written every frame.
    no_requests: Vec<u8>,
    /// Pixels per block side.
    pub block: u32,
    /// Blocks per row: the frame's width divided by `block`, rounded up.
    pub columns: u32,
    /// Blocks per column: the frame's height divided by `block`, rounded up.
    pub rows: u32,
}

impl FeedbackBuffer {
    /// The buffer for a `width x height` frame in blocks of `block` pixels (at least 1).
    pub fn new(device: &wgpu::Device, width: u32, height: u32, block: u32) -> FeedbackBuffer {
        let block = block.max(1);
        let (columns, rows) = (width.div_ceil(block).max(1), height.div_ceil(block).max(1));
        let buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("vortex feedback"),
            size: u64::from(columns * rows) * 4,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let no_requests = vec![0xff; (columns * rows) as usize * 4];
        FeedbackBuffer { buffer, no_requests, block, columns, rows }
    }

    /// Words in the buffer: one per block.
    pub fn words(&self) -> u32 {
        self.columns * self.rows
    }

    /// The storage buffer `vt_feedback` writes (bind it where the shader module says).
    pub fn buffer(&self) -> &wgpu::Buffer {
        &self.buffer
    }

    /// Resets every word to [`NO_REQUEST`](vortex_vt::feedback::NO_REQUEST) before the next submitted command buffer runs.
    pub fn clear(&self, queue: &wgpu::Queue) {
        queue.write_buffer(&self.buffer, 0, &self.no_requests);
    }

    /// The layout the shader gets for frame `frame`.
    pub(crate) fn layout(&self, frame: u64) -> FeedbackLayout {
        FeedbackLayout { block: self.block, columns: self.columns, rows: self.rows, elect: elected(frame, self.block) }
    }
}

/// The pixel of each `block x block` block that writes frame `n`'s feedback. The frames take
/// the block's pixels in the order of the ordered-dither (Bayer) matrix of the next power of two
/// (its pixels past the block skipped), from its centre on: in any `block²` consecutive frames
/// every pixel of the block is elected exactly once, and consecutive frames spread over the
/// block evenly (frame 0 takes the pixel at (1/2, 1/2) of a power-of-two block, frame 1 the one
/// at (1/2, 0), frame 2 the one at (0, 1/2), ...).
pub fn elected(n: u64, block: u32) -> [u32; 2] {
    let block = block.max(1);
    let side = block.next_power_of_two();
    let bits = side.trailing_zeros();
    let count = u64::from(block) * u64::from(block);
    let rank = (n + 1) % count;
    if side == block {
        return bayer_pixel(rank, bits);
    }
    (0..u64::from(side) * u64::from(side))
        .map(|r| bayer_pixel(r, bits))
        .filter(|&[x, y]| x < block && y < block)
        .nth(rank as usize)
        .unwrap_or([0, 0])
}

/// The pixel of rank `rank` in the ordered-dither matrix of side `2^bits`: the rank's base-4
/// digits, most significant first, are the pixel's coordinate bits, least significant first,
/// each digit placing the pixel in the (0, 0), (1, 1), (1, 0), (0, 1) quadrant in turn.
fn bayer_pixel(rank: u64, bits: u32) -> [u32; 2] {
    let (mut x, mut y) = (0, 0);
    for i in 0..bits {
        let digit = (rank >> (2 * (bits - 1 - i))) & 3;
        let [dx, dy] = [[0, 0], [1, 1], [1, 0], [0, 1]][digit as usize];
        x |= dx << i;
        y |= dy << i;
    }
    [x, y]
}

/// The words of one read-back feedback buffer, row-major.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FeedbackFrame {
    /// The number [`FeedbackReadback::encode_copy`] gave the copy.
    pub frame: u64,
    /// Words per row.
    pub columns: u32,
    /// Rows.
    pub rows: u32,
    /// The words, row by row.
    pub words: Vec<u32>,
}

/// What the map callback of a ring buffer reports: nothing yet, or the mapping's result.
type MapResult = Arc<Mutex<Option<Result<(), wgpu::BufferAsyncError>>>>;

#[derive(Debug)]
enum SlotState {
    Free,
    /// The copy is recorded; the mapping is requested by [`FeedbackReadback::submitted`].
    Copied {
        frame: u64,
    },
    /// Mapping requested; the callback fills in the result.
    Mapping {
        frame: u64,
        result: MapResult,
    },
}

#[derive(Debug)]
struct Slot {
    readback: Readback,
    state: SlotState,
}

/// A ring of mappable buffers that feedback buffers are copied into, read back without making
/// the CPU wait for the GPU. Per frame: [`FeedbackReadback::encode_copy`] after the frame's
/// passes, `queue.submit`, [`FeedbackReadback::submitted`], then [`FeedbackReadback::try_read`]
/// for the oldest frame the GPU has finished, if any.
#[derive(Debug)]
pub struct FeedbackReadback {
    /// Words per row of the buffers it reads.
    pub columns: u32,
    /// Rows of the buffers it reads.
    pub rows: u32,
    slots: Vec<Slot>,
    next_frame: u64,
}

impl FeedbackReadback {
    /// A ring of `buffers` (at least 1; 2 or 3 keep the CPU from waiting) for `feedback`.
    pub fn new(device: &wgpu::Device, feedback: &FeedbackBuffer, buffers: usize) -> FeedbackReadback {
        let (columns, rows) = (feedback.columns, feedback.rows);
        let slots = (0..buffers.max(1))
            .map(|_| Slot {
                readback: Readback::new(device, "feedback", columns * rows * 4, 1),
                state: SlotState::Free,
            })
            .collect();
        FeedbackReadback { columns, rows, slots, next_frame: 0 }
    }

    /// Copies that are recorded or in flight and not yet read.
    pub fn in_flight(&self) -> usize {
        self.slots.iter().filter(|s| !matches!(s.state, SlotState::Free)).count()
    }

    /// Records the copy of `feedback` into a free buffer of the ring and returns the frame number
    /// it will be read back under, or `None` when every buffer is still in flight (this frame's
    /// feedback is then skipped). Call [`FeedbackReadback::submitted`] after submitting.
    pub fn encode_copy(&mut self, encoder: &mut wgpu::CommandEncoder, feedback: &FeedbackBuffer) -> Option<u64> {
        assert_eq!((feedback.columns, feedback.rows), (self.columns, self.rows), "feedback buffer size");
        let slot = self.slots.iter_mut().find(|s| matches!(s.state, SlotState::Free))?;
        slot.readback.encode_copy_buffer(encoder, &feedback.buffer);
        let frame = self.next_frame;
        self.next_frame += 1;
        slot.state = SlotState::Copied { frame };
        Some(frame)
    }

    /// Requests the mapping of every copy recorded since the last call; call it once the
    /// encoders holding them are submitted (a buffer may not be mapped while a submission that
    /// uses it is still to come).
    pub fn submitted(&mut self) {
        for slot in &mut self.slots {
            if let SlotState::Copied { frame } = slot.state {
                let result: MapResult = Arc::default();
                let answer = result.clone();
                slot.readback.map(move |r| *lock(&answer) = Some(r));
                slot.state = SlotState::Mapping { frame, result };
            }
        }
    }

    /// The words of the oldest frame whose copy the GPU has finished, without blocking (the
    /// device is polled once); `Ok(None)` when none is ready. A failed mapping (a lost device)
    /// is an error naming its frame; the frame's buffer is free again, so a later call goes on
    /// with the next frames.
    pub fn try_read(&mut self, device: &wgpu::Device) -> Result<Option<FeedbackFrame>, ReadbackError> {
        device.poll(wgpu::PollType::Poll).map_err(|source| ReadbackError::Wait { what: "feedback", source })?;
        let oldest = self
            .slots
            .iter()
            .enumerate()
            .filter_map(|(i, s)| match &s.state {
                SlotState::Mapping { frame, result } => lock(result).clone().map(|r| (i, *frame, r)),
                _ => None,
            })
            .min_by_key(|&(_, frame, _)| frame);
        let Some((i, frame, result)) = oldest else { return Ok(None) };
        let slot = &mut self.slots[i];
        slot.state = SlotState::Free;
        result.map_err(|source| ReadbackError::Feedback { frame, source })?;
        let words =
            slot.readback.take()?.chunks_exact(4).map(|w| u32::from_le_bytes([w[0], w[1], w[2], w[3]])).collect();
        Ok(Some(FeedbackFrame { frame, columns: self.columns, rows: self.rows, words }))
    }

    /// Waits for the GPU to finish everything submitted, then reads the oldest frame in flight
    /// (`Ok(None)` if none was). For offline rendering and tests; a frame loop uses
    /// [`FeedbackReadback::try_read`].
    pub fn read_now(&mut self, device: &wgpu::Device) -> Result<Option<FeedbackFrame>, ReadbackError> {
        if !self.slots.iter().any(|s| matches!(s.state, SlotState::Mapping { .. })) {
            return Ok(None);
        }
        device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|source| ReadbackError::Wait { what: "feedback", source })?;
        self.try_read(device)
    }
}

/// The callback holds the lock only to store a value, so a poisoned lock still holds a whole one.
fn lock<T>(mutex: &Mutex<T>) -> MutexGuard<'_, T> {
    mutex.lock().unwrap_or_else(PoisonError::into_inner)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn any_block_squared_frames_elect_every_pixel_of_a_block_once() {
        for block in [1u32, 2, 3, 4, 5, 8, 12, 16] {
            let count = u64::from(block * block);
            for start in [0, 1, 7, count - 1, 1000] {
                let mut seen = std::collections::HashSet::new();
                for n in start..start + count {
                    let [x, y] = elected(n, block);
                    assert!(x < block && y < block, "block {block}, frame {n}: ({x}, {y})");
                    assert!(seen.insert((x, y)), "block {block}: ({x}, {y}) twice from frame {start}");
                }
            }
        }
    }

    #[test]
    fn consecutive_frames_elect_distant_pixels() {
        assert_eq!(elected(0, 8), [4, 4], "the centre first");
        assert_eq!([elected(1, 8), elected(2, 8), elected(3, 8)], [[4, 0], [0, 4], [2, 2]]);
        // A power of two: consecutive frames are never neighbours.
        for n in 0..64 {
            let ([a, b], [c, d]) = (elected(n, 8), elected(n + 1, 8));
            assert!(a.abs_diff(c).max(b.abs_diff(d)) >= 2, "frames {n} and {}: ({a}, {b}), ({c}, {d})", n + 1);
        }
    }
}
