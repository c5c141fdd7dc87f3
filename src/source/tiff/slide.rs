//! Vendor formats built on TIFF, recognised as OpenSlide and Bio-Formats recognise them: by the
//! first directory's ImageDescription (Aperio SVS starts it with "Aperio", OME-TIFF holds
//! OME-XML, Philips TIFF a `DPUfsImport` XML), a vendor's private tag (Hamamatsu NDPI) or XMP
//! packet (Ventana BIF), or as a generic pyramid where later directories are reduced-resolution
//! copies. Also which directories are associated images (label, macro,
//! thumbnail): they are never the image cut, only listed.

use std::borrow::Cow;

use crate::source::xml::unescape;

/// One directory of the main chain.
#[derive(Clone, Debug)]
pub(super) struct Page {
    pub width: u32,
    pub height: u32,
    /// NewSubfileType bit 0: a reduced-resolution copy of another page.
    pub reduced: bool,
    pub tiled: bool,
    pub description: String,
    /// Entries of its SubIFDs tag (the reduced levels of an OME-TIFF or `vips --subifd` pyramid).
    pub sub_ifds: usize,
    /// A private tag or XMP packet only one vendor writes (Hamamatsu's 65420, Ventana's iScan).
    pub hint: Option<Vendor>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Vendor {
    /// One image, or several pages with nothing to say which is which.
    Plain,
    /// Reduced-resolution levels next to the full one (NewSubfileType or SubIFDs), no vendor.
    Pyramid,
    Aperio,
    Ome,
    Philips,
    Hamamatsu,
    Ventana,
}

impl Vendor {
    pub(super) fn name(self) -> &'static str {
        match self {
            Vendor::Plain => "TIFF",
            Vendor::Pyramid => "pyramidal TIFF",
            Vendor::Aperio => "Aperio SVS",
            Vendor::Ome => "OME-TIFF",
            Vendor::Philips => "Philips TIFF",
            Vendor::Hamamatsu => "Hamamatsu NDPI",
            Vendor::Ventana => "Ventana BIF",
        }
    }
}

pub(super) fn recognise(pages: &[Page]) -> Vendor {
    let first = &pages[0].description;
    if let Some(vendor) = pages[0].hint {
        vendor
    } else if first.starts_with("Aperio") {
        Vendor::Aperio
    } else if first.contains("<OME") || first.contains(":OME") {
        Vendor::Ome
    } else if first.contains("DPUfsImport") {
        Vendor::Philips
    } else if pages.iter().skip(1).any(|p| p.reduced) || pages.iter().any(|p| p.sub_ifds > 0) {
        Vendor::Pyramid
    } else {
        Vendor::Plain
    }
}

/// What page `i` is if it is an associated image rather than part of the picture.
pub(super) fn associated(vendor: Vendor, pages: &[Page], i: usize) -> Option<&'static str> {
    let page = &pages[i];
    // Aperio's second directory is the thumbnail, in strips where the levels are tiled.
    if vendor == Vendor::Aperio && i == 1 && !page.tiled {
        return Some("thumbnail");
    }
    // OME-XML (a whole document) may use any of these words; other vendors write a short
    // description naming the associated image ("Aperio ...\nlabel 387x463", Philips "Label").
    if i == 0 || vendor == Vendor::Ome || page.description.len() > 1024 {
        return None;
    }
    let description = page.description.to_ascii_lowercase();
    let words: Vec<&str> = description.split(|c: char| !c.is_ascii_alphanumeric()).collect();
    ["label", "macro", "thumbnail"].into_iter().find(|kind| words.contains(kind))
}

/// Whether page `i` is a smaller copy of an earlier one: flagged reduced (NewSubfileType bit
/// 0), or, in Aperio's files, which flag none, any tiled page after the first.
pub(super) fn is_level(vendor: Vendor, pages: &[Page], i: usize) -> bool {
    let page = &pages[i];
    associated(vendor, pages, i).is_none() && (page.reduced || (vendor == Vendor::Aperio && page.tiled && i > 0))
}

