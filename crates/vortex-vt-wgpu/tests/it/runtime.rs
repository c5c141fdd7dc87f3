//! The whole frame loop on lavapipe, over packs written here (2048² texels: 16x16 pages of 128
//! texels with a 4-texel border, stored raw): camera paths converge to no fallback, the
//! page-table invariants hold after every frame, counters repeat exactly, the cache holds the
//! pack's bordered tiles byte for byte, renders match the CPU reference sampler, an
//! oversubscribed cache raises the LOD bias and lowers it again without ever showing a wrong
//! texel, uploads stay within the budget, coarse before fine, and a page seen by one pixel of
//! each feedback block is still asked for. Each renderer is paced offline (each frame's pages
//! land before the next frame is drawn), so that runs repeat exactly. Device conventions as in
//! `sample.rs` (see `common`).

use std::collections::HashSet;

use crate::common::pyramid::Synthetic;
use crate::common::{diff, gpu, untimed};
use vortex_vt::address::WindowOrigin;
use vortex_vt::sampler::{Rgba8Image, bilinear, trilinear};
use vortex_vt_wgpu::harness::camera::{Camera, Keyframe};
use vortex_vt_wgpu::harness::{Effects, FrameReport, Pose, Scene, SceneRenderer, SceneView, Shape, Window, WindowKey};
use vortex_vt_wgpu::{CacheFormat, Gpu, RuntimeError, SampleFilter};

const TILE: u32 = 136;
const BORDER: u32 = 4;
const PAGES: u16 = 16;
const SIZE: [u32; 2] = [128, 128];

fn key(frame: u32, center: [f64; 2], width: f64) -> Keyframe<WindowKey> {
    Keyframe { frame, at: WindowKey { center, width } }
}

/// A 2D viewer zooming from the whole texture into a corner where four pages meet, panning a
/// little, then holding still from frame 16.
fn zoom_scene(effects: Effects) -> Scene {
    Scene {
        textures: vec![],
        layers: vec![],
        size: SIZE,
        frames: 30,
        view: SceneView::Window {
            texture: 0,
            path: vec![key(0, [0.5, 0.5], 1.0), key(10, [0.49, 0.51], 0.07), key(16, [0.503, 0.497], 0.045)],
        },
        effects,
    }
}

fn effects(slots_per_side: u16, budget: usize) -> Effects {
    Effects {
        filter: Some(SampleFilter::Bilinear),
        cache_slots_per_side: slots_per_side,
        upload_budget: budget,
        ..Effects::exact()
    }
}

fn runtime(gpu: Gpu, textures: &[&Synthetic], scene: &Scene) -> SceneRenderer {
    let packs: Vec<_> = textures.iter().map(|t| &t.pack).collect();
    crate::common::renderer(gpu, &packs, scene)
}

/// Runs `scene`, returning every frame's counters and the last picture.
fn run(rt: &mut SceneRenderer, scene: &Scene) -> (Vec<FrameReport>, Rgba8Image) {
    let mut frames = Vec::new();
    let mut last = None;
    for f in 0..scene.frames {
        let (report, picture) = rt.frame(&scene.pose(f, rt.runtime().textures()), f + 1 == scene.frames).unwrap();
        frames.push(report);
        last = picture;
    }
    (frames, last.unwrap())
}

/// What a window render must be: at each pixel, the reference bilinear (or trilinear) sample
/// at the LOD the page table maps for the pixel's wanted page.
fn expected(rt: &SceneRenderer, tex: &Synthetic, window: &Window, filter: SampleFilter) -> Rgba8Image {
    let size = (SIZE[0], SIZE[1]);
    let origin: WindowOrigin = window.origin_texels(&tex.texture, size);
    let lods = tex.texture.grid.lod_count();
    let table = rt.runtime().page_table();
    Rgba8Image::from_fn(size.0, size.1, |x, y| {
        let [u, v] = window.uv(x, y, size).map(|t| t as f32);
        let lod = origin.lod(0.0, lods);
        let at = origin.at(x as f32 + 0.5, y as f32 + 0.5, lod, tex.texture.size(), tex.texture.payload());
        let entry = table.entry(0, lod, at.page[0] as u16, at.page[1] as u16);
        match filter {
            SampleFilter::Trilinear if entry.lod == lod => {
                let f = origin.step[0].max(origin.step[1]).log2().max(0.0);
                trilinear(&tex.chain, f, u, v)
            }
            _ => bilinear(&tex.chain, entry.lod, u, v),
        }
    })
}

