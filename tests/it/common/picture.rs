//! What the browser tests share: the browser's parts, the synthetic photograph they show, and
//! the PSNR judgement of a screenshot against the source region it should show.

use std::path::{Path, PathBuf};

use image::{ImageBuffer, Rgb, RgbImage, imageops};

/// Below this the picture is wrong (a blank viewer is about 5 dB); a correct one measured 26.8
/// to 39.4 dB, OpenSeadragon's bilinear drawing against our Triangle resize (the tests print
/// each).
pub const MIN_PSNR_DB: f64 = 24.0;
/// The viewer's size in CSS pixels; the regions shown have its aspect ratio.
pub const VIEW: (u32, u32) = (640, 480);

/// A synthetic photograph: smooth rings, colour ramps and hard-edged discs, so that a shift or
/// a seam shows and resampling differences do not.
pub fn test_image() -> RgbImage {
    ImageBuffer::from_fn(2000, 1500, |x, y| {
        let (fx, fy) = (x as f64, y as f64);
        let r = ((fx - 900.0).powi(2) + (fy - 700.0).powi(2)).sqrt();
        let rings = 0.5 + 0.5 * (r / 9.0).sin();
        let disc =
            ((x / 150 + y / 150) % 2 == 0) && ((fx % 150.0 - 75.0).powi(2) + (fy % 150.0 - 75.0).powi(2)) < 40.0 * 40.0;
        let (mut red, mut green, mut blue) = (fx / 2000.0, fy / 1500.0, rings);
        if disc {
            (red, green, blue) = (1.0, 0.85, 0.2);
        }
        let g = |v: f64| (40.0 + 200.0 * v.clamp(0.0, 1.0)) as u8;
        Rgb([g(red * rings), g(green), g(blue)])
    })
}

/// The browser, its driver and OpenSeadragon, or why a browser test cannot run.
pub struct Parts {
    pub chromium: PathBuf,
    pub chromedriver: PathBuf,
    /// OpenSeadragon's build directory (holding `openseadragon.min.js`).
    pub openseadragon: PathBuf,
}

pub fn browser_parts() -> Result<Parts, String> {
    let found = |names: &[&str]| names.iter().map(|n| Path::new("/usr/bin").join(n)).find(|p| p.is_file());
    let chromium = found(&["chromium", "chromium-browser"]).ok_or("no chromium (apt-get install chromium)")?;
    let chromedriver = found(&["chromedriver"]).ok_or("no chromedriver (apt-get install chromium-driver)")?;
    let openseadragon =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/browser/node_modules/openseadragon/build/openseadragon");
    if !openseadragon.join("openseadragon.min.js").is_file() {
        return Err("no OpenSeadragon (npm ci --prefix tests/browser)".into());
    }
    Ok(Parts { chromium, chromedriver, openseadragon })
}

/// Peak signal-to-noise ratio of `shot` against `region` of `source` resized to the view.
pub fn psnr(source: &RgbImage, region: (u32, u32, u32, u32), shot: &RgbImage) -> f64 {
    let part = imageops::crop_imm(source, region.0, region.1, region.2, region.3).to_image();
    let expected = imageops::resize(&part, VIEW.0, VIEW.1, imageops::FilterType::Triangle);
    assert_eq!(shot.dimensions(), VIEW, "the screenshot is not the viewer's size");
    let sum: f64 =
        expected.as_raw().iter().zip(shot.as_raw().iter()).map(|(a, b)| (*a as f64 - *b as f64).powi(2)).sum();
    let mse = sum / expected.as_raw().len() as f64;
    10.0 * (255.0f64 * 255.0 / mse.max(1e-9)).log10()
}

/// Whether `shot` shows `region` of `source`: `Ok` with the numbers, or `Err` saying why not.
/// The picture must reach [`MIN_PSNR_DB`] and match this region better than the same region
/// two screen pixels off in any direction: a shifted picture matches a shifted region better.
pub fn judge(source: &RgbImage, region: (u32, u32, u32, u32), shot: &RgbImage) -> Result<String, String> {
    let db = psnr(source, region, shot);
    let step = (2 * region.2).div_ceil(VIEW.0).max(2);
    let off = [(step as i64, 0), (-(step as i64), 0), (0, step as i64), (0, -(step as i64))]
        .map(|(dx, dy)| {
            psnr(source, ((region.0 as i64 + dx) as u32, (region.1 as i64 + dy) as u32, region.2, region.3), shot)
        })
        .into_iter()
        .fold(f64::MIN, f64::max);
    let numbers = format!("{db:.1} dB ({step} texels off: at best {off:.1} dB)");
    if db < MIN_PSNR_DB || db <= off {
        Err(format!("{numbers}: needs at least {MIN_PSNR_DB} dB and more than a shifted region"))
    } else {
        Ok(numbers)
    }
}
