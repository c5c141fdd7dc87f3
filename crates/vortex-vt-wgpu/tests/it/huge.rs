//! A texture far wider than any GPU texture: 2^20 x 2^10 texels in 120-texel pages (8739 x 9
//! pages at LOD 0, 15 LODs, ~110 000 tiles), through the whole frame loop on lavapipe. Its
//! feedback words name pages past x = 4096, its page table is wider than the largest 2D texture
//! would allow at smaller payloads, and windows ~95% of the way to its right edge (one hanging
//! over it) converge and match the CPU reference sampler.
//!
//! Kept cheap: the texture is one colour but for two small rectangles of detail (one at the
//! image's right edge), so the pack stores one-colour tiles everywhere else (a few hundred bytes
//! of index each) and about a hundred raw tiles; the content is procedural (a [`LodImages`], no
//! 4-GiB chain), each LOD drawn directly (the sampler compares one LOD at a time, so the levels
//! need not be each other's means). The detail fades into the base colour at its rectangle's
//! edges, so no sharp step magnifies the window path's 1/64-texel error into a code value.

use crate::common::gpu;
use vortex_pack::TileKind;
use vortex_vt::page::PageId;
use vortex_vt::sampler::{LodImages, Rgba8Image, bilinear};
use vortex_vt_wgpu::harness::camera::Keyframe;
use vortex_vt_wgpu::harness::{Effects, Pose, Scene, SceneRenderer, SceneView, Window, WindowKey};
use vortex_vt_wgpu::testing::{TestTile, bordered_tile, write_pack_with};
use vortex_vt_wgpu::{SampleFilter, VirtualTexture};

const W: u32 = 1 << 20;
const H: u32 = 1 << 10;
const TILE: u32 = 128;
const BORDER: u32 = 4;
const SIZE: (u32, u32) = (128, 96);
const BASE: [u8; 4] = [40, 90, 160, 255];
/// Rectangles of detail in LOD-0 texels, `[x0, x1, y0, y1)`: one inside, one at the right edge.
const DETAIL: [[u32; 4]; 2] = [[1_000_000, 1_000_600, 300, 700], [W - 500, W, 0, 400]];
/// Where the reference sampler's crop starts (a multiple of 2^16, so aligned at every LOD): the
/// crop is 2^16 texels wide, where an f32 UV resolves 1/256 texel instead of 1/16.
const CROP: u32 = W - (1 << 16);

/// The procedural texture.
struct Huge;

fn rects(lod: u8) -> impl Iterator<Item = [u32; 4]> {
    let s = 1u32 << lod;
    DETAIL.into_iter().map(move |r| [r[0] / s, r[1].div_ceil(s), r[2] / s, r[3].div_ceil(s)])
}

impl LodImages for Huge {
    fn lod_count(&self) -> u8 {
        15
    }
    fn size(&self, lod: u8) -> (u32, u32) {
        (W.div_ceil(1 << lod), H.div_ceil(1 << lod))
    }
    fn texel(&self, lod: u8, x: u32, y: u32) -> [u8; 4] {
        let Some(r) = rects(lod).find(|r| (r[0]..r[1]).contains(&x) && (r[2]..r[3]).contains(&y)) else {
            return BASE;
        };
        // Smooth detail under an envelope that is 0 at the rectangle's edges.
        let fade = |t: u32, a: u32, b: u32| (std::f64::consts::PI * (t - a) as f64 / (b - a) as f64).sin();
        let e = fade(x, r[0], r[1]) * fade(y, r[2], r[3]);
        let (fx, fy, s) = (x as f64, y as f64, lod as f64);
        let detail = [
            100.0 * (fx * 0.021 + fy * 0.013 + s).sin() + 20.0 * (fx * 0.11).sin(),
            100.0 * (fy * 0.017 - fx * 0.009 + 2.0 * s).cos(),
            -80.0 * (fx * 0.005 + fy * 0.007).sin(),
        ];
        let code = |v: f64| v.round().clamp(0.0, 255.0) as u8;
        [
            code(BASE[0] as f64 + e * detail[0]),
            code(BASE[1] as f64 + e * detail[1]),
            code(BASE[2] as f64 + e * detail[2]),
            255,
        ]
    }
}

/// [`Huge`] from LOD-0 texel [`CROP`] on, so that the reference sampler's f32 UVs are fine enough.
struct Cropped;

impl LodImages for Cropped {
    fn lod_count(&self) -> u8 {
        15
    }
    fn size(&self, lod: u8) -> (u32, u32) {
        ((W - CROP).div_ceil(1 << lod), H.div_ceil(1 << lod))
    }
    fn texel(&self, lod: u8, x: u32, y: u32) -> [u8; 4] {
        Huge.texel(lod, x + (CROP >> lod), y)
    }
}

/// A tile is one colour unless its stored area (payload and border, clamped to the level)
/// reaches a rectangle of detail.
fn tile(texture: &VirtualTexture, page: PageId) -> TestTile {
    let (w, h) = Huge.size(page.lod);
    let (p, b) = (texture.payload() as i64, texture.border as i64);
    let span = |i: u16, n: u32| ((i as i64 * p - b).max(0) as u32, ((i as i64 + 1) * p + b).min(n as i64) as u32);
    let ((x0, x1), (y0, y1)) = (span(page.x, w), span(page.y, h));
    if rects(page.lod).any(|r| x0 < r[1] && r[0] < x1 && y0 < r[3] && r[2] < y1) {
        TestTile::Texels(bordered_tile(&Huge, texture, page))
    } else {
        TestTile::Constant(BASE)
    }
}

