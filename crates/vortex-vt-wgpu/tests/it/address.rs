//! The shaders' address translation on lavapipe, held against the CPU mirror
//! (`vortex_vt::address`) and against exact f64 arithmetic at the largest virtual size the
//! feedback word addresses (4096 pages of 1016 texels: about 2^22 texels per side), with
//! non-dyadic windows; and LOD selection exactly at powers of two, which must not flicker from
//! frame to frame. Device conventions as in `sample.rs` (see `common`).

use crate::common::gpu;
use vortex_vt::feedback::decode;
use vortex_vt::page::TextureGrid;
use vortex_vt_wgpu::VirtualTexture;
use vortex_vt_wgpu::harness::probe::{AddressProbe, FeedbackProbe};
use vortex_vt_wgpu::harness::{View, Window};

const SIZE: u32 = 64;

#[test]
fn window_addresses_stay_within_a_sixteenth_of_a_texel_at_the_largest_size() {
    let Some(gpu) = gpu() else { return };
    let texture = VirtualTexture::filling(TextureGrid::new(4096, 4096).unwrap(), 1024, 4);
    let payload = texture.payload();
    let side = texture.width as f64;
    let probe = AddressProbe::new(&gpu, &[texture]);
    let mut worst_exact: f64 = 0.0;
    let mut worst_mirror: f64 = 0.0;
    // (origin, texels per pixel, LOD): deep inside the texture, near its far edge, minified.
    for &(o, step, lod) in &[
        ([0.7316514, 0.2113], 0.371, 0u8),
        ([0.99991, 0.999], 0.913, 0),
        ([0.5123417, 0.6], 3.1, 1),
        ([0.3331, 0.0711], 27.3, 4),
    ] {
        let extent = step * SIZE as f64 / side;
        let window = Window { texture: 0, origin: o, extent: [extent, extent] };
        let addresses = probe.addresses(&gpu, &View::Window(window), lod, SIZE, SIZE).unwrap();
        let mirror = window.origin_texels(&texture, (SIZE, SIZE));
        for (i, got) in addresses.iter().enumerate() {
            let (x, y) = (i as u32 % SIZE, i as u32 / SIZE);
            let want = mirror.at(x as f32 + 0.5, y as f32 + 0.5, lod, texture.size(), payload);
            for axis in 0..2 {
                let texel = |page: u32, within: f32| page as f64 * payload as f64 + within as f64;
                let pixel = [x, y][axis] as f64 + 0.5;
                let exact = (o[axis] * side + pixel * step) / (1u64 << lod) as f64;
                let g = texel(got.page[axis], got.within[axis]);
                worst_exact = worst_exact.max((g - exact).abs());
                worst_mirror = worst_mirror.max((g - texel(want.page[axis], want.within[axis])).abs());
            }
        }
    }
    eprintln!("largest size: worst error {worst_exact:.5} texel against f64, {worst_mirror:.6} against the CPU mirror");
    assert!(worst_exact <= 1.0 / 16.0, "{worst_exact} texel");
    assert!(worst_mirror <= 1.0 / 256.0, "{worst_mirror} texel");
}

#[test]
fn lod_selection_at_exact_powers_of_two_is_stable() {
    let Some(gpu) = gpu() else { return };
    let grid = TextureGrid::new(64, 64).unwrap();
    let texture = VirtualTexture::filling(grid, 136, 4);
    // Blocks of one pixel: every pixel writes its word, every frame (no bias); 2, 4 and 8
    // texels per pixel exactly.
    let mut probe = FeedbackProbe::new(&gpu, &[texture], SIZE, SIZE, 1, 2);
    for k in 1..=3u8 {
        let extent = (1u32 << k) as f64 * SIZE as f64 / texture.width as f64;
        let view = View::Window(Window { texture: 0, origin: [0.2371, 0.4113], extent: [extent, extent] });
        let mut first = None;
        for frame in 0..4 {
            probe.submit(&gpu, Some(&view), frame, 0.0).unwrap();
            let words = probe.readback().read_now(&gpu.device).unwrap().unwrap().words;
            assert_eq!(words.len(), (SIZE * SIZE) as usize);
            assert!(words.iter().all(|&w| decode(w).unwrap().lod == k), "2^{k} texels per pixel is LOD {k}");
            match &first {
                None => first = Some(words),
                Some(f) => assert_eq!(f, &words, "the same view gives the same words"),
            }
        }
    }
}
