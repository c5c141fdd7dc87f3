#![doc = include_str!("../README.md")]
// Every public item documented: clippy -D warnings (CI) makes it stick.
#![warn(missing_docs)]

pub mod address;
pub mod analysis;
pub mod anisotropy;
pub mod feedback;
pub mod invariants;
pub mod page;
pub mod page_table;
pub mod residency;
pub mod sampler;
