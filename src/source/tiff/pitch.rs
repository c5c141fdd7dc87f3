//! The physical size of a pixel, where a TIFF states it: an OME-TIFF's `PhysicalSizeX`/`Y`
//! (in the chosen series' `Pixels`), an Aperio slide's `MPP` (in its first description), or
//! the resolution tags when their unit is the centimetre (what NDPI, libvips and tifffile
//! write for microscopy). An inch resolution is a print size (72 dpi photographs), not a
//! measurement, and is not taken.
//!
//! A reduced level picked with `--page` is larger by the ratio of the full resolution to it.

use std::fs::File;
use std::io::BufReader;

use tiff::decoder::Decoder;
use tiff::decoder::ifd::Value;
use tiff::tags::Tag;

use super::slide::{self, Page, Vendor};
use crate::source::PixelPitch;

/// ResolutionUnit 3: XResolution and YResolution count pixels per centimetre.
const CENTIMETRE: u16 = 3;

/// The pitch of page `index`, the decoder positioned on it.
pub(super) fn of_page(
    vendor: Vendor,
    pages: &[Page],
    index: usize,
    decoder: &mut Decoder<BufReader<File>>,
) -> Option<PixelPitch> {
    match vendor {
        Vendor::Ome => ome(&pages[0].description, index),
        Vendor::Aperio => aperio(&pages[0].description).map(|mpp| {
            let (full, page) = (&pages[0], &pages[index]);
            PixelPitch {
                x_um: mpp * ratio(full.width, page.width),
                y_um: mpp * ratio(full.height, page.height),
                from: "the Aperio description's MPP",
            }
        }),
        _ => None,
    }
    .or_else(|| resolution(decoder))
}

fn ratio(full: u32, page: u32) -> f64 {
    if page == 0 { 1.0 } else { full as f64 / page as f64 }
}

/// `MPP = 0.2520` among an Aperio description's `|`-separated fields.
fn aperio(description: &str) -> Option<f64> {
    description
        .split('|')
        .find_map(|field| {
            let (key, value) = field.split_once('=')?;
            (key.trim() == "MPP").then(|| value.trim().parse::<f64>().ok()).flatten()
        })
        .filter(|mpp| mpp.is_finite() && *mpp > 0.0)
}

/// The `PhysicalSizeX`/`Y` of the OME-XML `Image` whose first plane is directory `index`
/// (series 0's for the first directory), in micrometres.
fn ome(xml: &str, index: usize) -> Option<PixelPitch> {
    let series = slide::ome_series(xml, "").ok()?;
    let n = series.iter().position(|t| t.as_ref().is_some_and(|t| t.ifd.unwrap_or(0) == index as u64))?;
    let image = slide::images(xml).into_iter().nth(n)?;
    let pixels = slide::start_tag(&image[slide::find_element(image, "Pixels")?..]);
    let side = |axis: &str| -> Option<f64> {
        let value: f64 = slide::attribute(pixels, &format!("PhysicalSize{axis}"))?.trim().parse().ok()?;
        // The schema's default unit is the micrometre.
        let unit = slide::attribute(pixels, &format!("PhysicalSize{axis}Unit"));
        let per = micrometres_per(unit.as_deref().unwrap_or("µm"))?;
        Some(value * per).filter(|v| v.is_finite() && *v > 0.0)
    };
    Some(PixelPitch { x_um: side("X")?, y_um: side("Y")?, from: "the OME-XML's PhysicalSizeX/Y" })
}

/// Micrometres in one of OME's length units (the ones a pixel is measured in).
fn micrometres_per(unit: &str) -> Option<f64> {
    Some(match unit {
        "pm" => 1e-6,
        "Å" => 1e-4,
        "nm" => 1e-3,
        "µm" | "μm" | "um" => 1.0,
        "mm" => 1e3,
        "cm" => 1e4,
        "m" => 1e6,
        _ => return None,
    })
}

/// XResolution/YResolution in pixels per centimetre.
fn resolution(decoder: &mut Decoder<BufReader<File>>) -> Option<PixelPitch> {
    let unit: u16 = decoder.find_tag_unsigned(Tag::ResolutionUnit).ok().flatten()?;
    if unit != CENTIMETRE {
        return None;
    }
    let mut per_cm = |tag| match decoder.find_tag(tag).ok().flatten()? {
        Value::Rational(n, d) if n > 0 && d > 0 => Some(n as f64 / d as f64),
        _ => None,
    };
    let (x, y) = (per_cm(Tag::XResolution)?, per_cm(Tag::YResolution)?);
    Some(PixelPitch { x_um: 1e4 / x, y_um: 1e4 / y, from: "the resolution tags (pixels per centimetre)" })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_aperio_description_gives_its_mpp() {
        let d = "Aperio Image Library v12.0.15\r\n46000x32914 [0,100 46000x32814] (240x240) JPEG/RGB Q=70|AppMag = 20|MPP = 0.4990|Filename = CMU-1";
        assert_eq!(aperio(d), Some(0.499));
        assert_eq!(aperio("Aperio Image Library|AppMag = 20"), None);
        assert_eq!(aperio("Aperio|MPP = -1"), None);
        assert_eq!(aperio("Aperio|MPP = x"), None);
    }

    #[test]
    fn ome_physical_sizes_are_read_in_their_units() {
        let xml = r#"<OME><Image ID="Image:0"><Pixels PhysicalSizeX="0.325" PhysicalSizeY="325" PhysicalSizeYUnit="nm"><TiffData IFD="0"/></Pixels></Image>
            <Image ID="Image:1"><Pixels PhysicalSizeX="2" PhysicalSizeXUnit="mm" PhysicalSizeY="2" PhysicalSizeYUnit="mm"><TiffData IFD="3"/></Pixels></Image>
            <Image ID="Image:2"><Pixels PhysicalSizeX="1" PhysicalSizeXUnit="furlong" PhysicalSizeY="1"><TiffData IFD="4"/></Pixels></Image></OME>"#;
        let pitch = |i| ome(xml, i).map(|p| (p.x_um, p.y_um));
        assert_eq!(pitch(0), Some((0.325, 0.325)));
        assert_eq!(pitch(3), Some((2000.0, 2000.0)));
        assert_eq!(pitch(4), None, "an unknown unit");
        assert_eq!(pitch(1), None, "no series starts there");
    }
}
