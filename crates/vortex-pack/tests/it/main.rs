//! The crate's one integration-test binary (one link instead of one per file); each module is
//! one concern of the reader and writer.
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests and measurement programs may panic on a broken set-up

mod common;
mod fuzz_regressions;
mod hostile;
mod kinds;
mod round_trip;
mod spec;
