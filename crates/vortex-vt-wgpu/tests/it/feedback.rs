//! The module's feedback (`vt_feedback_texel`, called from every fragment of the harness's window
//! shader) against `vortex_vt`'s CPU mirror of it: windows of a 16x16-page virtual texture
//! (120-texel pages) are drawn as 324x244 frames with feedback blocks of 8 pixels (41 x 31
//! blocks, the last column and row only 4 pixels deep), read back through the ring, and compared
//! word for word with `WindowOrigin::lod` + `WindowOrigin::at` + `encode` at the centre of each
//! block's elected pixel (`feedback::elected`), which moves every frame; a block whose elected
//! pixel lies past the frame's edge asks for nothing. The words are then run through
//! `vortex_vt::analysis`. And over `block²` frames every pixel of a block is heard: each block's
//! words over 64 frames are exactly the words of its 64 pixels. Device conventions as in
//! `sample.rs` (see `common`).

use std::collections::{BTreeMap, BTreeSet};

use crate::common::gpu;
use vortex_vt::analysis::analyze;
use vortex_vt::feedback::{NO_REQUEST, encode};
use vortex_vt::page::{PageId, TextureGrid};
use vortex_vt_wgpu::feedback::elected;
use vortex_vt_wgpu::harness::probe::FeedbackProbe;
use vortex_vt_wgpu::harness::{View, Window};
use vortex_vt_wgpu::{Gpu, VirtualTexture};

const PAGES: u16 = 16;
const PAYLOAD: u32 = 120;
const FRAME: (u32, u32) = (324, 244);
const BLOCK: u32 = 8;
const BLOCKS: (u32, u32) = (41, 31);

/// A window and the LOD bias the frame asks with (the residency's, when oversubscribed).
#[derive(Clone, Copy, Debug)]
struct Case {
    window: Window,
    bias: f32,
}

fn view(texture: u8, origin: [f64; 2], extent: [f64; 2], bias: f32) -> Case {
    Case { window: Window { texture, origin, extent }, bias }
}

/// Sixteen textures of the same shape, so that any texture id of a word can be tried.
fn textures() -> Vec<VirtualTexture> {
    vec![VirtualTexture::filling(TextureGrid::new(PAGES.into(), PAGES.into()).unwrap(), PAYLOAD + 8, 4); 16]
}

/// What the shader must write as frame `frame`: per block, `encode` of the page holding the
/// address of its elected pixel's centre at the LOD of the window's footprint, or `NO_REQUEST`
/// where that pixel lies past the frame. Also asserts that the view keeps every elected pixel
/// clear of rounding: no position within a hundredth of a texel of a page edge, no footprint
/// near a LOD boundary, so that bit-exactness is a fair demand.
fn expected(c: &Case, frame: u64) -> Vec<u32> {
    let (w, h) = FRAME;
    let texture = textures()[0];
    let origin = c.window.origin_texels(&texture, FRAME);
    let grid = texture.grid;
    let lod = origin.lod(c.bias, grid.lod_count());
    let f = origin.step[0].max(origin.step[1]).log2() + c.bias;
    assert!((f - f.round()).abs() > 1e-3, "footprint {f} is too close to a LOD boundary");
    let side = texture.width as f64;
    assert_eq!(texture.width, texture.height);
    let page_texels = (PAYLOAD << lod) as f64;
    let [ex, ey] = elected(frame, BLOCK);
    let mut words = Vec::with_capacity((BLOCKS.0 * BLOCKS.1) as usize);
    for by in 0..BLOCKS.1 {
        for bx in 0..BLOCKS.0 {
            let (x, y) = (bx * BLOCK + ex, by * BLOCK + ey);
            if x >= w || y >= h {
                words.push(NO_REQUEST);
                continue;
            }
            let at = origin.at(x as f32 + 0.5, y as f32 + 0.5, lod, texture.size(), PAYLOAD);
            for (i, uv) in c.window.uv(x, y, FRAME).into_iter().enumerate() {
                let texel = uv * side;
                let edge = (texel / page_texels).round() * page_texels;
                assert!(
                    (texel - edge).abs() > 0.01 || texel <= 0.0 || texel >= side,
                    "pixel ({x}, {y}) axis {i} is on a page edge"
                );
            }
            words.push(encode(PageId::new(c.window.texture, lod, at.page[0] as u16, at.page[1] as u16), &grid));
        }
    }
    words
}

