//! The OME-XML an OME-TIFF carries in its first IFD's `ImageDescription` (OME schema
//! 2016-06): one image, its size, channels and pixel type, the physical pixel size where
//! known, and one `TiffData` naming the first IFD (its reduced levels are that IFD's SubIFDs,
//! which the schema does not describe and readers find by the tag).

use std::fmt::Write;

use super::Spec;
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

/// The OME-XML of `spec`'s image: samples interleaved in one IFD a plane, so one channel of
/// as many samples as a pixel has (OME's RGB convention), `SizeC` counting the samples.
pub(super) fn xml(spec: &Spec) -> String {
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
    let mut out = String::new();
    let _ = write!(
        out,
        concat!(
            r#"<?xml version="1.0" encoding="UTF-8"?>"#,
            r#"<OME xmlns="{ns}" xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" "#,
            r#"xsi:schemaLocation="{ns} {ns}/ome.xsd" Creator="vortex-tiler {version}">"#,
            r#"<Image ID="Image:0" Name="{name}">"#,
            r#"<Pixels ID="Pixels:0" DimensionOrder="XYCZT" Type="{ty}" SignificantBits="{bits}" "#,
            r#"Interleaved="true" BigEndian="false" SizeX="{w}" SizeY="{h}" SizeC="{c}" SizeZ="1" SizeT="1"{physical}>"#,
            r#"<Channel ID="Channel:0:0" SamplesPerPixel="{c}"><LightPath/></Channel>"#,
            r#"<TiffData IFD="0" PlaneCount="1"/>"#,
            r#"</Pixels></Image></OME>"#
        ),
        ns = NAMESPACE,
        version = env!("CARGO_PKG_VERSION"),
        name = escape(&spec.name),
        ty = pixel_type(spec.stored.depth),
        bits = bits,
        w = spec.layout.width,
        h = spec.layout.height,
        c = samples,
        physical = physical,
    );
    out
}
