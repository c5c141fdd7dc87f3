//! Failures in the middle of a run stop it cleanly with the first error, on every thread count.

use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};

use crate::common;
use crate::common::{Image, layouts, png_options};
use vortex_tiler::background::Background;
use vortex_tiler::error::{Result, TilerError};
use vortex_tiler::sink::TileSink;
use vortex_tiler::source::{ImageHeader, RowSource};
use vortex_tiler::split::split;

/// Fails with a full disk after `ok` tiles.
struct FullDisk {
    ok: usize,
    written: AtomicUsize,
}

impl TileSink for FullDisk {
    fn write_tile(&self, _: u32, _: u32, _: u32, _: &[u8]) -> Result<()> {
        if self.written.fetch_add(1, Ordering::SeqCst) >= self.ok {
            return Err(TilerError::write("out/tile.png", std::io::Error::from_raw_os_error(28)));
        }
        Ok(())
    }
    fn bytes_written(&self) -> u64 {
        0
    }
}

/// Delivers `good` rows, then fails.
struct BrokenSource {
    inner: Box<dyn RowSource>,
    good: u64,
    row: u64,
}

impl RowSource for BrokenSource {
    fn header(&self) -> ImageHeader {
        self.inner.header()
    }
    fn read_row(&mut self, row: &mut [u8]) -> Result<()> {
        if self.row == self.good {
            return Err(TilerError::DecodeRow {
                path: PathBuf::from("broken.png"),
                row: self.row,
                message: "boom".into(),
            });
        }
        self.row += 1;
        self.inner.read_row(row)
    }
    fn describe(&self) -> String {
        "broken".into()
    }
}

#[test]
fn a_failing_sink_stops_the_run_with_its_error() {
    let image = Image::random(300, 300, layouts()[4], 3);
    for threads in [1, 2, 4] {
        for ok in [0, 5, 200] {
            let sink = FullDisk { ok, written: AtomicUsize::new(0) };
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            let err =
                pool.install(|| split(image.source(), &sink, &png_options(16, 1, Background::Edge), &())).unwrap_err();
            let text = err.to_string();
            assert!(text.contains("out/tile.png") && text.contains("No space left"), "{text}");
        }
    }
}

#[test]
fn a_failing_source_stops_the_run_naming_the_row() {
    let image = Image::random(200, 200, layouts()[2], 4);
    for good in [0, 1, 57, 199] {
        let src = Box::new(BrokenSource { inner: image.source(), good, row: 0 });
        let err = split(src, &common::MemSink::default(), &png_options(32, 2, Background::Edge), &()).unwrap_err();
        assert_eq!(err.to_string(), format!("broken.png: row {good}: boom"));
    }
}