#[test]
fn a_zoom_converges_matches_the_reference_and_repeats_exactly() {
    let Some(gpu) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let tex = Synthetic::new(dir.path(), "a.vtpk", PAGES, TILE, BORDER, 1);
    let scene = zoom_scene(effects(16, 16));
    let mut rt = runtime(gpu, &[&tex], &scene);
    let (frames, picture) = run(&mut rt, &scene);
    let report = rt.report(&scene, frames.clone());
    for f in &frames {
        eprintln!(
            "frame {:2}: requested {:3} loaded {:2} evicted {:2} fallback {:.3} bias {}",
            f.frame, f.requested, f.loaded, f.evicted, f.fallback_fraction, f.lod_bias
        );
    }
    let last = frames.last().unwrap();
    assert_eq!(last.fallback_fraction, 0.0, "the still view converges");
    assert!(report.frames_to_converge.is_some_and(|n| n <= 10), "{:?}", report.frames_to_converge);
    assert!(frames.iter().skip(1).all(|f| f.loaded <= 16), "the budget holds");
    assert!(
        report.pages_touched * 4 < report.pages_total as usize,
        "{} of {}",
        report.pages_touched,
        report.pages_total
    );
    assert_eq!(report.bytes_read, report.pages_touched as u64 * (TILE * TILE * 4) as u64, "raw tiles, each read once");

    // The converged picture is the reference, sampled at the LOD the view wants.
    let Pose::Window(window) = scene.pose(scene.frames - 1, rt.runtime().textures()) else { unreachable!() };
    let (max, psnr) = diff(&picture, &expected(&rt, &tex, &window, SampleFilter::Bilinear));
    eprintln!("converged zoom: max difference {max}/255, PSNR {psnr:.1} dB");
    assert!(max <= 2 && psnr >= 50.0, "max {max}, PSNR {psnr:.1} dB");

    // Every resident page's slot holds the pack's bordered tile, exactly (premultiplied, which
    // an opaque tile is already).
    let state = rt.runtime();
    for (page, slot) in state.residency().resident() {
        assert!(state.cache().read_slot(rt.gpu(), slot).unwrap() == tex.tile(page), "slot {slot} of {page:?}");
    }

    // The same run again gives the same counters, frame for frame, and on lavapipe the ones
    // recorded in the golden file, whatever the build profile (`cargo test --release` too).
    let adapter = rt.gpu().adapter_info().name;
    drop(rt);
    let mut again = runtime(crate::common::gpu().unwrap(), &[&tex], &scene);
    assert_eq!(untimed(&run(&mut again, &scene).0), untimed(&frames), "counters repeat on {adapter}");
    check_golden("zoom-counters.txt", &adapter, &frames);
}

/// The adapter family the golden counters are recorded on: lavapipe's, whose adapter names
/// itself `llvmpipe (LLVM x.y.z, N bits)`. Any llvmpipe must give these counters (they count
/// pages, not colours: a Mesa or LLVM update that changes them is a change to look at).
const GOLDEN_FAMILY: &str = "llvmpipe";

/// What [`check_golden`] does on an adapter: compare on any llvmpipe, whatever its version; on
/// another adapter (a real GPU may round texel footprints differently) there is nothing to
/// compare with, which a CI run, pinned to lavapipe, must not meet.
#[derive(Debug, PartialEq)]
enum Golden {
    Compare,
    OtherAdapter,
}

fn golden_applies(adapter: &str) -> Golden {
    let family = adapter.split(" (").next().unwrap_or(adapter);
    if family == GOLDEN_FAMILY { Golden::Compare } else { Golden::OtherAdapter }
}

