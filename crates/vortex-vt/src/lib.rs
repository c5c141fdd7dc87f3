//! The CPU side of Vortex virtual texturing, with no GPU dependency: everything that decides
//! which pages a frame needs and where they live, so that it can be tested exactly on any
//! machine. The GPU runtime drives it once per frame.

pub mod address;
pub mod analysis;
pub mod feedback;
pub mod invariants;
pub mod page;
pub mod page_table;
pub mod residency;
pub mod sampler;