/// Blocks whose elected pixel lies in the frame, in frame `frame`.
fn inside(frame: u64) -> usize {
    let [ex, ey] = elected(frame, BLOCK);
    let columns = (0..BLOCKS.0).filter(|bx| bx * BLOCK + ex < FRAME.0).count();
    let rows = (0..BLOCKS.1).filter(|by| by * BLOCK + ey < FRAME.1).count();
    columns * rows
}

fn probe(gpu: &Gpu, ring: usize) -> FeedbackProbe {
    let probe = FeedbackProbe::new(gpu, &textures(), FRAME.0, FRAME.1, BLOCK, ring);
    assert_eq!((probe.feedback().columns, probe.feedback().rows), BLOCKS);
    probe
}

/// Draws `case` as frame `frame` and reads the words back, blocking.
fn render(gpu: &Gpu, probe: &mut FeedbackProbe, case: Option<&Case>, frame: u64) -> Vec<u32> {
    let view = case.map(|c| View::Window(c.window));
    let copy = probe.submit(gpu, view.as_ref(), frame, case.map_or(0.0, |c| c.bias)).expect("a free buffer");
    let got = probe.readback().read_now(&gpu.device).unwrap().expect("a frame in flight");
    assert_eq!((got.frame, got.columns, got.rows), (copy, BLOCKS.0, BLOCKS.1));
    got.words
}

