//! Reading a texture back to the CPU, written once for the render target, the address probe, a
//! cache slot and the feedback ring: a mappable buffer whose rows are padded to the 256 bytes
//! that texture-to-buffer copies require, the copy of a texture region into it, and the map, the
//! wait and the unpadding of the rows. Render thread.
//!
//! A readback is where a lost device shows: the map's callback gets an error, or waiting for the
//! GPU fails. Both come back as a [`ReadbackError`] naming what was being read, never as a
//! panic, so that a caller (the frame loop, `vortex-tiler render`) can report it and stop.

use std::sync::mpsc;

/// Why a readback gave no bytes.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ReadbackError {
    /// Waiting for the GPU to finish the copy failed.
    #[error("reading back the {what}: waiting for the GPU failed (is the device lost?): {source}")]
    Wait {
        /// What was read back.
        what: &'static str,
        /// What wgpu said.
        #[source]
        source: wgpu::PollError,
    },
    /// The buffer could not be mapped: the device was lost, or the buffer destroyed.
    #[error("reading back the {what}: mapping the buffer failed (is the device lost?): {source}")]
    Map {
        /// What was read back.
        what: &'static str,
        /// What wgpu said.
        #[source]
        source: wgpu::BufferAsyncError,
    },
    /// The mapping of one frame's feedback failed (the ring goes on with the next frames).
    #[error("reading back the feedback of frame {frame}: mapping the buffer failed (is the device lost?): {source}")]
    Feedback {
        /// The frame.
        frame: u64,
        /// What wgpu said.
        #[source]
        source: wgpu::BufferAsyncError,
    },
    /// The GPU was done, yet the map was never answered, or the mapped range was refused.
    #[error("reading back the {what}: the buffer is not mapped: {message}")]
    NotMapped {
        /// What was read back.
        what: &'static str,
        /// What happened.
        message: String,
    },
}

/// A mappable buffer that a `width x height` texture region is copied into, row by row.
#[derive(Debug)]
pub(crate) struct Readback {
    buffer: wgpu::Buffer,
    /// What is read back, for labels and errors: "target", "probe", "slot", "feedback".
    what: &'static str,
    /// Bytes of one row of texels (or of BC blocks) as the caller wants them.
    row_bytes: u32,
    /// Bytes per row in the buffer: `row_bytes` rounded up to a multiple of 256.
    padded_row: u32,
    rows: u32,
}

impl Readback {
    /// A buffer for `rows` rows of `row_bytes` bytes each.
    pub(crate) fn new(device: &wgpu::Device, what: &'static str, row_bytes: u32, rows: u32) -> Readback {
        let padded_row = row_bytes.next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(&format!("vortex {what} readback")),
            size: u64::from(padded_row) * u64::from(rows),
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        Readback { buffer, what, row_bytes, padded_row, rows }
    }

    /// Records the copy of the `extent` of `source` into the buffer.
    pub(crate) fn encode_copy(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        source: wgpu::TexelCopyTextureInfo,
        extent: wgpu::Extent3d,
    ) {
        encoder.copy_texture_to_buffer(
            source,
            wgpu::TexelCopyBufferInfo {
                buffer: &self.buffer,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(self.padded_row),
                    rows_per_image: Some(self.rows),
                },
            },
            extent,
        );
    }

    /// Records the copy of the whole of `source` (one row of `row_bytes`) into the buffer.
    pub(crate) fn encode_copy_buffer(&self, encoder: &mut wgpu::CommandEncoder, source: &wgpu::Buffer) {
        encoder.copy_buffer_to_buffer(source, 0, &self.buffer, 0, u64::from(self.row_bytes));
    }

    /// Requests the mapping of the whole buffer, once the copy is submitted; `done` gets the
    /// result when the device is next polled.
    pub(crate) fn map(&self, done: impl FnOnce(Result<(), wgpu::BufferAsyncError>) + Send + 'static) {
        self.buffer.map_async(wgpu::MapMode::Read, .., done);
    }

    /// The rows of the mapped buffer without their padding, concatenated; unmaps it.
    pub(crate) fn take(&self) -> Result<Vec<u8>, ReadbackError> {
        let bytes = {
            let view = self
                .buffer
                .get_mapped_range(..)
                .map_err(|e| ReadbackError::NotMapped { what: self.what, message: e.to_string() })?;
            let row = self.row_bytes as usize;
            view.chunks_exact(self.padded_row as usize).flat_map(|r| &r[..row]).copied().collect()
        };
        self.buffer.unmap();
        Ok(bytes)
    }

    /// Maps the buffer (after a submitted [`Readback::encode_copy`]), waits for the GPU and
    /// returns the rows: blocking.
    pub(crate) fn read(&self, device: &wgpu::Device) -> Result<Vec<u8>, ReadbackError> {
        let (tx, rx) = mpsc::channel();
        self.map(move |result| {
            // The receiver is gone only if `read` already returned (a failed wait).
            let _ = tx.send(result);
        });
        let what = self.what;
        device.poll(wgpu::PollType::wait_indefinitely()).map_err(|source| ReadbackError::Wait { what, source })?;
        match rx.try_recv() {
            Ok(Ok(())) => self.take(),
            Ok(Err(source)) => Err(ReadbackError::Map { what, source }),
            Err(_) => Err(ReadbackError::NotMapped {
                what,
                message: "the GPU finished without answering the map request".into(),
            }),
        }
    }
}
