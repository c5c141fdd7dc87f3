//! The feedback pass against `vortex_vt`'s CPU mirror of its shader: windows of a 16x16-page
//! virtual texture (120-texel pages) are drawn into a 40x30 feedback target standing for a
//! 320x240 frame (so with a LOD bias of -3), read back through the ring, and compared word for
//! word with `WindowOrigin::lod` + `WindowOrigin::at` + `encode` at the same pixel centres; the
//! words are then run through `vortex_vt::analysis`. Device conventions as in `sample.rs` (see
//! `common`).

use std::collections::{BTreeMap, BTreeSet};

use crate::common::gpu;
use vortex_vt::analysis::analyze;
use vortex_vt::feedback::{NO_REQUEST, encode};
use vortex_vt::page::{PageId, TextureGrid};
use vortex_vt_wgpu::{FeedbackPass, FeedbackReadback, FeedbackTarget, Gpu, View, VirtualTexture, Window};

const PAGES: u16 = 16;
const PAYLOAD: u32 = 120;
const FRAME: (u32, u32) = (320, 240);
const DIVISOR: u32 = 8;

/// A window and the frame's own LOD bias.
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

/// What the shader must write: per pixel, `encode` of the page holding the pixel's address at
/// the LOD of the window's footprint. Also asserts that the view keeps every pixel clear of
/// rounding: no position within a hundredth of a texel of a page edge, no footprint near a LOD
/// boundary, so that bit-exactness is a fair demand.
fn expected(c: &Case, target: &FeedbackTarget) -> Vec<u32> {
    let (w, h) = (target.width, target.height);
    let texture = textures()[0];
    let origin = c.window.origin_texels(&texture, (w, h));
    let bias = c.bias + target.bias();
    let grid = texture.grid;
    let lod = origin.lod(bias, grid.lod_count());
    let f = origin.step[0].max(origin.step[1]).log2() + bias;
    assert!((f - f.round()).abs() > 1e-3, "footprint {f} is too close to a LOD boundary");
    let side = texture.width as f64;
    assert_eq!(texture.width, texture.height);
    let page_texels = (PAYLOAD << lod) as f64;
    let mut words = Vec::with_capacity((w * h) as usize);
    for y in 0..h {
        for x in 0..w {
            let at = origin.at(x as f32 + 0.5, y as f32 + 0.5, lod, texture.size(), PAYLOAD);
            for (i, uv) in c.window.uv(x, y, (w, h)).into_iter().enumerate() {
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

struct Fixture {
    gpu: Gpu,
    pass: FeedbackPass,
    target: FeedbackTarget,
    readback: FeedbackReadback,
}

impl Fixture {
    fn new(gpu: Gpu, ring: usize) -> Fixture {
        let pass = FeedbackPass::new(&gpu.device);
        let target = FeedbackTarget::new(&gpu.device, FRAME.0, FRAME.1, DIVISOR);
        assert_eq!((target.width, target.height), (40, 30));
        assert_eq!(target.bias(), -3.0);
        let readback = FeedbackReadback::new(&gpu.device, target.width, target.height, ring);
        Fixture { gpu, pass, target, readback }
    }

    /// Records and submits the pass and the copy; the frame number, or `None` if the ring is full.
    fn submit(&mut self, case: Option<&Case>) -> Option<u64> {
        let mut encoder =
            self.gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("feedback test") });
        let view = case.map(|c| View::Window(c.window));
        let bias = case.map_or(0.0, |c| c.bias);
        self.pass.encode(&self.gpu.device, &mut encoder, &self.target, &textures(), view.as_ref(), bias, [0.0; 2]);
        let frame = self.readback.encode_copy(&mut encoder, &self.target);
        self.gpu.queue.submit([encoder.finish()]);
        self.readback.submitted();
        frame
    }

    fn render(&mut self, view: Option<&Case>) -> Vec<u32> {
        let frame = self.submit(view).expect("a free buffer");
        let got = self.readback.read_now(&self.gpu.device).unwrap().expect("a frame in flight");
        assert_eq!((got.frame, got.width, got.height), (frame, 40, 30));
        got.words
    }
}

#[test]
fn words_match_the_cpu_mirror_and_analysis_finds_the_pages() {
    let Some(gpu) = gpu() else { return };
    let mut fx = Fixture::new(gpu, 2);
    let grid = TextureGrid::new(PAGES.into(), PAGES.into()).unwrap();
    // (view, the LOD it must ask for): non-dyadic windows; the footprint in texels per feedback
    // pixel, after the -3 bias, is max(extent.x * 6, extent.y * 8).
    let cases = [
        (view(0, [0.137, 0.291], [0.15, 0.2], 0.0), 0),
        (view(5, [0.213, 0.058], [0.31, 0.37], 0.0), 1),
        (view(5, [0.05, 0.11], [0.83, 0.71], 0.0), 2),
        // Beyond the texture on every side: pages clamp to the grid, derivatives do not.
        (view(9, [-0.3, -0.2], [1.9, 1.5], 0.0), 3),
        // The whole texture with the frame's own bias pushing past the root: clamped to it.
        (view(15, [0.0, 0.0], [1.0, 1.0], 1.5), 4),
    ];
    for (v, lod) in &cases {
        let want = expected(v, &fx.target);
        assert!(want.iter().all(|&w| w >> 24 & 0xF == *lod), "{v:?} asks for LOD {lod}");
        let got = fx.render(Some(v));
        let wrong: Vec<_> = (0..want.len()).filter(|&i| got[i] != want[i]).collect();
        assert!(
            wrong.is_empty(),
            "{v:?}: {} of {} words differ; first at ({}, {}): got {:#010x}, want {:#010x}",
            wrong.len(),
            want.len(),
            wrong[0] % 40,
            wrong[0] / 40,
            got[wrong[0]],
            want[wrong[0]]
        );

        // Analysis of the read-back words: every requested page with its pixel count, plus
        // its ancestors, nothing resident.
        let mut direct: BTreeMap<PageId, u32> = BTreeMap::new();
        for &w in &want {
            let p = vortex_vt::feedback::decode(w).and_then(|r| r.page(&[grid; 16])).unwrap();
            *direct.entry(p).or_default() += 1;
        }
        let all: BTreeSet<PageId> = direct.keys().flat_map(|p| p.ancestors_and_self(&grid)).collect();
        let a = analyze(&got, &[grid; 16], |_| None);
        assert_eq!((a.samples, a.no_request, a.invalid, a.requested), (1200, 0, 0, direct.len()));
        let pages: BTreeSet<PageId> = a.requests.iter().map(|r| r.page).collect();
        assert_eq!(pages, all, "{v:?}");
        for r in &a.requests {
            assert_eq!(r.direct, direct.get(&r.page).copied().unwrap_or(0), "{:?}", r.page);
            assert_eq!(r.distance, grid.lod_count() - r.page.lod, "{:?}", r.page);
        }
        let root = a.requests.iter().find(|r| r.page == grid.root(v.window.texture)).unwrap();
        assert_eq!(root.samples, 1200);
        eprintln!("{v:?}: LOD {lod}, {} pages requested, {} with ancestors", direct.len(), all.len());
    }
}

#[test]
fn nothing_drawn_reads_no_request() {
    let Some(gpu) = gpu() else { return };
    let mut fx = Fixture::new(gpu, 2);
    // A frame with feedback first, so that the clear has something to overwrite.
    fx.render(Some(&view(0, [0.0; 2], [1.0; 2], 0.0)));
    let words = fx.render(None);
    assert!(words.iter().all(|&w| w == NO_REQUEST));
    let a = analyze(&words, &[TextureGrid::new(PAGES.into(), PAGES.into()).unwrap()], |_| None);
    assert_eq!((a.samples, a.no_request, a.requests.len()), (0, 1200, 0));
}

#[test]
fn the_ring_reads_frames_in_order_without_blocking() {
    let Some(gpu) = gpu() else { return };
    let mut fx = Fixture::new(gpu, 2);
    let views = [view(1, [0.137, 0.291], [0.15, 0.2], 0.0), view(2, [0.213, 0.058], [0.31, 0.37], 0.0)];
    assert_eq!(fx.submit(Some(&views[0])), Some(0));
    assert_eq!(fx.submit(Some(&views[1])), Some(1));
    assert_eq!(fx.readback.in_flight(), 2);
    // Both buffers in flight: the third frame's feedback is skipped, not waited for.
    assert_eq!(fx.submit(Some(&views[0])), None);
    // try_read never blocks; poll it until the GPU is done with the oldest frame.
    let start = std::time::Instant::now();
    let first = loop {
        if let Some(f) = fx.readback.try_read(&fx.gpu.device).unwrap() {
            break f;
        }
        assert!(start.elapsed().as_secs() < 30, "frame 0 never completed");
        std::thread::yield_now();
    };
    assert_eq!(first.frame, 0, "the oldest frame first");
    assert_eq!(first.words, expected(&views[0], &fx.target));
    let second = fx.readback.read_now(&fx.gpu.device).unwrap().unwrap();
    assert_eq!(second.frame, 1);
    assert_eq!(second.words, expected(&views[1], &fx.target));
    assert_eq!(fx.readback.in_flight(), 0);
    assert_eq!(fx.readback.try_read(&fx.gpu.device).unwrap(), None);
    assert_eq!(fx.readback.read_now(&fx.gpu.device).unwrap(), None);
    // The freed buffers take new frames, numbered on.
    assert_eq!(fx.submit(Some(&views[1])), Some(2));
    assert_eq!(fx.readback.read_now(&fx.gpu.device).unwrap().map(|f| f.frame), Some(2));
}
