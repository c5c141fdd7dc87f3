//! The integration tests of `vortex-vt-wgpu`, one binary: one link instead of one per file, and the
//! helpers in `common` shared without `#![allow(dead_code)]`. The GPU tests run on whatever
//! adapter wgpu finds, pinned to lavapipe (Mesa's CPU Vulkan driver) when it is installed and no
//! Vulkan driver is chosen; without an adapter they print a note and pass, except under
//! `CI=true`, where they fail. `loader` needs no GPU.
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests and measurement programs may panic on a broken set-up

mod address;
mod anisotropy;
mod common;
mod defaults;
mod embed;
mod feedback;
mod huge;
mod latency;
mod layers;
mod loader;
mod readback;
mod runtime;
mod sample;
mod tier;
mod transcode;
