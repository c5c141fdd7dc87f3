//! Everything `accuracy` takes from the tiler, in one place: the pipeline it runs (`split`, the
//! pack sink, the row source it feeds), the choices it sweeps (filters, codecs) and the defaults
//! it judges (`settings::resolve`). When the tiler's modules move, only these paths change.

pub use vortex_tiler::background::Background;
pub use vortex_tiler::codec::{Bc7Effort, Codec, JxlEffort, PngLevel, RowFilter, Subsampling};
pub use vortex_tiler::error::Result as TilerResult;
pub use vortex_tiler::formats::pack::PackSink;
pub use vortex_tiler::layout::Layout;
pub use vortex_tiler::pixel::{Channels, Depth, PixelLayout};
pub use vortex_tiler::pyramid::Filter;
pub use vortex_tiler::settings::{self, CodecChoice, Requested};
pub use vortex_tiler::source::{ImageHeader, RowSource};
pub use vortex_tiler::split::{self, SplitOptions};
