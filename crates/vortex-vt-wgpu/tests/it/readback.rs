//! Every blocking readback on a lost device (`Device::destroy`, as a driver reset or a removed
//! GPU leaves it) returns a `ReadbackError` that names what it was reading, instead of
//! panicking in a map callback or waiting forever. Device conventions as in `sample.rs`.

use std::sync::Arc;

use vortex_vt::page::TextureGrid;
use vortex_vt_wgpu::probe::AddressProbe;
use vortex_vt_wgpu::{
    CacheFormat, FeedbackReadback, FeedbackTarget, Gpu, PageCache, ReadbackError, RenderTarget, View, VirtualTexture,
    Window,
};

use crate::common::gpu;

/// Destroys the device. Work recorded on it afterwards is invalid: wgpu reports that to the
/// uncaptured-error handler, whose default panics, so the test's handler only prints it.
fn lose(gpu: &Gpu) {
    gpu.device.on_uncaptured_error(Arc::new(|e| eprintln!("after the loss, as expected: {e}")));
    gpu.device.destroy();
}

#[test]
fn reading_back_from_a_lost_device_is_an_error_naming_what_was_read() {
    let Some(gpu) = gpu() else { return };
    let target = RenderTarget::new(&gpu.device, 16, 16);
    let cache = PageCache::new(&gpu.device, 2, 16, 1, CacheFormat::Rgba8).unwrap();
    let feedback = FeedbackTarget::with_size(&gpu.device, 4, 4, 32, 32);
    let mut ring = FeedbackReadback::new(&gpu.device, 4, 4, 2);
    let probe = AddressProbe::new(&gpu.device);
    let mut encoder = gpu.device.create_command_encoder(&Default::default());
    target.encode_copy_out(&mut encoder);
    assert_eq!(ring.encode_copy(&mut encoder, &feedback), Some(0));
    gpu.queue.submit([encoder.finish()]);
    lose(&gpu);
    ring.submitted();

    let err = target.read(&gpu).unwrap_err();
    assert!(err.to_string().starts_with("reading back the target: "), "{err}");
    let err = ring.read_now(&gpu.device).unwrap_err();
    assert!(matches!(err, ReadbackError::Feedback { frame: 0, .. } | ReadbackError::Wait { .. }), "{err}");
    assert!(err.to_string().starts_with("reading back the feedback"), "{err}");
    assert_eq!(ring.in_flight(), 0, "the failed frame's buffer is free again");
    let err = cache.read_slot(&gpu, 0).unwrap_err();
    assert!(err.to_string().starts_with("reading back the slot: "), "{err}");
    let texture = VirtualTexture::filling(TextureGrid::new(4, 4).unwrap(), 16, 1);
    let window = Window { texture: 0, origin: [0.0, 0.0], extent: [1.0, 1.0] };
    let err = probe.addresses(&gpu, &[texture], &View::Window(window), 0, 8, 8).unwrap_err();
    assert!(err.to_string().starts_with("reading back the probe: "), "{err}");
    // Waiting for a lost device returns (Ok, or the error wgpu gives), without a panic.
    let _ = gpu.wait_idle();
}
