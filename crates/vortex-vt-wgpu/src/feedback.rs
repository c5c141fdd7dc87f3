//! The feedback pass and its readback. The view is drawn a second time, into a small `R32Uint`
//! target ([`FeedbackTarget`], the frame's size divided by e.g. 8), cleared to
//! [`NO_REQUEST`]; its fragment shader (`shaders/feedback.wgsl`) writes per pixel the feedback
//! word (`vortex_vt::feedback::encode`) of the page it wants. The LOD is the one
//! `vortex_vt::feedback::lod_for` gives for the fragment's footprint, plus the frame's bias and
//! [`FeedbackTarget::bias`] (`feedback_bias`, which makes up for the reduced size), and the page
//! is the one holding its address at that LOD (`vortex_vt::address`).
//!
//! [`FeedbackReadback`] copies the target into one of a small ring of mappable buffers, so that
//! the CPU picks up the words of an earlier frame when the GPU is done with them and never
//! waits: [`FeedbackReadback::try_read`] never blocks; a frame whose copy finds every buffer
//! still in flight is skipped.

use std::sync::{Arc, Mutex, MutexGuard, PoisonError};

use vortex_vt::feedback::{NO_REQUEST, feedback_bias};

use crate::draw::{self, Pipelines, Target};
use crate::params::Frame;
use crate::readback::{Readback, ReadbackError};
use crate::texture::VirtualTexture;
use crate::view::View;

/// The format of feedback targets: one feedback word per pixel.
pub const FEEDBACK_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R32Uint;

/// The `R32Uint` target of the feedback pass, at a fraction of the frame's size.
#[derive(Debug)]
pub struct FeedbackTarget {
    pub width: u32,
    pub height: u32,
    /// The size of the frame the feedback stands for (sets [`FeedbackTarget::bias`]).
    pub frame_width: u32,
    pub frame_height: u32,
    target: Target,
}

impl FeedbackTarget {
    /// A target of the frame's size divided by `divisor` (rounded up, at least one pixel).
    pub fn new(device: &wgpu::Device, frame_width: u32, frame_height: u32, divisor: u32) -> FeedbackTarget {
        let divisor = divisor.max(1);
        let (w, h) = (frame_width.div_ceil(divisor).max(1), frame_height.div_ceil(divisor).max(1));
        FeedbackTarget::with_size(device, w, h, frame_width, frame_height)
    }

    /// A `width x height` target for a `frame_width x frame_height` frame.
    pub fn with_size(
        device: &wgpu::Device,
        width: u32,
        height: u32,
        frame_width: u32,
        frame_height: u32,
    ) -> FeedbackTarget {
        let target = Target::new(device, "vortex feedback", FEEDBACK_FORMAT, width, height);
        FeedbackTarget { width, height, frame_width, frame_height, target }
    }

    /// The LOD bias that makes up for the reduced size: `feedback_bias` (e.g. -3 at 1/8).
    pub fn bias(&self) -> f32 {
        feedback_bias(self.width, self.height, self.frame_width, self.frame_height)
    }

    pub fn view(&self) -> &wgpu::TextureView {
        &self.target.view
    }
}

/// The pipelines of the feedback pass, made once per device.
#[derive(Debug)]
pub struct FeedbackPass {
    pipelines: Pipelines,
    layout: wgpu::BindGroupLayout,
}

impl FeedbackPass {
    pub fn new(device: &wgpu::Device) -> FeedbackPass {
        let module = draw::shader(device, "vortex feedback.wgsl", include_str!("shaders/feedback.wgsl"));
        let layout = draw::frame_only_layout(device, "vortex feedback");
        let pipelines = Pipelines::new(device, "vortex feedback", &module, &layout, FEEDBACK_FORMAT, &[]);
        FeedbackPass { pipelines, layout }
    }

