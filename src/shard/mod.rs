//! Scale-out: one pyramid cut by many machines, merged into the pack one machine makes. This
//! module is what the runs share (the runs themselves are [`crate::scale_out`]).
//!
//! `split --shard I/N` makes shard `I` of `N` ([`plan`]: whole subtrees of a cut level,
//! balanced by real pages) into a shard pack: its pages at the cut level and below, and in
//! its metadata ([`manifest`]) the exact sums of its subtree roots ([`sums`]) and what it was
//! made from ([`fingerprint`](mod@fingerprint)). `merge` ([`crate::scale_out::merge()`]) checks that the shards belong together,
//! makes the levels above the cut from the sums (the same exact cascade, so the same texels),
//! and stores every page in the order one machine's `split --pack` would ([`order`]), copying
//! the shards' payloads as they are: the merged pack is that pack, byte for byte.

pub mod fingerprint;
pub mod manifest;
pub mod order;
pub mod plan;
pub mod sums;

pub use fingerprint::fingerprint;
