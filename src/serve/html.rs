//! The two HTML pages: `/` lists the inputs with their URLs, `/view/NAME` opens one in
//! OpenSeadragon (from `--openseadragon DIR` at `/openseadragon/`, else jsDelivr's CDN).

use super::catalog::{Catalog, Input, Source, StaticLayout, describe};

/// OpenSeadragon from jsDelivr when no local copy is given.
pub const CDN_SCRIPT: &str = "https://cdn.jsdelivr.net/npm/openseadragon@6.1/build/openseadragon/openseadragon.min.js";
pub const CDN_IMAGES: &str = "https://cdn.jsdelivr.net/npm/openseadragon@6.1/build/openseadragon/images/";

/// Text for HTML element content and attribute values.
pub fn escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

/// A name as one URL path segment.
pub fn url_segment(s: &str) -> String {
    let mut out = String::new();
    for b in s.bytes() {
        if b.is_ascii_alphanumeric() || b"-._~".contains(&b) {
            out.push(b as char);
        } else {
            out.push_str(&format!("%{b:02X}"));
        }
    }
    out
}

/// The tile source OpenSeadragon opens for an input, if it has one it can open.
pub fn tile_source(input: &Input) -> Option<String> {
    let n = url_segment(&input.name);
    match &input.source {
        Source::Tiled(_) => Some(format!("/{n}.dzi")),
        Source::Static(s) => match s.layout {
            StaticLayout::Dzi { .. } => Some(format!("/{n}.dzi")),
            StaticLayout::Iiif { .. } => Some(format!("/{n}/iiif/info.json")),
            StaticLayout::Xyz => None,
        },
    }
}

pub fn index(catalog: &Catalog) -> String {
    let mut rows = String::new();
    for input in &catalog.inputs {
        let n = url_segment(&input.name);
        let (size, levels, links) = match &input.source {
            Source::Tiled(t) => {
                let l = &t.layout;
                let mut links = format!(
                    "<a href=\"/{n}.dzi\">DZI</a> <a href=\"/{n}/iiif/info.json\">IIIF</a> <a href=\"/{n}/xyz/0/0/0.{}\">XYZ</a>",
                    t.format.extension(crate::formats::viewer::Viewer::Xyz)
                );
                if t.pack().is_some() {
                    links.push_str(&format!(" <a href=\"/{n}.vtpk\">pack</a>"));
                }
                (
                    format!("{} x {}", l.width, l.height),
                    format!("{} (tile {}, border {})", l.lod_count, l.tile_size, l.border),
                    links,
                )
            }
            Source::Static(s) => {
                let size = s.size.map_or("?".into(), |(w, h)| format!("{w} x {h}"));
                let links = match s.layout {
                    StaticLayout::Dzi { .. } => format!("<a href=\"/{n}.dzi\">DZI</a>"),
                    StaticLayout::Iiif { .. } => format!("<a href=\"/{n}/iiif/info.json\">IIIF</a>"),
                    StaticLayout::Xyz => format!("<a href=\"/{n}/xyz/tilejson.json\">TileJSON</a>"),
                };
                (size, "-".into(), links)
            }
        };
        let name = match tile_source(input) {
            Some(_) => format!("<a href=\"/view/{n}\">{}</a>", escape(&input.name)),
            None => escape(&input.name),
        };
        rows.push_str(&format!(
            "<tr><td>{name}</td><td>{}</td><td>{size}</td><td>{levels}</td><td>{links}</td></tr>\n",
            escape(&describe(&input.source))
        ));
    }
    format!(
        concat!(
            "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>vortex-tiler serve</title>\n",
            "<style>body{{font-family:sans-serif;margin:2em}}td,th{{padding:.3em .8em;text-align:left}}</style>\n",
            "</head><body>\n<h1>{} inputs</h1>\n<table>\n",
            "<tr><th>name</th><th>what</th><th>size</th><th>levels</th><th>URLs</th></tr>\n{}</table>\n</body></html>\n"
        ),
        catalog.inputs.len(),
        rows
    )
}

/// The OpenSeadragon page of one input, its viewer as `window.viewer`.
pub fn view(input: &Input, tile_source: &str, local_openseadragon: bool) -> String {
    let (script, images) = if local_openseadragon {
        ("/openseadragon/openseadragon.min.js", "/openseadragon/images/")
    } else {
        (CDN_SCRIPT, CDN_IMAGES)
    };
    let source = serde_json::to_string(tile_source).unwrap_or_default();
    format!(
        concat!(
            "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>{name}</title>\n",
            "<style>html,body{{margin:0;height:100%;background:#222}}#viewer{{width:100%;height:100%}}</style>\n",
            "<script src=\"{script}\"></script>\n</head><body>\n<div id=\"viewer\"></div>\n<script>\n",
            // OpenSeadragon 6 opens the image formats it lists, JPEG XL not among them; the
            // browser decodes it where it can.
            "OpenSeadragon.setImageFormatsSupported({{ jxl: true }});\n",
            "window.viewer = OpenSeadragon({{\n  id: \"viewer\",\n  prefixUrl: \"{images}\",\n",
            "  tileSources: {source},\n  crossOriginPolicy: \"Anonymous\",\n  showNavigator: true\n}});\n",
            "</script>\n</body></html>\n"
        ),
        name = escape(&input.name),
        script = script,
        images = images,
        source = source.replace('<', "\\u003c"),
    )
}
