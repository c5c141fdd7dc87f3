//! Vertical stripes: an image cut under a `--max-memory` too small for one band gives the
//! same tiles as one band, and both match the naive whole-image oracle.

use crate::common::*;
use proptest::prelude::*;
use vortex_tiler::background::Background;
use vortex_tiler::error::TilerError;
use vortex_tiler::layout::Layout;
use vortex_tiler::pyramid::Filter;
use vortex_tiler::split::{SplitOptions, split};
use vortex_tiler::testing::one_band_bytes;

const EXACT: [Filter; 4] = [Filter::Box, Filter::Linear, Filter::Premultiplied, Filter::LinearPremultiplied];

/// Encoded tiles by (lod, x, y).
type Encoded = std::collections::BTreeMap<(u32, u32, u32), Vec<u8>>;

/// The passes over the source and the encoded tiles of a run under `max_memory`, or `None` when the
/// budget cannot hold even one stripe.
fn run(image: &Image, opts: &SplitOptions) -> Option<(usize, Encoded)> {
    let sink = MemSink::default();
    match split(image.source(), &sink, opts, &()) {
        Ok(summary) => Some((summary.passes, sink.tiles.into_inner().unwrap())),
        Err(TilerError::Limit(_)) => None,
        Err(e) => panic!("{e}"),
    }
}

fn budget(image: &Image, opts: &SplitOptions, fraction: f64) -> u64 {
    let layout = Layout::new(image.width as u64, image.height as u64, opts.tile_size, opts.border).unwrap();
    (one_band_bytes(&layout, image.layout.bytes_per_pixel() as u64) as f64 * fraction) as u64
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 40, max_global_rejects: 4096, .. ProptestConfig::default() })]

    #[test]
    fn stripes_give_the_tiles_of_one_band(
        w in 40u32..700,
        h in 1u32..40,
        layout_idx in 0usize..8,
        filter_idx in 0usize..EXACT.len(),
        tile in 8u32..24,
        border in 0u32..3,
        colour in proptest::option::of(any::<[u8; 4]>()),
        fraction in 0.05f64..0.9,
        seed in any::<u64>(),
    ) {
        let image = Image::random(w, h, layouts()[layout_idx], seed);
        let background = colour.map_or(Background::Edge, Background::Colour);
        let opts = SplitOptions { filter: EXACT[filter_idx], ..png_options(tile, border, background) };
        let striped_opts = SplitOptions { max_memory: budget(&image, &opts, fraction), ..opts.clone() };
        let striped = run(&image, &striped_opts);
        prop_assume!(striped.is_some());
        let (passes, striped) = striped.unwrap();
        prop_assert!(passes > 1);
        let (one, whole) = run(&image, &opts).unwrap();
        prop_assert_eq!(one, 1);
        prop_assert!(striped == whole, "{}x{} {} tile {} border {}: {} passes differ", w, h, image.layout, tile, border, passes);
        // And both are the oracle's (decoded).
        let want = naive_tiles(&image, &opts);
        prop_assert_eq!(striped.len(), want.len());
        for (key, png) in &striped {
            prop_assert!(decode_png(png) == want[key], "tile {:?}", key);
        }
    }
}

#[test]
fn a_wide_strip_is_cut_in_many_stripes() {
    // 3000 x 5 RGBA 16-bit: 250 pages of 12 texels at LOD 0, 9 LODs.
    let image = Image::random(3000, 5, layouts()[7], 7);
    let opts = SplitOptions { filter: Filter::LinearPremultiplied, ..png_options(16, 2, Background::Edge) };
    let (passes, striped) =
        run(&image, &SplitOptions { max_memory: budget(&image, &opts, 0.17), ..opts.clone() }).unwrap();
    assert!(passes >= 8, "{passes} passes");
    assert!(striped == run(&image, &opts).unwrap().1);
}

#[test]
fn resampling_filters_say_they_cannot_be_striped() {
    let image = Image::random(3000, 5, layouts()[2], 7);
    let opts = SplitOptions { filter: Filter::Lanczos3, ..png_options(16, 2, Background::Edge) };
    let sink = MemSink::default();
    let e = split(image.source(), &sink, &SplitOptions { max_memory: budget(&image, &opts, 0.1), ..opts }, &())
        .unwrap_err()
        .to_string();
    assert!(e.contains("lanczos3") && e.contains("--max-memory"), "{e}");
}

/// A PPM reads only each stripe's columns (seeking in the file); the tiles are those of one band.
#[test]
fn a_ppm_is_read_a_stripe_at_a_time() {
    let dir = tempfile::tempdir().unwrap();
    let image = Image::random(2500, 9, layouts()[4], 11);
    let path = dir.path().join("wide.ppm");
    let mut bytes = b"P6\n2500 9\n255\n".to_vec();
    bytes.extend(image.samples.iter().map(|s| *s as u8));
    std::fs::write(&path, bytes).unwrap();
    let opts = SplitOptions { filter: Filter::LinearPremultiplied, ..png_options(16, 2, Background::Edge) };
    let tiles = |max_memory: u64| {
        let sink = MemSink::default();
        let source = vortex_tiler::source::open(&path, vortex_tiler::limits::Budget::new(1 << 30)).unwrap();
        let summary = split(source, &sink, &SplitOptions { max_memory, ..opts.clone() }, &()).unwrap();
        (summary.passes, sink.tiles.into_inner().unwrap())
    };
    let (passes, striped) = tiles(budget(&image, &opts, 0.25));
    assert!(passes > 2, "{passes} passes");
    let (one, whole) = tiles(1 << 30);
    assert_eq!(one, 1);
    assert!(striped == whole);
}
