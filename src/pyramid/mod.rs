//! The pyramid: every power-of-two LOD made from the source rows as they arrive, and the
//! stored tiles cut out of each level, in memory bounded by `--max-memory` whatever the size.
//!
//! In data order:
//! - `band`: one level's rows of tiles, filled as its rows arrive;
//! - `reduce`: exact 2x2 sums passed from each level to the next, rounded once per texel;
//! - `filter`: what those sums add up (`--filter`: box, linear light, premultiplied);
//! - `resample`: the filters that cannot cascade sums (lanczos3, mitchell), band by band;
//! - `labels`: the filters of label images (mode, nearest), one texel of each 2x2 block;
//! - `cut`: which texels make a tile (payload, borders, padding), and copying a row of them;
//! - `cascade`: all levels in flight at once, wiring the above together for one pass;
//! - `stripes`: the passes of an image too wide for one band: vertical stripes of the fine
//!   levels, then the coarse levels from block sums.
//!
//! Only [`Filter`], an option of [`crate::split::SplitOptions`], is public; the rest is the
//! pipeline's inside (tests reach it through the `testing` feature).

pub(crate) mod band;
pub(crate) mod cascade;
pub(crate) mod cut;
pub(crate) mod filter;
pub(crate) mod labels;
pub(crate) mod reduce;
pub(crate) mod resample;
pub(crate) mod stripes;

pub use filter::Filter;