    /// Records the feedback pass into `target`: the clear to [`NO_REQUEST`], then the draw of
    /// `view` if there is one (`None` records the clear alone: nothing virtual on screen). `bias`
    /// is the frame's own LOD bias (the residency's); the target's is added to it. Each feedback
    /// pixel samples at `jitter` (feedback pixels, within ±0.5) from its centre: pass
    /// [`jitter`]`(frame)` so that over frames the samples cover every frame pixel, or `[0, 0]`.
    #[allow(clippy::too_many_arguments)]
    pub fn encode(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        target: &FeedbackTarget,
        textures: &[VirtualTexture],
        view: Option<&View>,
        bias: f32,
        jitter: [f32; 2],
    ) {
        let bind_group = view.map(|view| {
            let size = (target.width, target.height);
            let frame = Frame::new(textures, None, view, size, bias + target.bias(), None).jittered(jitter, size);
            draw::frame_only_bind_group(device, "vortex feedback", &self.layout, &frame)
        });
        // Integer targets take the clear colour converted to the channel type: all ones.
        let clear = NO_REQUEST as f64;
        let colour = wgpu::Color { r: clear, g: clear, b: clear, a: clear };
        let draw = bind_group.as_ref().zip(view).map(|(g, v)| (&self.pipelines, g, v));
        target.target.record(encoder, "vortex feedback", colour, draw);
    }
}

/// Where frame `n`'s feedback samples within its pixels, relative to their centres: the Halton
/// (2, 3) sequence, so that the samples of a few consecutive frames spread evenly over each
/// feedback pixel's block of frame pixels. A page seen only by frame pixels between two
/// feedback samples (at the frame's edge, or a thin sliver) is then still asked for, within a
/// few frames, instead of never.
pub fn jitter(n: u64) -> [f32; 2] {
    let halton = |mut i: u64, base: u64| {
        let (mut f, mut r) = (1.0f64, 0.0f64);
        while i > 0 {
            f /= base as f64;
            r += f * (i % base) as f64;
            i /= base;
        }
        r
    };
    // Index 1 on, so that frame 0 samples near the centre: (0.5, 1/3) - 0.5.
    [(halton(n + 1, 2) - 0.5) as f32, (halton(n + 1, 3) - 0.5) as f32]
}

/// The words of one read-back feedback target, row-major.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FeedbackFrame {
    /// The number [`FeedbackReadback::encode_copy`] gave the copy.
    pub frame: u64,
    pub width: u32,
    pub height: u32,
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

/// A ring of mappable buffers that feedback targets are copied into, read back without making
/// the CPU wait for the GPU. Per frame: [`FeedbackReadback::encode_copy`] after the feedback
/// pass, `queue.submit`, [`FeedbackReadback::submitted`], then [`FeedbackReadback::try_read`]
/// for the oldest frame the GPU has finished, if any.
#[derive(Debug)]
pub struct FeedbackReadback {
    pub width: u32,
    pub height: u32,
    slots: Vec<Slot>,
    next_frame: u64,
}

impl FeedbackReadback {
    /// A ring of `buffers` (at least 1; 2 or 3 keep the CPU from waiting) for `width x height`
    /// targets.
    pub fn new(device: &wgpu::Device, width: u32, height: u32, buffers: usize) -> FeedbackReadback {
        let slots = (0..buffers.max(1))
            .map(|_| Slot { readback: Readback::new(device, "feedback", width * 4, height), state: SlotState::Free })
            .collect();
        FeedbackReadback { width, height, slots, next_frame: 0 }
    }

    /// Copies that are recorded or in flight and not yet read.
    pub fn in_flight(&self) -> usize {
        self.slots.iter().filter(|s| !matches!(s.state, SlotState::Free)).count()
    }

    /// Records the copy of `target` into a free buffer of the ring and returns the frame number
    /// it will be read back under, or `None` when every buffer is still in flight (this frame's
    /// feedback is then skipped). Call [`FeedbackReadback::submitted`] after submitting.
    pub fn encode_copy(&mut self, encoder: &mut wgpu::CommandEncoder, target: &FeedbackTarget) -> Option<u64> {
        assert_eq!((target.width, target.height), (self.width, self.height), "feedback target size");
        let slot = self.slots.iter_mut().find(|s| matches!(s.state, SlotState::Free))?;
        let (source, extent) = target.target.copy_source();
        slot.readback.encode_copy(encoder, source, extent);
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
        Ok(Some(FeedbackFrame { frame, width: self.width, height: self.height, words }))
    }

    /// Waits for the GPU to finish everything submitted, then reads the oldest frame in flight
    /// (`Ok(None)` if none was). For tests and tools; a frame loop uses
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