/// Compares `frames` with `tests/golden/NAME` (its first line says which llvmpipe recorded it,
/// for the reader; any llvmpipe is compared). On another adapter it skips with a note, and
/// fails under `CI=true`, naming the adapter. `BLESS=1` rewrites the file.
fn check_golden(name: &str, adapter: &str, frames: &[FrameReport]) {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/golden").join(name);
    let mut counters =
        "frame requested hits loaded evicted deferred fallback_fraction lod_bias bytes_read\n".to_string();
    for f in frames {
        counters += &format!(
            "{} {} {} {} {} {} {:?} {:?} {}\n",
            f.frame,
            f.requested,
            f.hits,
            f.loaded,
            f.evicted,
            f.deferred,
            f.fallback_fraction,
            f.lod_bias,
            f.bytes_read
        );
    }
    if golden_applies(adapter) == Golden::OtherAdapter {
        crate::common::skip_unless_ci(
            &format!("the golden counters of {}", path.display()),
            &format!("the adapter is {adapter:?}, and the counters are recorded on {GOLDEN_FAMILY} (lavapipe)"),
        );
        return;
    }
    if std::env::var_os("BLESS").is_some() {
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(&path, format!("adapter: {adapter}\n{counters}")).unwrap();
        return;
    }
    let golden =
        std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e} (BLESS=1 records it)", path.display()));
    let (recorded, golden) = golden.split_once('\n').unwrap_or((golden.as_str(), ""));
    assert!(
        golden == counters,
        "counters on {adapter} differ from {} ({recorded}); BLESS=1 records them if the change is understood:\n{counters}",
        path.display()
    );
}

/// The golden counters are compared on every llvmpipe, not only the version that recorded
/// them (a Mesa update on CI would otherwise turn the comparison off without a word), and a
/// different adapter is named, not passed over.
#[test]
fn golden_counters_apply_to_any_llvmpipe() {
    for adapter in ["llvmpipe (LLVM 15.0.6, 256 bits)", "llvmpipe (LLVM 19.1.7, 256 bits)", "llvmpipe"] {
        assert_eq!(golden_applies(adapter), Golden::Compare, "{adapter}");
    }
    for adapter in ["NVIDIA GeForce RTX 4090", "AMD Radeon RX 7900 XTX (RADV NAVI31)", "llvmpipe2", "softpipe"] {
        assert_eq!(golden_applies(adapter), Golden::OtherAdapter, "{adapter}");
    }
}

#[test]
fn a_camera_over_a_plane_converges_with_every_filter() {
    let Some(gpu) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let tex = Synthetic::new(dir.path(), "a.vtpk", PAGES, TILE, BORDER, 2);
    let mut scene = Scene::default_plane();
    scene.size = [128, 96];
    scene.frames = 50;
    scene.effects = effects(16, 24);
    let mut rt = runtime(gpu, &[&tex], &scene);
    let (frames, picture) = run(&mut rt, &scene);
    let report = rt.report(&scene, frames.clone());
    eprintln!(
        "plane: {} of {} pages, converged after {:?}",
        report.pages_touched, report.pages_total, report.frames_to_converge
    );
    assert_eq!(frames.last().unwrap().fallback_fraction, 0.0);
    assert!(report.pages_touched * 2 < report.pages_total as usize);
    // Something was drawn: the plane covers most of the frame.
    let drawn = picture.texels.iter().filter(|t| t[3] == 255).count();
    assert!(drawn * 2 > picture.texels.len(), "{drawn} pixels drawn");

    // The other filters converge along the same path to the same pages.
    for filter in [SampleFilter::Nearest, SampleFilter::Trilinear] {
        scene.effects.filter = Some(filter);
        let mut rt = runtime(crate::common::gpu().unwrap(), &[&tex], &scene);
        let (f, p) = run(&mut rt, &scene);
        assert_eq!(f.last().unwrap().fallback_fraction, 0.0, "{filter:?}");
        assert_eq!(untimed(&f), untimed(&frames), "the feedback does not depend on the filter");
        let (max, _) = diff(&p, &picture);
        assert!(max > 0, "{filter:?} renders differently from bilinear");
    }
}