/// One OME-XML `TiffData` element: planes from (FirstC, FirstZ, FirstT) on, `PlaneCount` of
/// them, stored in directories from `IFD` on.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(in crate::source) struct TiffData {
    /// FirstC, FirstZ, FirstT (0 where absent).
    pub first: [u64; 3],
    pub ifd: Option<u64>,
    pub count: Option<u64>,
    /// The file its `UUID` child names when that is not this one (a multi-file OME-TIFF):
    /// neither this file's name nor the document's own UUID. `None`: this file.
    pub elsewhere: Option<String>,
}

/// The TiffData elements of `image` (one `Image` element of the document `xml`), in order;
/// `file` is this file's name. A number that is not one is an error naming the attribute.
pub(in crate::source) fn tiff_data(xml: &str, image: &str, file: &str) -> Result<Vec<TiffData>, String> {
    let own_uuid = find_element(xml, "OME").and_then(|at| attribute(start_tag(&xml[at..]), "UUID"));
    let mut all = Vec::new();
    let mut from = 0;
    while let Some(at) = find_element(&image[from..], "TiffData") {
        let element = &image[from + at..];
        let tag = start_tag(element);
        let number = |name: &str| -> Result<Option<u64>, String> {
            attribute(tag, name)
                .map(|v| v.trim().parse::<u64>().map_err(|_| format!("TiffData {name} \"{v}\" is not a number")))
                .transpose()
        };
        let first = [number("FirstC")?.unwrap_or(0), number("FirstZ")?.unwrap_or(0), number("FirstT")?.unwrap_or(0)];
        let (ifd, count) = (number("IFD")?, number("PlaneCount")?);
        // `<TiffData .../>` has no UUID child; `<TiffData ...><UUID FileName="f">urn:..</UUID></TiffData>`.
        let body = match tag.ends_with('/') {
            true => "",
            false => &element[..find_closing(element, "TiffData").unwrap_or(element.len())],
        };
        let elsewhere = find_element(body, "UUID").and_then(|u| {
            let uuid_tag = start_tag(&body[u..]);
            let text = body[u + uuid_tag.len()..].trim_start_matches('>');
            let text = unescape(text[..text.find('<').unwrap_or(text.len())].trim()).into_owned();
            let name = attribute(uuid_tag, "FileName");
            let this = name.as_deref() == Some(file) || own_uuid.as_deref() == Some(text.as_str());
            (!this).then(|| match name {
                Some(name) => format!("FileName \"{name}\""),
                None => format!("UUID {text}"),
            })
        });
        all.push(TiffData { first, ifd, count, elsewhere });
        from += at + 1;
    }
    Ok(all)
}

/// The start tag that `element` begins with, without its closing `>`.
pub(in crate::source) fn start_tag(element: &str) -> &str {
    &element[..element.find('>').unwrap_or(element.len())]
}

/// Each OME-XML `Image` element (series) of `xml`, in order.
pub(in crate::source) fn images(xml: &str) -> Vec<&str> {
    let mut images = Vec::new();
    let mut rest = xml;
    while let Some(at) = find_element(rest, "Image") {
        let body = &rest[at..];
        let end = find_closing(body, "Image").unwrap_or(body.len());
        images.push(&body[..end]);
        rest = &body[end.max(1)..];
    }
    images
}

/// The first TiffData of each OME-XML `Image` (series), in order (its IFD 0 where the
/// attribute is absent, as the OME schema says), `None` for an Image without TiffData.
pub(in crate::source) fn ome_series(xml: &str, file: &str) -> Result<Vec<Option<TiffData>>, String> {
    images(xml)
        .into_iter()
        .enumerate()
        .map(|(n, image)| {
            tiff_data(xml, image, file)
                .map(|all| all.into_iter().next())
                .map_err(|e| format!("Image {n} (series {n}): {e}"))
        })
        .collect()
}

