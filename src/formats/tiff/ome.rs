//! The OME-XML an OME-TIFF carries in its first IFD's `ImageDescription` (OME schema
//! 2016-06): one image, its size, channels and pixel type, the physical pixel size where
//! known, and `TiffData` naming the main IFD of each plane (its reduced levels are that IFD's
//! SubIFDs, which the schema does not describe and readers find by the tag).

use std::fmt::Write;

use super::associated::Placed;
use super::{OmeChannel, Spec};
use crate::pixel::Depth;

const NAMESPACE: &str = "http://www.openmicroscopy.org/Schemas/OME/2016-06";

/// The OME `Pixels` `Type` of a stored depth.
fn pixel_type(depth: Depth) -> &'static str {
    match depth {
        Depth::U8 => "uint8",
        Depth::U16 => "uint16",
        Depth::U32 => "uint32",
        Depth::F32 | Depth::F16 => "float",
    }
}

/// `text` as XML attribute content.
fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            // XML 1.0 allows no other control characters; the name is only a label.
            c if c.is_control() && !matches!(c, '\t' | '\n' | '\r') => out.push(' '),
            c => out.push(c),
        }
    }
    out
}

/// The OME-XML of `spec`'s image. Samples interleaved in one IFD a plane: one channel of as
/// many samples as a pixel has (OME's RGB convention), `SizeC` counting the samples, named
/// where the source names it. Planes (`Spec::planar`): a channel each, of one sample, each
/// with its name and, where the source gives it, its colour, and a `TiffData` mapping main IFD
/// `c` (the `c`th of the chain; SubIFDs are not counted) to channel `c`.
///
/// Each of the source's associated images (`associated`, placed after the planes) is an
/// `Image` of its own, named as Aperio names it (`label`, `macro`, `thumbnail`): 8-bit grey
/// or RGB interleaved, its one IFD the main IFD after the planes' (QuPath and Bio-Formats
/// list them beside the pyramid).
pub(super) fn xml(spec: &Spec, associated: &[Placed]) -> String {
    let samples = spec.stored.channels.count();
    let bits = spec.stored.depth.bytes() * 8;
    let mut physical = String::new();
    if let Some(size) = spec.pixel_size {
        let _ = write!(
            physical,
            r#" PhysicalSizeX="{0}" PhysicalSizeXUnit="µm" PhysicalSizeY="{0}" PhysicalSizeYUnit="µm""#,
            size.0
        );
    }
    let (size_c, interleaved) = match spec.planar {
        true => (spec.channels.len(), "false"),
        false => (samples, "true"),
    };
    let mut out = String::new();
    let _ = write!(
        out,
        concat!(
            r#"<?xml version="1.0" encoding="UTF-8"?>"#,
            r#"<OME xmlns="{ns}" xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" "#,
            r#"xsi:schemaLocation="{ns} {ns}/ome.xsd" Creator="vortex-tiler {version}">"#,
            r#"<Image ID="Image:0" Name="{name}">"#,
            r#"<Pixels ID="Pixels:0" DimensionOrder="XYCZT" Type="{ty}" SignificantBits="{bits}" "#,
            r#"Interleaved="{interleaved}" BigEndian="false" SizeX="{w}" SizeY="{h}" SizeC="{c}" SizeZ="1" SizeT="1"{physical}>"#,
        ),
        ns = NAMESPACE,
        version = env!("CARGO_PKG_VERSION"),
        name = escape(&spec.name),
        ty = pixel_type(spec.stored.depth),
        bits = bits,
        interleaved = interleaved,
        w = spec.layout.width,
        h = spec.layout.height,
        c = size_c,
        physical = physical,
    );
    match spec.planar {
        false => {
            let channel = spec.channels.first().cloned().unwrap_or_default();
            let _ = write!(out, r#"<Channel ID="Channel:0:0"{}"#, attributes(&channel));
            let _ = write!(out, r#" SamplesPerPixel="{samples}"><LightPath/></Channel>"#);
            out.push_str(r#"<TiffData IFD="0" PlaneCount="1"/>"#);
        }
        true => {
            for (c, channel) in spec.channels.iter().enumerate() {
                let _ = write!(out, r#"<Channel ID="Channel:0:{c}"{}"#, attributes(channel));
                out.push_str(r#" SamplesPerPixel="1"><LightPath/></Channel>"#);
            }
            for c in 0..spec.channels.len() {
                let _ = write!(out, r#"<TiffData IFD="{c}" FirstC="{c}" FirstZ="0" FirstT="0" PlaneCount="1"/>"#);
            }
        }
    }
    out.push_str("</Pixels></Image>");
    let planes = spec.planes();
    for (j, image) in associated.iter().enumerate() {
        let (i, spp) = (j + 1, image.channels.count());
        let _ = write!(
            out,
            concat!(
                r#"<Image ID="Image:{i}" Name="{name}">"#,
                r#"<Pixels ID="Pixels:{i}" DimensionOrder="XYCZT" Type="uint8" SignificantBits="8" "#,
                r#"Interleaved="true" BigEndian="false" SizeX="{w}" SizeY="{h}" SizeC="{spp}" SizeZ="1" SizeT="1">"#,
                r#"<Channel ID="Channel:{i}:0" SamplesPerPixel="{spp}"><LightPath/></Channel>"#,
                r#"<TiffData IFD="{ifd}" PlaneCount="1"/></Pixels></Image>"#,
            ),
            i = i,
            name = super::associated::word(image.kind),
            w = image.width,
            h = image.height,
            spp = spp,
            ifd = planes as usize + j,
        );
    }
    out.push_str("</OME>");
    out
}

/// A channel's `Name` and `Color` attributes, each where known. `Color` is RGBA as the signed
/// 32-bit integer the schema types it.
fn attributes(channel: &OmeChannel) -> String {
    let mut out = String::new();
    if let Some(name) = &channel.name {
        let _ = write!(out, r#" Name="{}""#, escape(name));
    }
    if let Some(colour) = channel.colour {
        let _ = write!(out, r#" Color="{}""#, colour as i32);
    }
    out
}
