//! The two runs of a scale-out (the crate-private `shard` holds what they share): a shard's run of
//! `split --shard I/N` ([`write_shard`]) and `merge` ([`merge()`]), which joins the shard packs
//! into the pack one machine's `split --pack` makes, byte for byte. Both run the pipeline of
//! [`crate::split`], which sits below them: the shard plan, manifest, page order and sums do not
//! depend on it, so `split` and the sources can use them.

mod merge;
mod objects;
mod write;

// The shard format and geometry, as `super::` paths from the two runs name them.
use crate::shard::{fingerprint, manifest, order, plan, sums};

pub use merge::{Merged, merge, merge_files};
pub use objects::{ShardFiles, claim_pack};
pub use write::{ShardJob, write_shard};

/// What a pack's metadata says of it if it is a shard (`info`), and the refusal of a shard pack
/// where a whole pyramid is needed.
pub use crate::shard::manifest::{describe, refuse_shard};