/// Where the next `<name` or `<prefix:name` start tag begins (not `<ImageRef`, `</Image>`).
pub(in crate::source) fn find_element(xml: &str, name: &str) -> Option<usize> {
    let mut from = 0;
    while let Some(lt) = xml[from..].find('<') {
        let at = from + lt;
        let tag = &xml[at + 1..];
        let local = tag.split([' ', '>', '/', '\t', '\r', '\n']).next().unwrap_or("");
        let local = local.rsplit(':').next().unwrap_or(local);
        if local == name {
            return Some(at);
        }
        from = at + 1;
    }
    None
}

/// The end of the element starting `xml` (after its `</name>` or its self-closing tag).
pub(in crate::source) fn find_closing(xml: &str, name: &str) -> Option<usize> {
    let mut from = 1;
    while let Some(lt) = xml[from..].find("</") {
        let at = from + lt;
        let tag = &xml[at + 2..];
        let local = tag.split(['>', ' ']).next().unwrap_or("");
        if local.rsplit(':').next() == Some(name) {
            return Some(at + 2 + tag.find('>').map_or(tag.len(), |e| e + 1));
        }
        from = at + 2;
    }
    None
}

/// The one `Channel` of OME-XML series `series`, its `Name` and `Color` as given; `None` where
/// the series has none, several, or one that says neither.
pub(in crate::source) fn ome_channel_label(xml: &str, series: u32) -> Option<crate::source::ChannelLabel> {
    let image = *images(xml).get(series as usize)?;
    let first = find_element(image, "Channel")?;
    if find_element(&image[first + 1..], "Channel").is_some() {
        return None;
    }
    let tag = start_tag(&image[first..]);
    let name = attribute(tag, "Name").map(Cow::into_owned);
    let colour = attribute(tag, "Color").and_then(|v| colour(&v));
    (name.is_some() || colour.is_some()).then_some(crate::source::ChannelLabel { name, colour })
}

/// An OME `Color`: RGBA as a signed 32-bit integer (the schema's type), or as the unsigned
/// one some writers put; anything else is no colour (it is only a display hint).
pub(in crate::source) fn colour(value: &str) -> Option<u32> {
    let v: i64 = value.trim().parse().ok()?;
    match v {
        -0x8000_0000..0 => Some(v as i32 as u32),
        0..=0xFFFF_FFFF => Some(v as u32),
        _ => None,
    }
}

