//! The references of XML text (entities and character references) replaced: one rule for the
//! XML this crate reads, the OME-XML of an OME-TIFF (`tiff/slide.rs`, `channels.rs`) and a
//! Deep Zoom descriptor (`tiled/deepzoom.rs`).

use std::borrow::Cow;

/// `text` with its XML references replaced: the five predefined entities (`&amp;` `&lt;`
/// `&gt;` `&quot;` `&apos;`) and character references (`&#65;`, `&#x41;`). A malformed
/// reference (an unknown name, no `;`, a number that is no character) is kept as written, so
/// a value is never lost or shortened.
pub(crate) fn unescape(text: &str) -> Cow<'_, str> {
    if !text.contains('&') {
        return Cow::Borrowed(text);
    }
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(amp) = rest.find('&') {
        out.push_str(&rest[..amp]);
        rest = &rest[amp..];
        // The longest reference is `&#x10FFFF;` (10 bytes) or `&#1114111;`.
        let reference = rest[1..].find(';').filter(|&end| end <= 10).and_then(|end| {
            let name = &rest[1..1 + end];
            let c = match name {
                "amp" => Some('&'),
                "lt" => Some('<'),
                "gt" => Some('>'),
                "quot" => Some('"'),
                "apos" => Some('\''),
                _ => {
                    let code = match name.strip_prefix("#x") {
                        Some(hex) => u32::from_str_radix(hex, 16).ok(),
                        None => name.strip_prefix('#').and_then(|dec| dec.parse::<u32>().ok()),
                    };
                    // XML's Char production: no NUL, no C0 controls but tab and newlines.
                    code.filter(|&c| c >= 0x20 || matches!(c, 0x9 | 0xA | 0xD)).and_then(char::from_u32)
                }
            };
            c.map(|c| (c, end + 2))
        });
        match reference {
            Some((c, len)) => {
                out.push(c);
                rest = &rest[len..];
            }
            None => {
                out.push('&');
                rest = &rest[1..];
            }
        }
    }
    out.push_str(rest);
    Cow::Owned(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn references_are_replaced_and_malformed_ones_kept() {
        assert_eq!(unescape("A&amp;B &lt;1&gt; &quot;x&quot; &apos;y&apos;"), r#"A&B <1> "x" 'y'"#);
        assert_eq!(unescape("&#65;&#x42;&#X43;&amp;lt;"), "AB&#X43;&lt;");
        assert_eq!(unescape("&nope; &amp &#0; &#xD800; & ;"), "&nope; &amp &#0; &#xD800; & ;");
        assert!(matches!(unescape("plain"), Cow::Borrowed("plain")));
    }
}
