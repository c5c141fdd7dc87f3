//! `examples/embed.rs`, run as it is (its source is compiled into this test): an application's own
//! device, pipeline and shader drawing a pack through the module. Its quad fills a frame of the
//! image's size, so once the pages have landed its picture must be the pack's LOD 0, within the
//! GPU's rounding.

use vortex_pack::TileKind;
use vortex_vt::sampler::Rgba8Image;
use vortex_vt_wgpu::VirtualTexture;
use vortex_vt_wgpu::testing::{box_chain, write_pack};

use crate::common::gpu;

#[allow(dead_code, reason = "the example's `main` is not called here, its `run` is")]
#[path = "../../examples/embed.rs"]
mod example;

#[test]
fn the_embed_example_draws_the_pack_as_the_reference_sampler_does() {
    // Only for the note and the lavapipe pinning: the example makes its own device.
    if gpu().is_none() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    // 300 x 180 texels in 62-texel payloads (tile 64, border 1): 5 x 3 pages at LOD 0, sides
    // multiples of neither the payload nor a power of two.
    let lod0 = Rgba8Image::from_fn(300, 180, |x, y| {
        [(x * 7 + y * 3) as u8, ((x * x) / 7 + y * 5) as u8, ((x ^ y) * 13) as u8, 255]
    });
    let texture = VirtualTexture::new(300, 180, 64, 1).unwrap();
    let chain = box_chain(lod0.clone(), texture.grid.lod_count());
    let pack = dir.path().join("embed.vtpk");
    write_pack(&pack, &chain, &texture, TileKind::Raw).unwrap();
    let out = dir.path().join("out.png");
    example::run(&pack, &out, 40).unwrap();

    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&out).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut pixels = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut pixels).unwrap();
    assert_eq!((info.width, info.height), (300, 180));
    let mut worst = (0, 0, 0);
    for (i, (got, want)) in pixels.chunks_exact(4).zip(&lod0.texels).enumerate() {
        let off = (0..3).map(|c| got[c].abs_diff(want[c])).max().unwrap();
        if off > worst.0 {
            worst = (off, i % 300, i / 300);
        }
    }
    assert!(worst.0 <= 1, "{} code values off at ({}, {})", worst.0, worst.1, worst.2);
}