#[test]
fn words_at_the_elected_pixels_match_the_cpu_mirror_and_analysis_finds_the_pages() {
    let Some(gpu) = gpu() else { return };
    let mut probe = probe(&gpu, 2);
    let grid = TextureGrid::new(PAGES.into(), PAGES.into()).unwrap();
    // (view, the LOD it must ask for): non-dyadic windows; the footprint in texels per pixel is
    // max(extent.x * 5.93, extent.y * 7.87), plus the bias.
    let cases = [
        (view(0, [0.137, 0.291], [0.15, 0.2], 0.0), 0),
        (view(5, [0.213, 0.058], [0.31, 0.37], 0.0), 1),
        (view(5, [0.05, 0.11], [0.83, 0.71], 0.0), 2),
        // Beyond the texture on every side: pages clamp to the grid, derivatives do not.
        (view(9, [-0.3, -0.2], [1.9, 1.5], 0.0), 3),
        // The whole texture with a bias pushing past the root: clamped to it.
        (view(15, [0.0, 0.0], [1.0, 1.0], 1.5), 4),
        // A negative bias (never the residency's, but the shader must add, not clamp, it).
        (view(3, [0.213, 0.058], [0.31, 0.37], -1.0), 0),
    ];
    for (v, lod) in &cases {
        // Four frames, four elected pixels: the first is the blocks' centre, which reaches past
        // the frame's right and bottom edges in the last column and row.
        for frame in 0..4 {
            let want = expected(v, frame);
            let samples = inside(frame);
            assert!(
                want.iter().filter(|&&w| w != NO_REQUEST).all(|&w| w >> 24 & 0xF == *lod),
                "{v:?} asks for LOD {lod}"
            );
            assert_eq!(want.iter().filter(|&&w| w != NO_REQUEST).count(), samples);
            let got = render(&gpu, &mut probe, Some(v), frame);
            let wrong: Vec<_> = (0..want.len()).filter(|&i| got[i] != want[i]).collect();
            assert!(
                wrong.is_empty(),
                "{v:?}, frame {frame}: {} of {} words differ; first at block ({}, {}): got {:#010x}, want {:#010x}",
                wrong.len(),
                want.len(),
                wrong[0] as u32 % BLOCKS.0,
                wrong[0] as u32 / BLOCKS.0,
                got[wrong[0]],
                want[wrong[0]]
            );

            // Analysis of the read-back words: every requested page with its sample count, plus
            // its ancestors, nothing resident.
            let mut direct: BTreeMap<PageId, u32> = BTreeMap::new();
            for &w in want.iter().filter(|&&w| w != NO_REQUEST) {
                let p = vortex_vt::feedback::decode(w).and_then(|r| r.page(&[grid; 16])).unwrap();
                *direct.entry(p).or_default() += 1;
            }
            let all: BTreeSet<PageId> = direct.keys().flat_map(|p| p.ancestors_and_self(&grid)).collect();
            let a = analyze(&got, &[grid; 16], |_| None);
            let blocks = (BLOCKS.0 * BLOCKS.1) as usize;
            assert_eq!(
                (a.samples, a.no_request, a.invalid, a.requested),
                (samples as u32, (blocks - samples) as u32, 0, direct.len())
            );
            let pages: BTreeSet<PageId> = a.requests.iter().map(|r| r.page).collect();
            assert_eq!(pages, all, "{v:?}");
            for r in &a.requests {
                assert_eq!(r.direct, direct.get(&r.page).copied().unwrap_or(0), "{:?}", r.page);
                assert_eq!(r.distance, grid.lod_count() - r.page.lod, "{:?}", r.page);
            }
            let root = a.requests.iter().find(|r| r.page == grid.root(v.window.texture)).unwrap();
            assert_eq!(root.samples as usize, samples);
            if frame == 0 {
                eprintln!("{v:?}: LOD {lod}, {} pages requested, {} with ancestors", direct.len(), all.len());
            }
        }
    }
    // The centre's frame loses the last column and row; frame 1 (x 1/2, y 0) only the column.
    assert_eq!((inside(0), inside(1)), (40 * 30, 40 * 31));
}

#[test]
fn over_block_squared_frames_every_pixel_of_a_block_is_heard() {
    let Some(gpu) = gpu() else { return };
    // 256 x 256 pages of 16 texels, no border: the whole image is 12.6 texels per pixel; asked 4
    // LODs finer (LOD 0), each 8-pixel block spans about 6 x 6 pages, so that its 64 pixels see
    // about 40 different pages.
    let fine = [VirtualTexture::filling(TextureGrid::new(256, 256).unwrap(), 16, 0)];
    let case = view(0, [0.0, 0.0], [1.0, 1.0], -4.0);
    let mut probe = FeedbackProbe::new(&gpu, &fine, FRAME.0, FRAME.1, BLOCK, 2);
    // The words of every pixel: the same window through blocks of one pixel.
    let mut pixels = FeedbackProbe::new(&gpu, &fine, FRAME.0, FRAME.1, 1, 1);
    pixels.submit(&gpu, Some(&View::Window(case.window)), 0, case.bias).unwrap();
    let every = pixels.readback().read_now(&gpu.device).unwrap().unwrap().words;
    assert!(every.iter().all(|&w| w != NO_REQUEST && w >> 24 & 0xF == 0));
    // Per block, the pages its pixels see.
    let mut per_block = vec![BTreeSet::new(); (BLOCKS.0 * BLOCKS.1) as usize];
    for y in 0..FRAME.1 {
        for x in 0..FRAME.0 {
            per_block[((y / BLOCK) * BLOCKS.0 + x / BLOCK) as usize].insert(every[(y * FRAME.0 + x) as usize]);
        }
    }
    let mut heard = vec![BTreeSet::new(); per_block.len()];
    // Blocks whose every page was heard.
    let full = |heard: &[BTreeSet<u32>]| {
        heard.iter().zip(&per_block).filter(|(h, all)| h.iter().filter(|&&w| w != NO_REQUEST).eq(all.iter())).count()
    };
    // Start anywhere in the sequence: any block² consecutive frames will do.
    let first = 13;
    for frame in first..first + u64::from(BLOCK * BLOCK) {
        let words = render(&gpu, &mut probe, Some(&case), frame);
        for (h, w) in heard.iter_mut().zip(words) {
            h.insert(w);
        }
        if frame == first {
            let after_one = full(&heard);
            assert_eq!(after_one, 0, "one frame hears every page of {after_one} blocks: a trivial view");
        }
    }
    let complete = full(&heard);
    assert_eq!(complete, heard.len(), "blocks whose pixels' pages were not all heard in 64 frames");
    let most = per_block.iter().map(BTreeSet::len).max().unwrap();
    eprintln!("every block heard all its pages (up to {most}) within 64 frames");
    assert!(most >= 30, "{most} pages at most in a block");
}

