//! The clock the frame and the loader time themselves with: std's `Instant` natively; in the
//! browser (wasm32), where std's panics, the page's monotonic clock (`performance.now()`) through
//! `web-time`, which has the same API.

#[cfg(not(target_arch = "wasm32"))]
pub(crate) use std::time::Instant;
#[cfg(target_arch = "wasm32")]
pub(crate) use web_time::Instant;