/// The value of attribute `name` in the start tag `tag`, its references replaced: the five
/// predefined entities (`&amp;` `&lt;` `&gt;` `&quot;` `&apos;`) and character references
/// (`&#65;`, `&#x41;`). A malformed reference (an unknown name, no `;`, a number that is no
/// character) is kept as written, so a value is never lost or shortened.
pub(in crate::source) fn attribute<'a>(tag: &'a str, name: &str) -> Option<Cow<'a, str>> {
    let mut rest = tag;
    while let Some(at) = rest.find(name) {
        let before = rest[..at].chars().last();
        let after = rest[at + name.len()..].trim_start();
        if before.is_some_and(char::is_whitespace)
            && let Some(value) = after.strip_prefix('=')
        {
            let value = value.trim_start();
            let quote = value.chars().next()?;
            let value = &value[quote.len_utf8()..];
            return value.find(quote).map(|end| unescape(&value[..end]));
        }
        rest = &rest[at + name.len()..];
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ome_series_are_found_by_their_first_tiff_data() {
        let xml = r#"<?xml version="1.0"?><OME xmlns="http://www.openmicroscopy.org/Schemas/OME/2016-06" UUID="urn:uuid:1">
            <Image ID="Image:0" Name="a"><Pixels><TiffData IFD="0" PlaneCount="1"/></Pixels></Image>
            <Image ID="Image:1"><Pixels><TiffData PlaneCount="1" IFD='3'/></Pixels></Image>
            <ome:Image ID="Image:2"><ome:Pixels><ome:TiffData/></ome:Pixels></ome:Image>
            <Image ID="Image:3"><Pixels/></Image>
            <Image ID="Image:4"><Pixels><TiffData IFD="1"><UUID FileName="b.ome.tif">urn:uuid:2</UUID></TiffData></Pixels></Image>
            <Image ID="Image:5"><Pixels><TiffData IFD="2"><UUID FileName="renamed.tif">urn:uuid:1</UUID></TiffData>
            <TiffData IFD="2"><UUID FileName="a.ome.tif">urn:uuid:3</UUID></TiffData><TiffData><UUID>urn:uuid:4</UUID></TiffData></Pixels></Image></OME>"#;
        let first = |n: usize| ome_series(xml, "a.ome.tif").unwrap()[n].clone().map(|t| (t.ifd, t.elsewhere));
        assert_eq!(first(0), Some((Some(0), None)));
        assert_eq!(first(1), Some((Some(3), None)));
        assert_eq!(first(2), Some((None, None)));
        assert_eq!(first(3), None);
        // Another file's planes, named by FileName; this file's, by its UUID or its name.
        assert_eq!(first(4), Some((Some(1), Some(r#"FileName "b.ome.tif""#.into()))));
        let image = images(xml)[5];
        let all: Vec<_> = tiff_data(xml, image, "a.ome.tif").unwrap().into_iter().map(|t| t.elsewhere).collect();
        assert_eq!(all, [None, None, Some("UUID urn:uuid:4".into())]);
        assert_eq!(ome_series("<OME></OME>", "a").unwrap(), Vec::<Option<TiffData>>::new());
        let bad = r#"<OME><Image><Pixels><TiffData IFD="x1"/></Pixels></Image></OME>"#;
        assert_eq!(ome_series(bad, "a").unwrap_err(), r#"Image 0 (series 0): TiffData IFD "x1" is not a number"#);
    }

    #[test]
    fn attribute_values_are_unescaped() {
        let tag = r#"<Channel Name="A&amp;B &lt;1&gt; &quot;x&quot; &apos;y&apos;" ID='&#65;&#x42;&#X43;' Bad="&nope; &amp &#0; &#xD800; & ;""#;
        assert_eq!(attribute(tag, "Name").as_deref(), Some(r#"A&B <1> "x" 'y'"#));
        // `&#X43;` is no reference (XML's hex prefix is a lower-case x): kept as written.
        assert_eq!(attribute(tag, "ID").as_deref(), Some("AB&#X43;"));
        assert_eq!(attribute(tag, "Bad").as_deref(), Some("&nope; &amp &#0; &#xD800; & ;"));
        assert!(matches!(attribute(r#"<P Name="plain">"#, "Name"), Some(Cow::Borrowed("plain"))));
        assert_eq!(attribute(r#"<P Name="é&#233;">"#, "Name").as_deref(), Some("éé"));
    }

    #[test]
    fn associated_images_are_named_by_their_description() {
        let page = |description: &str, tiled: bool| Page {
            width: 10,
            height: 10,
            reduced: false,
            tiled,
            description: description.into(),
            sub_ifds: 0,
            hint: None,
        };
        let pages = vec![
            page("Aperio Image Library v12\r\n46000x32914 (240x240) JPEG/RGB Q=70|AppMag = 20", true),
            page("Aperio Image Library v12\r\n46000x32914 -> 1024x732", false),
            page("Aperio Image Library v12\r\n46000x32914 -> 11500x8228", true),
            page("Aperio Image Library v12\nlabel 387x463", false),
            page("Aperio Image Library v12\nmacro 1280x431", false),
        ];
        assert_eq!(recognise(&pages), Vendor::Aperio);
        let kinds: Vec<_> = (0..5).map(|i| associated(Vendor::Aperio, &pages, i)).collect();
        assert_eq!(kinds, [None, Some("thumbnail"), None, Some("label"), Some("macro")]);
        assert_eq!(associated(Vendor::Plain, &[page("", true), page("Labelled", false)], 1), None);
    }
}
