//! Every blocking readback on a lost device (`Device::destroy`, as a driver reset or a removed
//! GPU leaves it) returns a `ReadbackError` that names what it was reading, instead of
//! panicking in a map callback or waiting forever. Device conventions as in `sample.rs`.

use std::sync::Arc;

use vortex_vt::page::TextureGrid;
use vortex_vt_wgpu::harness::camera::Keyframe;
use vortex_vt_wgpu::harness::probe::AddressProbe;
use vortex_vt_wgpu::harness::{Effects, Scene, SceneRenderer, SceneView, View, Window, WindowKey};
use vortex_vt_wgpu::{
    CacheFormat, FeedbackBuffer, FeedbackReadback, Gpu, Pacing, PageCache, PageSource, ReadbackError, VirtualTexture,
};

use crate::common::gpu;
use crate::common::pyramid::Synthetic;

/// Destroys the device. Work recorded on it afterwards is invalid: wgpu reports that to the
/// uncaptured-error handler, whose default panics, so the test's handler only prints it.
fn lose(gpu: &Gpu) {
    gpu.device.on_uncaptured_error(Arc::new(|e| eprintln!("after the loss, as expected: {e}")));
    gpu.device.destroy();
}

#[test]
fn reading_back_from_a_lost_device_is_an_error_naming_what_was_read() {
    let Some(gpu) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let tex = Synthetic::new(dir.path(), "a.vtpk", 4, 16, 1, 0);
    let key = Keyframe { frame: 0, at: WindowKey { center: [0.5, 0.5], width: 1.0 } };
    let scene = Scene {
        textures: vec![],
        layers: vec![],
        size: [16, 16],
        frames: 1,
        view: SceneView::Window { texture: 0, path: vec![key] },
        effects: Effects::default(),
    };
    let sources = vec![tex.pack.clone() as Arc<dyn PageSource>];
    let renderer = SceneRenderer::new(gpu, sources, &scene, Pacing::Offline).unwrap();
    let pose = scene.pose(0, renderer.runtime().textures());
    let gpu = renderer.gpu();
    let cache = PageCache::new(&gpu.device, 2, 16, 1, CacheFormat::Rgba8).unwrap();
    let feedback = FeedbackBuffer::new(&gpu.device, 32, 32, 8);
    let mut ring = FeedbackReadback::new(&gpu.device, &feedback, 2);
    let texture = VirtualTexture::filling(TextureGrid::new(4, 4).unwrap(), 16, 1);
    let probe = AddressProbe::new(gpu, &[texture]);
    let mut encoder = gpu.device.create_command_encoder(&Default::default());
    assert_eq!(ring.encode_copy(&mut encoder, &feedback), Some(0));
    gpu.queue.submit([encoder.finish()]);
    lose(gpu);
    ring.submitted();

    let err = renderer.still(&pose, None).unwrap_err();
    assert!(err.to_string().starts_with("reading back the target: "), "{err}");
    let err = ring.read_now(&gpu.device).unwrap_err();
    assert!(matches!(err, ReadbackError::Feedback { frame: 0, .. } | ReadbackError::Wait { .. }), "{err}");
    assert!(err.to_string().starts_with("reading back the feedback"), "{err}");
    assert_eq!(ring.in_flight(), 0, "the failed frame's buffer is free again");
    let err = cache.read_slot(gpu, 0).unwrap_err();
    assert!(err.to_string().starts_with("reading back the slot: "), "{err}");
    let window = Window { texture: 0, origin: [0.0, 0.0], extent: [1.0, 1.0] };
    let err = probe.addresses(gpu, &View::Window(window), 0, 8, 8).unwrap_err();
    assert!(err.to_string().starts_with("reading back the probe: "), "{err}");
    // Waiting for a lost device returns (Ok, or the error wgpu gives), without a panic.
    let _ = gpu.wait_idle();
}