#[test]
fn trilinear_matches_the_reference_between_lods() {
    let Some(gpu) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let tex = Synthetic::new(dir.path(), "a.vtpk", PAGES, TILE, BORDER, 3);
    // Still at 2.7 texels per pixel: between LOD 1 and 2.
    let mut scene = zoom_scene(Effects { filter: Some(SampleFilter::Trilinear), ..effects(16, 64) });
    scene.view = SceneView::Window { texture: 0, path: vec![key(0, [0.41, 0.37], 2.7 * 128.0 / 2048.0)] };
    scene.frames = 8;
    let mut rt = runtime(gpu, &[&tex], &scene);
    let (frames, picture) = run(&mut rt, &scene);
    assert_eq!(frames.last().unwrap().fallback_fraction, 0.0);
    let Pose::Window(window) = scene.pose(0, rt.runtime().textures()) else { unreachable!() };
    let (max, psnr) = diff(&picture, &expected(&rt, &tex, &window, SampleFilter::Trilinear));
    eprintln!("trilinear: max difference {max}/255, PSNR {psnr:.1} dB");
    assert!(max <= 2 && psnr >= 50.0, "max {max}, PSNR {psnr:.1} dB");
}

#[test]
fn an_oversubscribed_cache_blurs_but_never_shows_a_wrong_texel() {
    let Some(gpu) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let tex = Synthetic::new(dir.path(), "a.vtpk", PAGES, TILE, BORDER, 4);
    // A view needing about 3x3 LOD-0 pages (plus ancestors) in a cache of 3x3 slots; then a
    // view of the whole texture, which needs only the root and its children.
    let mut scene = zoom_scene(effects(3, 4));
    scene.view = SceneView::Window {
        texture: 0,
        path: vec![key(0, [0.5, 0.5], 0.14), key(24, [0.5, 0.5], 0.14), key(26, [0.5, 0.5], 1.0)],
    };
    scene.frames = 44;
    let mut rt = runtime(gpu, &[&tex], &scene);
    let mut biases = Vec::new();
    let mut worst = (0, f64::INFINITY);
    for f in 0..scene.frames {
        let pose = scene.pose(f, rt.runtime().textures());
        let Pose::Window(window) = pose else { unreachable!() };
        // A frame draws with the table as the previous frame left it: the reference at the LOD
        // of each pixel's entry, however coarse.
        let want = expected(&rt, &tex, &window, SampleFilter::Bilinear);
        let (report, picture) = rt.frame(&pose, true).unwrap();
        biases.push(report.lod_bias);
        let (max, psnr) = diff(&picture.unwrap(), &want);
        assert!(max <= 2 && psnr >= 50.0, "frame {f}: max {max}, PSNR {psnr:.1} dB");
        worst = (worst.0.max(max), worst.1.min(psnr));
    }
    eprintln!("oversubscribed: worst max difference {}/255, worst PSNR {:.1} dB", worst.0, worst.1);
    let peak = biases.iter().cloned().fold(0.0f32, f32::max);
    eprintln!("LOD bias per frame: {biases:?}");
    assert!(peak >= 1.0, "the bias rose to {peak}");
    assert_eq!(*biases.last().unwrap(), 0.0, "and fell back once the view fits");
    assert!(biases.iter().all(|&b| b >= 0.0));
}

#[test]
fn uploads_stay_within_the_budget_coarse_before_fine() {
    let Some(gpu) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let tex = Synthetic::new(dir.path(), "a.vtpk", PAGES, TILE, BORDER, 5);
    let scene = zoom_scene(effects(16, 3));
    let mut rt = runtime(gpu, &[&tex], &scene);
    let grid = tex.texture.grid;
    // The roots, pinned before the first frame.
    assert_eq!(rt.runtime().residency().resident_count(), 1);
    let mut deferred = 0;
    for f in 0..scene.frames {
        let (report, _) = rt.frame(&scene.pose(f, rt.runtime().textures()), false).unwrap();
        assert!(report.loaded <= 3, "frame {f} loaded {}", report.loaded);
        deferred += report.deferred;
        // A page is mapped (its own entry names its LOD) only once its parent is.
        let state = rt.runtime();
        let table = state.page_table();
        for (page, _) in state.residency().resident() {
            if table.get(page).lod != page.lod {
                continue;
            }
            if let Some(parent) = page.parent(&grid) {
                assert_eq!(table.get(parent).lod, parent.lod, "frame {f}: {page:?} mapped before its parent");
            }
        }
    }
    assert!(deferred > 0, "the budget held pages back");
    assert_eq!(rt.runtime().in_flight(), 0);
}

