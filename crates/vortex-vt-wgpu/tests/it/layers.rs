//! Layer stacks: three packs on one page grid (albedo, normal, roughness, made from one picture
//! by `testing::material_stack`) streamed as one texture. Every layer matches the reference,
//! the page table is written once per page whatever the layers, a data layer is filtered as
//! stored (never sRGB-decoded), and a page is mapped only once every layer of it has landed.

use std::sync::Arc;

use vortex_pack::TileKind;
use vortex_vt::sampler::{self, LodChain, Rgba8Image};
use vortex_vt_wgpu::harness::{FrameReport, SceneRenderer};
use vortex_vt_wgpu::testing::{Gate, bordered_tile, box_chain, gated, material_stack, write_pack};
use vortex_vt_wgpu::{Layer, Pacing, PageSource, RuntimeError, VirtualTexture};

use crate::common::gpu;
use crate::defaults::window_scene;

const SIZE: [u32; 2] = [96, 64];

fn texture() -> VirtualTexture {
    VirtualTexture::new(SIZE[0], SIZE[1], 16, 1).unwrap()
}

/// The stack's LOD chains, albedo first.
fn chains(texture: &VirtualTexture) -> Vec<LodChain> {
    let picture = Rgba8Image::from_fn(SIZE[0], SIZE[1], |x, y| {
        let ring = (((x as f32 - 40.0).powi(2) + (y as f32 - 30.0).powi(2)).sqrt() * 0.6).sin();
        [(x * 2 + 30) as u8, (100.0 + 80.0 * ring) as u8, (y * 3) as u8, 255]
    });
    material_stack(&picture).into_iter().map(|image| box_chain(image, texture.grid.lod_count())).collect()
}

fn packs(dir: &std::path::Path, texture: &VirtualTexture, chains: &[LodChain]) -> Vec<Arc<dyn PageSource>> {
    chains
        .iter()
        .enumerate()
        .map(|(k, chain)| write_pack(&dir.join(format!("layer{k}.vtpk")), chain, texture, TileKind::Raw).unwrap() as _)
        .collect()
}

/// Albedo as colour, the others as data.
fn stack(packs: &[Arc<dyn PageSource>]) -> Vec<Layer> {
    packs
        .iter()
        .enumerate()
        .map(|(k, p)| if k == 0 { Layer::colour(vec![p.clone()]) } else { Layer::data(vec![p.clone()]) })
        .collect()
}

/// The whole image one texel per pixel, drawing `layer`, run offline for 8 frames: the reports
/// and the last picture.
fn run(layers: Vec<Layer>, layer: u32) -> (Vec<FrameReport>, Rgba8Image) {
    let mut scene = window_scene(&texture(), SIZE, [48.0, 32.0], 1.0);
    scene.effects.layer = layer;
    let mut renderer = SceneRenderer::with_layers(gpu().unwrap(), layers, &scene, Pacing::Offline).unwrap();
    let pose = scene.pose(0, renderer.runtime().textures());
    let reports = (0..8).map(|_| renderer.frame(&pose, false).unwrap().0).collect();
    assert!(renderer.runtime().errors().is_empty());
    (reports, renderer.still(&pose, None).unwrap())
}

fn total(reports: &[FrameReport], field: impl Fn(&FrameReport) -> usize) -> usize {
    reports.iter().map(field).sum()
}

#[test]
fn three_layers_match_the_reference_and_write_the_page_table_once_per_page() {
    let Some(_) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let texture = texture();
    let chains = chains(&texture);
    let packs = packs(dir.path(), &texture, &chains);

    let (alone, albedo_alone) = run(stack(&packs[..1]), 0);
    let (stacked, albedo) = run(stack(&packs), 0);
    assert!(total(&alone, |r| r.table_writes) > 0);
    assert_eq!(
        total(&stacked, |r| r.table_writes),
        total(&alone, |r| r.table_writes),
        "the writes of one layer, not three times as many"
    );
    assert_eq!(total(&stacked, |r| r.loaded), total(&alone, |r| r.loaded));
    assert_eq!(albedo, albedo_alone, "the albedo layer draws as the texture alone does");
    for (i, t) in albedo.texels.iter().enumerate() {
        let (x, y) = (i as u32 % SIZE[0], i as u32 / SIZE[0]);
        let want = chains[0].0[0].texels[i];
        assert!((0..3).all(|c| t[c].abs_diff(want[c]) <= 1), "albedo pixel ({x}, {y}): {t:?}, want {want:?}");
    }
    // Data is filtered as stored: the target (sRGB) encodes the stored value taken as linear,
    // where a layer sampled as colour would give the stored code back.
    for layer in [1, 2] {
        let (_, picture) = run(stack(&packs), layer);
        let stored = &chains[layer as usize].0[0];
        let mut differs = false;
        for (i, (t, s)) in picture.texels.iter().zip(&stored.texels).enumerate() {
            let want = s.map(|c| sampler::linear_to_srgb(f32::from(c) / 255.0));
            assert!((0..3).all(|c| t[c].abs_diff(want[c]) <= 1), "layer {layer} pixel {i}: {t:?}, want {want:?}");
            differs |= (0..3).any(|c| t[c].abs_diff(s[c]) > 8);
        }
        assert!(differs, "layer {layer} would pass as colour");
    }
}

