//! The banded, parallel pipeline against the naive whole-image oracle.

use crate::common::*;
use proptest::prelude::*;
use vortex_tiler::background::Background;
use vortex_tiler::pyramid::Filter;
use vortex_tiler::split::SplitOptions;

const FILTERS: [Filter; 6] = Filter::ALL;

fn check(image: &Image, tile: u32, border: u32, background: Background, threads: usize) {
    check_filtered(image, tile, border, background, threads, Filter::Box)
}

fn check_filtered(image: &Image, tile: u32, border: u32, background: Background, threads: usize, filter: Filter) {
    let opts = SplitOptions { filter, ..png_options(tile, border, background) };
    let (summary, got) = run_pipeline(image, &opts, threads);
    let want = naive_tiles(image, &opts);
    assert_eq!(summary.tiles as usize, want.len());
    assert_eq!(got.len(), want.len(), "tile count");
    for (key, w) in &want {
        let g = &got[key];
        assert!(
            g == w,
            "tile (lod, x, y) = {key:?} differs for {}x{} {} tile {tile} border {border} {background} filter {filter}",
            image.width,
            image.height,
            image.layout
        );
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, .. ProptestConfig::default() })]

    #[test]
    fn pipeline_matches_oracle(
        w in 1u32..70,
        h in 1u32..70,
        layout_idx in 0usize..8,
        tile in 8u32..24,
        border in 0u32..3,
        colour in proptest::option::of(any::<[u8; 4]>()),
        threads in 1usize..4,
        seed in any::<u64>(),
    ) {
        let layout = layouts()[layout_idx];
        let image = Image::random(w, h, layout, seed);
        let background = colour.map_or(Background::Edge, Background::Colour);
        check(&image, tile, border, background, threads);
    }

    /// Every filter, streamed in bands, against its whole-image definition.
    #[test]
    fn every_filter_matches_its_oracle(
        w in 1u32..70,
        h in 1u32..70,
        layout_idx in 0usize..8,
        filter_idx in 0usize..FILTERS.len(),
        tile in 8u32..24,
        border in 0u32..3,
        threads in 1usize..3,
        seed in any::<u64>(),
    ) {
        let image = Image::random(w, h, layouts()[layout_idx], seed);
        check_filtered(&image, tile, border, Background::Edge, threads, FILTERS[filter_idx]);
    }
}

#[test]
fn thin_and_tiny_images() {
    let rgb = layouts()[4];
    for (w, h) in [(1, 1), (1, 37), (37, 1), (2, 2), (17, 16), (16, 17), (33, 65)] {
        check(&Image::random(w, h, rgb, w as u64 * 31 + h as u64), 16, 2, Background::Edge, 2);
    }
}

#[test]
fn odd_tiny_and_just_over_a_tile_sizes_for_every_filter() {
    // 1x1, 1xN, Nx1, 2^k - 1, 2^k + 1, and one texel past a multiple of the 12-texel payload.
    let sizes = [(1, 1), (1, 33), (33, 1), (63, 65), (65, 63), (2, 129), (25, 37), (37, 25)];
    for filter in FILTERS {
        for (i, (w, h)) in sizes.into_iter().enumerate() {
            let layout = layouts()[[7, 3, 5, 0][i % 4]];
            check_filtered(&Image::random(w, h, layout, i as u64), 16, 2, Background::Edge, 2, filter);
        }
    }
}

#[test]
fn output_does_not_depend_on_thread_count() {
    let image = Image::random(150, 97, layouts()[7], 7);
    let opts = png_options(32, 2, Background::Colour([10, 20, 30, 40]));
    let (_, one) = run_pipeline(&image, &opts, 1);
    let (_, four) = run_pipeline(&image, &opts, 4);
    assert_eq!(one, four);
}
