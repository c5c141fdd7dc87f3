//! What the measurement programs share. Each binary (`accuracy`, `sampling_cost`) measures
//! something and writes only what it computed (tables, verdicts, plots) into a document whose
//! prose is written by hand: [`splice`] puts each generated block between its markers,
//! [`run_info`] says when and where the run happened and writes the result atomically, and
//! [`measure`] holds the arithmetic of their tables (medians, PSNR). The tools the benchmark
//! scripts run are binaries here too: `gen_image` (synthetic test images of any size), `psnr`
//! (a pyramid's finest level against its source), `codec_speed` (each tile codec's cost) and
//! `create_files` (what creating a tile file costs the file system).
//!
//! ```sh
//! cargo run --release -p vortex-bench --bin accuracy        # docs/accuracy.md + its two SVGs
//! cargo run --release -p vortex-bench --bin sampling_cost   # docs/gpu-sampling.md (lavapipe)
//! cargo run --release -p vortex-bench --bin gen_image -- 2048 2048 img.png
//! cargo run --release -p vortex-bench --bin psnr -- img.png --vortex OUT_DIR
//! cargo run --release -p vortex-bench --bin codec_speed -- img.png
//! cargo run --release -p vortex-bench --bin create_files -- /tmp/new-dir --threads 2
//! ```
#![allow(clippy::unwrap_used, clippy::expect_used)] // measurement programs may panic on a broken set-up

pub mod ground;
pub mod measure;
pub mod run_info;
pub mod splice;

/// Appends one formatted line (or an empty one) to a `String`: `out!(s)`, `out!(s, "{x}")`.
#[macro_export]
macro_rules! out {
    ($s:expr) => {
        $s.push('\n')
    };
    ($s:expr, $($t:tt)*) => {{
        use std::fmt::Write as _;
        writeln!($s, $($t)*).expect("writing to a String")
    }};
}
