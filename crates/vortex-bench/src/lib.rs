//! What the measurement programs share. Each binary (`accuracy`, `sampling_cost`) measures
//! something and writes only what it computed (tables, verdicts, plots) into a document whose
//! prose is written by hand: [`splice`] puts each generated block between its markers,
//! [`run_info`] says when and where the run happened and writes the result atomically.
//!
//! ```sh
//! cargo run --release -p vortex-bench --bin accuracy        # docs/accuracy.md + its two SVGs
//! cargo run --release -p vortex-bench --bin sampling_cost   # docs/gpu-sampling.md (lavapipe)
//! ```
#![allow(clippy::unwrap_used, clippy::expect_used)] // measurement programs may panic on a broken set-up

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
