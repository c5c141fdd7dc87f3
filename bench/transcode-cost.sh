#!/usr/bin/env bash
# bench/transcode-cost.sh: what transcoding pages to BC1 or BC7 at load costs and gives (issue 17).
#
# The 16384² BigTIFF of bench/split-vs-vips.sh (generated if missing) as the runtime benchmarks'
# JPEG pack (136-texel tiles, 4-texel border: bench/lib.sh world_pack) and as a lossless PNG pack
# cut alike (the source), then `transcode_cost` (crates/vortex-bench) loads 240 pages of the JPEG
# pack through the runtime's loader into each cache format and writes the `transcode` block of
# docs/accuracy.md (or $ACCURACY_DOC): ms per page, GPU bytes per page, PSNR against the RGBA8 cache and
# against the source. About 3 minutes on 2 cores the first time (the PNG pack), 30 s after.
#     bench/transcode-cost.sh
set -euo pipefail
cd "$(dirname "$0")/.."
source bench/lib.sh
bench_setup
PACK=$(world_pack)
SOURCE=$(world_png_pack)
# The block lives in docs/accuracy.md, not in bench/lib.sh's default $DOC.
cargo run --release -q -p vortex-bench --bin transcode_cost -- "$PACK" "$SOURCE" "${ACCURACY_DOC:-$ROOT/docs/accuracy.md}"