#[test]
fn several_textures_stream_side_by_side() {
    let Some(gpu) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let a = Synthetic::new(dir.path(), "a.vtpk", PAGES, TILE, BORDER, 6);
    let b = Synthetic::new(dir.path(), "b.vtpk", 4, TILE, BORDER, 7);
    let key = |frame, eye, target| Keyframe { frame, at: Camera { eye, target } };
    let scene = Scene {
        textures: vec![],
        layers: vec![],
        size: [128, 96],
        frames: 40,
        view: SceneView::Camera {
            fov_y_deg: 60.0,
            path: vec![key(0, [0.0, 1.2, 1.4], [0.0, 0.0, 0.0]), key(20, [0.05, 0.25, 0.35], [0.0, 0.2, 0.0])],
            geometry: vec![
                Shape::Plane { texture: 0, size: 2.0 },
                Shape::Box { texture: 1, center: [0.0, 0.2, 0.0], size: [0.4, 0.4, 0.4] },
            ],
        },
        effects: effects(16, 32),
    };
    let mut rt = runtime(gpu, &[&a, &b], &scene);
    let (frames, picture) = run(&mut rt, &scene);
    assert_eq!(frames.last().unwrap().fallback_fraction, 0.0);
    let residency = rt.runtime().residency();
    let textures: HashSet<u8> = residency.resident().map(|(p, _)| p.texture).collect();
    assert_eq!(textures, HashSet::from([0, 1]));
    let fine_b = residency.resident().filter(|(p, _)| p.texture == 1 && p.lod < 2).count();
    assert!(fine_b > 0, "the box, close up, asks for its own fine pages");
    assert!(picture.texels.iter().all(|t| t[3] == 255), "the box covers the frame");
}

