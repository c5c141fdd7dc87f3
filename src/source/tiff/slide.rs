//! Vendor formats built on TIFF, recognised as OpenSlide and Bio-Formats recognise them: by the
//! first directory's ImageDescription (Aperio SVS starts it with "Aperio", OME-TIFF holds
//! OME-XML, Philips TIFF a `DPUfsImport` XML), a vendor's private tag (Hamamatsu NDPI) or XMP
//! packet (Ventana BIF), or as a generic pyramid where later directories are reduced-resolution
//! copies. Also which directories are associated images (label, macro,
//! thumbnail): they are never the image cut, only listed.

use super::pyramid::Page;

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

/// The first directory of each OME-XML `Image` (series), in order: its first TiffData's IFD
/// attribute (0 where the attribute is absent, as the OME schema says), `None` without TiffData.
pub(super) fn ome_series(xml: &str) -> Vec<Option<usize>> {
    let mut series = Vec::new();
    let mut rest = xml;
    while let Some(at) = find_element(rest, "Image") {
        let body = &rest[at..];
        let end = find_closing(body, "Image").unwrap_or(body.len());
        let image = &body[..end];
        let ifd = find_element(image, "TiffData").map(|t| {
            let tag = &image[t..];
            let tag = &tag[..tag.find('>').unwrap_or(tag.len())];
            attribute(tag, "IFD").and_then(|v| v.parse().ok()).unwrap_or(0)
        });
        series.push(ifd);
        rest = &body[end.max(1)..];
    }
    series
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

pub(in crate::source) fn attribute<'a>(tag: &'a str, name: &str) -> Option<&'a str> {
    let mut rest = tag;
    while let Some(at) = rest.find(name) {
        let before = rest[..at].chars().last();
        let after = rest[at + name.len()..].trim_start();
        if before.is_some_and(char::is_whitespace)
            && let Some(value) = after.strip_prefix('=')
        {
            let value = value.trim_start();
            let quote = value.chars().next()?;
            let value = &value[1..];
            return value.find(quote).map(|end| &value[..end]);
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
        let xml = r#"<?xml version="1.0"?><OME xmlns="http://www.openmicroscopy.org/Schemas/OME/2016-06">
            <Image ID="Image:0" Name="a"><Pixels><TiffData IFD="0" PlaneCount="1"/></Pixels></Image>
            <Image ID="Image:1"><Pixels><TiffData PlaneCount="1" IFD='3'/></Pixels></Image>
            <ome:Image ID="Image:2"><ome:Pixels><ome:TiffData/></ome:Pixels></ome:Image>
            <Image ID="Image:3"><Pixels/></Image></OME>"#;
        assert_eq!(ome_series(xml), vec![Some(0), Some(3), Some(0), None]);
        assert_eq!(ome_series("<OME></OME>"), Vec::<Option<usize>>::new());
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
