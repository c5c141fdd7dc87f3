//! Puts a benchmark script's report into a document, between the lines `<!-- NAME:begin -->`
//! and `<!-- NAME:end -->` ([`vortex_bench::splice`]: the one implementation of the convention,
//! which `bench/lib.sh`'s `splice` and `splice_check` call).
//!
//! ```sh
//! splice DOC NAME REPORT [INTRO]   # REPORT's text into block NAME; without the block, a new
//!                                  # section INTRO with it is appended first (none without INTRO)
//! splice --check DOC NAME          # only check that NAME's markers are there, once each, in order
//! ```

use std::path::Path;

use anyhow::{Context, Result, bail};
use vortex_bench::run_info::write_atomically;
use vortex_bench::splice::{splice, with_block};

const USAGE: &str = "usage: splice DOC NAME REPORT [INTRO] | splice --check DOC NAME";

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let read = |path: &str| std::fs::read_to_string(path).with_context(|| format!("{path}: cannot read"));
    match args.as_slice() {
        [flag, doc, name] if flag == "--check" => {
            splice(&read(doc)?, name, "")
                .with_context(|| format!("{doc}: the report of block `{name}` has no place"))?;
        }
        [doc, name, report, intro @ ..] if intro.len() <= 1 => {
            let text = match intro.first().filter(|i| !i.is_empty()) {
                Some(intro) => with_block(&read(doc)?, name, intro),
                None => read(doc)?,
            };
            let out = splice(&text, name, &read(report)?).with_context(|| doc.clone())?;
            write_atomically(Path::new(doc), out.as_bytes()).with_context(|| format!("{doc}: cannot write"))?;
        }
        _ => bail!(USAGE),
    }
    Ok(())
}