/// What the frame must be: per pixel, the reference bilinear sample at the LOD the page table
/// maps for the pixel's wanted page, from the crop; off the image, the background (transparent).
fn expected(rt: &SceneRenderer, texture: &VirtualTexture, window: &Window) -> Rgba8Image {
    let origin = window.origin_texels(texture, SIZE);
    let lod = origin.lod(0.0, texture.grid.lod_count());
    Rgba8Image::from_fn(SIZE.0, SIZE.1, |x, y| {
        if !origin.on_image(x as f32 + 0.5, y as f32 + 0.5, texture.size()) {
            return [0; 4];
        }
        let [u, v] = window.uv(x, y, SIZE);
        let at = origin.at(x as f32 + 0.5, y as f32 + 0.5, lod, texture.size(), texture.payload());
        let entry = rt.runtime().page_table().entry(0, lod, at.page[0] as u16, at.page[1] as u16);
        let u_crop = ((u * W as f64 - CROP as f64) / (W - CROP) as f64) as f32;
        bilinear(&Cropped, entry.lod, u_crop, v as f32)
    })
}

#[test]
fn windows_far_to_the_right_of_a_2_20_texel_texture_match_the_reference() {
    let Some(gpu) = gpu() else { return };
    let texture = VirtualTexture::new(W, H, TILE, BORDER).unwrap();
    assert_eq!((texture.grid.pages(), texture.grid.lod_count()), ([8739, 9], 15));
    let dir = tempfile::tempdir().unwrap();
    let started = std::time::Instant::now();
    let pack = write_pack_with(&dir.path().join("huge.vtpk"), &texture, TileKind::Raw, |p| tile(&texture, p)).unwrap();
    eprintln!("{} tiles written in {:.2} s", pack.header().index_count, started.elapsed().as_secs_f64());

    let key = |center, width| Keyframe { frame: 0, at: WindowKey { center, width } };
    let scene = |center, width| Scene {
        textures: vec![],
        layers: vec![],
        size: [SIZE.0, SIZE.1],
        frames: 1,
        view: SceneView::Window { texture: 0, path: vec![key(center, width)] },
        effects: Effects {
            filter: Some(SampleFilter::Bilinear),
            cache_slots_per_side: 16,
            upload_budget: 64,
            ..Effects::default()
        },
    };
    // Image UV centres and texels per pixel: inside the first rectangle magnified (LOD 0),
    // over the image's right edge (LOD 0, the window hangs past it: the background there), and
    // minified (LOD 2).
    let views = [
        ([1_000_300.4 / W as f64, 500.3 / H as f64], 0.71),
        ([(W as f64 - 40.7) / W as f64, 200.2 / H as f64], 1.37),
        ([1_000_290.0 / W as f64, 480.0 / H as f64], 5.3),
    ];
    let first = scene(views[0].0, views[0].1 * SIZE.0 as f64 / W as f64);
    let mut rt = crate::common::renderer(gpu, &[&pack], &first);
    for (center, texels_per_pixel) in views {
        let s = scene(center, texels_per_pixel * SIZE.0 as f64 / W as f64);
        let pose = s.pose(0, rt.runtime().textures());
        let Pose::Window(window) = pose else { unreachable!() };
        let origin = window.origin_texels(&texture, SIZE);
        assert!((origin.step[0] - origin.step[1]).abs() < 1e-6, "square pixels on a 1024:1 image");
        let mut frames = 0;
        let mut max_x = 0;
        loop {
            let (report, _) = rt.frame(&pose, false).unwrap();
            assert_eq!(report.load_errors, 0);
            max_x = max_x.max(rt.runtime().residency().resident().map(|(p, _)| p.x).max().unwrap_or(0));
            frames += 1;
            if report.fallback_fraction == 0.0 && report.loaded == 0 {
                break;
            }
            assert!(frames < 30, "{center:?}: no convergence in 30 frames ({report:?})");
        }
        let (_, picture) = rt.frame(&pose, true).unwrap();
        let (got, want) = (picture.unwrap(), expected(&rt, &texture, &window));
        let mut max = 0;
        for (g, w) in got.texels.iter().zip(&want.texels) {
            max = max.max((0..4).map(|c| g[c].abs_diff(w[c])).max().unwrap());
        }
        let lod = origin.lod(0.0, texture.grid.lod_count());
        let detailed = want.texels.iter().filter(|t| **t != BASE).count();
        eprintln!(
            "{center:?} at LOD {lod}: converged in {frames} frames, max page x {max_x}, max difference {max}/255, {detailed} texels of detail"
        );
        assert!(detailed > 1000, "the view shows the detail");
        assert!(max <= 2, "{center:?}: max difference {max}");
        assert!(lod > 0 || max_x > 8300, "pages far past 4096 were loaded");
    }
}