#[test]
fn bc7_blocks_stream_as_they_are_and_draw_what_rgba8_draws() {
    let Some(gpu) = gpu() else { return };
    if !gpu.device.features().contains(wgpu::Features::TEXTURE_COMPRESSION_BC) {
        crate::common::skip_unless_ci(
            "the BC7 cache test",
            "the adapter samples no BC formats (TEXTURE_COMPRESSION_BC)",
        );
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let tex = Synthetic::with_kind(dir.path(), "bc7.vtpk", PAGES, TILE, BORDER, 8, vortex_pack::TileKind::Bc7);
    let scene = zoom_scene(Effects { cache_format: None, ..effects(16, 16) });
    let mut bc7 = runtime(gpu, &[&tex], &scene);
    assert_eq!(bc7.runtime().cache().format(), CacheFormat::Bc7);
    let (frames, picture) = run(&mut bc7, &scene);
    // The cache holds the pack's blocks byte for byte.
    let state = bc7.runtime();
    for (page, slot) in state.residency().resident() {
        let vortex_pack::Tile::Data(_, blocks) =
            tex.pack.tile(vortex_pack::TileId::new(page.lod.into(), page.x.into(), page.y.into())).unwrap()
        else {
            panic!("{page:?} is stored as BC7")
        };
        assert!(state.cache().read_slot(bc7.gpu(), slot).unwrap() == blocks, "slot {slot} of {page:?}");
    }
    drop(bc7);
    // The same scene through an RGBA8 cache (the blocks decoded on the CPU) streams the same
    // pages and draws the same picture.
    let mut scene = scene;
    scene.effects.cache_format = Some(CacheFormat::Rgba8);
    let mut rgba = runtime(crate::common::gpu().unwrap(), &[&tex], &scene);
    assert_eq!(rgba.runtime().cache().format(), CacheFormat::Rgba8);
    let (frames_rgba, picture_rgba) = run(&mut rgba, &scene);
    assert_eq!(untimed(&frames), untimed(&frames_rgba));
    let (max, psnr) = diff(&picture, &picture_rgba);
    eprintln!("BC7 cache against RGBA8 cache: max difference {max}/255, PSNR {psnr:.1} dB");
    assert!(max <= 1, "max {max}");
}

#[test]
fn pages_seen_by_one_pixel_of_each_feedback_block_are_still_loaded() {
    let Some(gpu) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let tex = Synthetic::new(dir.path(), "a.vtpk", PAGES, TILE, BORDER, 9);
    // Frame column 511 shows LOD-0 texel 768.15 (page 6), but the rest of the last column of
    // 8x8 feedback blocks (columns 504 to 510) shows page 5: only the frames whose elected pixel
    // is the last of its block's row ask for page 6. The elected pixel visits every pixel of a
    // block in any 64 frames, so 64 frames load page 6, whichever frames elect column 511.
    let size = [512, 384];
    let mut scene = zoom_scene(effects(16, 32));
    scene.size = size;
    scene.frames = 64;
    scene.view = SceneView::Window { texture: 0, path: vec![key(0, [0.3127, 0.4419], 0.125)] };
    assert_eq!(scene.effects.feedback_divisor, 8);
    let mut rt = runtime(gpu, &[&tex], &scene);
    let Pose::Window(window) = scene.pose(0, rt.runtime().textures()) else { unreachable!() };
    let origin = window.origin_texels(&tex.texture, (size[0], size[1]));
    let lod = origin.lod(0.0, tex.texture.grid.lod_count());
    let page_x = |x: u32| origin.at(x as f32 + 0.5, 0.5, lod, tex.texture.size(), tex.texture.payload()).page[0];
    assert_eq!((lod, page_x(504), page_x(510), page_x(511)), (0, 5, 5, 6), "the view's last columns");
    let coarse = |rt: &SceneRenderer| -> Vec<(u32, u32)> {
        (0..size[1])
            .flat_map(|y| (0..size[0]).map(move |x| (x, y)))
            .filter(|&(x, y)| {
                let at = origin.at(x as f32 + 0.5, y as f32 + 0.5, lod, tex.texture.size(), tex.texture.payload());
                rt.runtime().page_table().entry(0, lod, at.page[0] as u16, at.page[1] as u16).lod != lod
            })
            .collect()
    };
    let mut column_511_from = None;
    for f in 0..scene.frames {
        rt.frame(&scene.pose(f, rt.runtime().textures()), false).unwrap();
        if column_511_from.is_none() && coarse(&rt).is_empty() {
            column_511_from = Some(f);
        }
    }
    let coarse = coarse(&rt);
    assert!(coarse.is_empty(), "{} pixels still drawn coarser than LOD {lod}, e.g. {:?}", coarse.len(), coarse.first());
    // Not at once: page 6 waited for a frame electing column 511 (a frame electing another
    // column of the block never asks for it).
    let from = column_511_from.unwrap();
    eprintln!("every pixel at LOD {lod} from frame {from}");
    assert!(from > 0, "page 6 was asked for by the first frame");
}

#[test]
fn a_lost_device_ends_the_frame_loop_with_an_error_not_a_panic() {
    let Some(gpu) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let tex = Synthetic::new(dir.path(), "a.vtpk", PAGES, TILE, BORDER, 1);
    let scene = zoom_scene(effects(16, 16));
    let mut rt = runtime(gpu, &[&tex], &scene);
    rt.frame(&scene.pose(0, rt.runtime().textures()), false).unwrap();
    // What is recorded on a destroyed device is invalid: wgpu reports it to this handler (the
    // default one panics); the frame itself fails where it reads back.
    let device = &rt.gpu().device;
    device.on_uncaptured_error(std::sync::Arc::new(|e| eprintln!("after the loss, as expected: {e}")));
    device.destroy();
    let err = rt.frame(&scene.pose(1, rt.runtime().textures()), true).unwrap_err();
    assert!(matches!(err, RuntimeError::Readback { frame: 1, .. }), "{err}");
    assert!(err.to_string().starts_with("frame 1: reading back the "), "{err}");
}
