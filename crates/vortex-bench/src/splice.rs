//! Generated blocks in hand-written documents. A block named `NAME` lives between the lines
//! `<!-- NAME:begin -->` and `<!-- NAME:end -->`, with one empty line after the first and before
//! the second: the convention of `bench/lib.sh`, so that every generated part of `docs/` looks
//! the same. Everything outside the markers is left byte for byte as it was.

use std::path::Path;

use anyhow::{Context, Result, bail};

/// One generated block: its marker name and its Markdown (without the surrounding empty lines).
pub struct Block {
    pub name: String,
    pub body: String,
}

impl Block {
    pub fn new(name: impl Into<String>, body: impl Into<String>) -> Block {
        Block { name: name.into(), body: body.into() }
    }
}

fn begin(name: &str) -> String {
    format!("<!-- {name}:begin -->")
}

fn end(name: &str) -> String {
    format!("<!-- {name}:end -->")
}

/// `doc` as it is if it has block `name`'s opening marker, else with a new section `intro` and
/// the block's (empty) markers appended: how a benchmark adds its table the first time.
pub fn with_block(doc: &str, name: &str, intro: &str) -> String {
    if doc.lines().any(|line| line.trim_end() == begin(name)) {
        return doc.to_string();
    }
    let mut out = doc.to_string();
    if !out.ends_with('\n') {
        out.push('\n');
    }
    out.push_str(&format!("\n{intro}\n\n{}\n{}\n", begin(name), end(name)));
    out
}

/// `doc` with the block between `name`'s markers replaced by `body`. Fails when the markers are
/// missing, repeated or out of order: a document whose prose lost its place for a table.
pub fn splice(doc: &str, name: &str, body: &str) -> Result<String> {
    let (b, e) = (begin(name), end(name));
    let lines: Vec<&str> = doc.split_inclusive('\n').collect();
    let find = |marker: &str| -> Result<usize> {
        let at: Vec<usize> = (0..lines.len()).filter(|&i| lines[i].trim_end_matches(['\n', '\r']) == marker).collect();
        match at[..] {
            [i] => Ok(i),
            [] => bail!("no line `{marker}`: the document needs a place for block `{name}`"),
            _ => bail!("`{marker}` appears {} times", at.len()),
        }
    };
    let (i, j) = (find(&b)?, find(&e)?);
    if j < i {
        bail!("`{e}` comes before `{b}`");
    }
    let mut out: String = lines[..=i].concat();
    out.push('\n');
    let body = body.trim_matches('\n');
    if !body.is_empty() {
        out.push_str(body);
        out.push_str("\n\n");
    }
    out.push_str(&lines[j..].concat());
    Ok(out)
}

/// Splices every block of `blocks` into `doc`, and fails if `doc` has a block named with
/// `prefix` that no block fills (a stale table nobody regenerates).
pub fn splice_all(doc: &str, prefix: &str, blocks: &[Block]) -> Result<String> {
    let mut out = doc.to_string();
    for block in blocks {
        out = splice(&out, &block.name, &block.body)?;
    }
    for line in doc.lines() {
        let name = line.strip_prefix("<!-- ").and_then(|l| l.strip_suffix(":begin -->"));
        if let Some(name) = name.filter(|n| n.starts_with(prefix))
            && !blocks.iter().any(|b| b.name == name)
        {
            bail!("block `{name}` is in the document but this program does not generate it");
        }
    }
    Ok(out)
}

/// Reads `path`, splices `blocks` into it and writes it back atomically.
pub fn splice_file(path: &Path, prefix: &str, blocks: &[Block]) -> Result<()> {
    let doc = std::fs::read_to_string(path).with_context(|| format!("{}: cannot read", path.display()))?;
    let out = splice_all(&doc, prefix, blocks).with_context(|| path.display().to_string())?;
    crate::run_info::write_atomically(path, out.as_bytes()).with_context(|| format!("{}: cannot write", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn replaces_only_between_the_markers() {
        let doc = "prose\n<!-- t:begin -->\n\nold\n\n<!-- t:end -->\nmore prose\n";
        let out = splice(doc, "t", "new\nlines").unwrap();
        assert_eq!(out, "prose\n<!-- t:begin -->\n\nnew\nlines\n\n<!-- t:end -->\nmore prose\n");
        assert_eq!(splice(&out, "t", "new\nlines").unwrap(), out, "splicing twice changes nothing");
    }

    #[test]
    fn missing_or_stale_markers_fail() {
        assert!(splice("prose\n", "t", "x").is_err());
        let doc = "<!-- p:a:begin -->\n<!-- p:a:end -->\n<!-- p:b:begin -->\n<!-- p:b:end -->\n";
        assert!(splice_all(doc, "p:", &[Block::new("p:a", "x")]).is_err());
        assert!(splice_all(doc, "p:", &[Block::new("p:a", "x"), Block::new("p:b", "y")]).is_ok());
    }

    #[test]
    fn a_new_block_comes_with_its_section_once() {
        let doc = with_block("prose", "t", "## T");
        assert_eq!(doc, "prose\n\n## T\n\n<!-- t:begin -->\n<!-- t:end -->\n");
        assert_eq!(with_block(&doc, "t", "## T"), doc, "a block already there is left as it is");
        let out = splice(&doc, "t", "table").unwrap();
        assert_eq!(out, "prose\n\n## T\n\n<!-- t:begin -->\n\ntable\n\n<!-- t:end -->\n");
    }
}