#[test]
fn a_page_is_mapped_only_once_every_layer_of_it_has_landed() {
    let Some(gpu) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let texture = texture();
    let chains = chains(&texture);
    let mut packs = packs(dir.path(), &texture, &chains);
    // The normal map's reads wait at a gate: open while the roots are pinned, then closed, so
    // that the albedo lands and the normals cannot until the test says so.
    let gate = Gate::opened();
    packs[1] = Arc::new(gated(packs[1].clone(), Arc::clone(&gate)));
    let scene = window_scene(&texture, SIZE, [48.0, 32.0], 1.0);
    let mut renderer = SceneRenderer::with_layers(gpu, stack(&packs), &scene, Pacing::RealTime).unwrap();
    let pose = scene.pose(0, renderer.runtime().textures());
    gate.close();
    let frame = |renderer: &mut SceneRenderer| {
        let (report, _) = renderer.frame(&pose, false).unwrap();
        let rt = renderer.runtime();
        for (page, slot) in rt.residency().resident() {
            let entry = rt.page_table().get(page);
            if entry.lod != page.lod || entry.slot != slot {
                continue;
            }
            let held = rt.caches()[1].read_slot(renderer.gpu(), slot).unwrap();
            assert!(
                held == bordered_tile(&chains[1], &texture, page),
                "frame {}: {page:?} mapped before its normals landed",
                report.frame
            );
        }
        report
    };
    // A bound against a hang, in frames: a busy machine slows the frames as much as the
    // loads, so a working runtime lands its pages within a few of them, never near this.
    const MAX_FRAMES: usize = 100_000;
    let pages = |renderer: &SceneRenderer| {
        renderer.runtime().loaders().iter().map(|l| l.counters().pages).collect::<Vec<u64>>()
    };
    for n in 0.. {
        let report = frame(&mut renderer);
        assert_eq!(report.loaded, 0, "frame {}: a page was mapped with its normals held", report.frame);
        let [albedo, normal, _]: [u64; 3] = pages(&renderer).try_into().unwrap();
        if albedo > normal {
            break;
        }
        assert!(n < MAX_FRAMES, "the albedo never landed in {n} frames: nothing was tested");
        std::thread::yield_now(); // the loaders' turn
    }
    gate.open();
    for n in 0.. {
        let report = frame(&mut renderer);
        if report.fallback_fraction == 0.0 && report.in_flight == 0 {
            break;
        }
        assert!(n < MAX_FRAMES, "did not converge in {n} frames: {report:?}");
        std::thread::yield_now();
    }
}

#[test]
fn layers_on_different_grids_are_refused_with_both_named() {
    let Some(gpu) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let texture = texture();
    let chains = chains(&texture);
    let mut packs = packs(dir.path(), &texture, &chains[..2]);
    let wide = VirtualTexture::new(SIZE[0] + 1, SIZE[1], 16, 1).unwrap();
    let chain = box_chain(Rgba8Image::from_fn(SIZE[0] + 1, SIZE[1], |_, _| [1, 2, 3, 255]), wide.grid.lod_count());
    packs[1] = write_pack(&dir.path().join("wide.vtpk"), &chain, &wide, TileKind::Raw).unwrap();
    let scene = window_scene(&texture, SIZE, [48.0, 32.0], 1.0);
    match SceneRenderer::with_layers(gpu, stack(&packs), &scene, Pacing::Offline) {
        Err(RuntimeError::Config(m)) => {
            assert!(m.contains("wide.vtpk") && m.contains("layer0.vtpk") && m.contains("one page grid"), "{m}")
        }
        Err(e) => panic!("{e}"),
        Ok(_) => panic!("layers on different grids were accepted"),
    }
}