#[test]
fn nothing_drawn_reads_no_request() {
    let Some(gpu) = gpu() else { return };
    let mut probe = probe(&gpu, 2);
    // A frame with feedback first, so that the clear has something to overwrite.
    let words = render(&gpu, &mut probe, Some(&view(0, [0.0; 2], [1.0; 2], 0.0)), 0);
    assert!(words.iter().any(|&w| w != NO_REQUEST));
    let words = render(&gpu, &mut probe, None, 1);
    assert!(words.iter().all(|&w| w == NO_REQUEST));
    let a = analyze(&words, &[TextureGrid::new(PAGES.into(), PAGES.into()).unwrap()], |_| None);
    assert_eq!((a.samples, a.no_request, a.requests.len()), (0, BLOCKS.0 * BLOCKS.1, 0));
}

#[test]
fn the_ring_reads_frames_in_order_without_blocking() {
    let Some(gpu) = gpu() else { return };
    let mut probe = probe(&gpu, 2);
    let views = [view(1, [0.137, 0.291], [0.15, 0.2], 0.0), view(2, [0.213, 0.058], [0.31, 0.37], 0.0)];
    let submit = |probe: &mut FeedbackProbe, case: &Case, frame| {
        probe.submit(&gpu, Some(&View::Window(case.window)), frame, case.bias)
    };
    assert_eq!(submit(&mut probe, &views[0], 0), Some(0));
    assert_eq!(submit(&mut probe, &views[1], 1), Some(1));
    assert_eq!(probe.readback().in_flight(), 2);
    // Both buffers in flight: the third frame's feedback is skipped, not waited for.
    assert_eq!(submit(&mut probe, &views[0], 2), None);
    // try_read never blocks. The event it waits for is the GPU finishing the frames submitted:
    // once the device says it has (and has run the mapping callbacks), the oldest frame is there.
    gpu.device.poll(wgpu::PollType::wait_indefinitely()).unwrap();
    let first = probe.readback().try_read(&gpu.device).unwrap().expect("frame 0 is read once the GPU is done");
    assert_eq!(first.frame, 0, "the oldest frame first");
    assert_eq!(first.words, expected(&views[0], 0));
    let second = probe.readback().read_now(&gpu.device).unwrap().unwrap();
    assert_eq!(second.frame, 1);
    assert_eq!(second.words, expected(&views[1], 1));
    assert_eq!(probe.readback().in_flight(), 0);
    assert_eq!(probe.readback().try_read(&gpu.device).unwrap(), None);
    assert_eq!(probe.readback().read_now(&gpu.device).unwrap(), None);
    // The freed buffers take new frames, numbered on.
    assert_eq!(submit(&mut probe, &views[1], 3), Some(2));
    let third = probe.readback().read_now(&gpu.device).unwrap().unwrap();
    assert_eq!((third.frame, third.words), (2, expected(&views[1], 3)));
}
