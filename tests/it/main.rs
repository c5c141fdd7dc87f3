//! The root crate's integration tests, one binary (one link instead of one per file). Each
//! module is one concern; `common` holds the shared helpers (in-memory sources and sinks, the
//! naive whole-image oracle, running the built binary).
//!
//! Run one module with a filter, e.g. `cargo test --test it oracle::`; bless the golden files
//! with `BLESS=1 cargo test --test it golden::` after checking the diff.
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests and measurement programs may panic on a broken set-up

mod browser;
mod cli;
mod codecs;
mod color;
mod common;
mod convert;
mod copy_tiles;
mod dicom_in;
mod dicom_jxl;
mod dicom_out;
mod docs;
mod failures;
mod fast_shrink;
mod golden;
mod hostile;
mod hostile_sources;
mod iiif;
mod jxl;
mod keep_icc;
mod library;
mod memory;
mod module_graph;
mod ndpi;
mod object_storage;
mod ome_zarr;
mod openslide_files;
mod oracle;
mod outputs;
mod pack_cli;
mod pack_trust;
mod pixel_size;
mod pmtiles;
mod remote_pack;
mod render;
mod resample_reference;
mod resume;
mod sample_types;
mod serve;
mod serve_hostile;
mod shard;
mod slurm;
mod sources;
mod stability;
mod stage_cpu;
mod static_web;
mod stripes;
mod tiff_corpus;
mod tiff_kinds;
mod tiff_out;
mod tiff_planes;
mod tiff_slides;
mod value_range;
mod view;
mod viewers;
mod vtpk_js;
mod web_runtime;
