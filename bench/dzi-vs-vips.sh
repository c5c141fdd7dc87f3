#!/usr/bin/env bash
# bench/dzi-vs-vips.sh: `split --layout dzi` against `vips dzsave`, the tool people use for Deep
# Zoom today, writing the same files (issue 14).
#
# What it measures (results go to docs/benchmarks.md between the dzi-vs-vips markers):
#   the 16384 x 16384 RGB BigTIFF of bench/lib.sh cut into Deep Zoom tiles of 254 texels with
#   overlap 1 (vips' defaults), JPEG quality 85, alternately RUNS times by
#     - vortex-tiler split SRC --layout dzi -o OUT --tile-size 254 --overlap 1 --quality 85 --filter box -q
#       (levels averaged in stored values, as vips does) and the same with the default filter
#       (linear-premultiplied: averaged in linear light)
#     - vips dzsave SRC OUT/src16k --tile-size 254 --overlap 1 --suffix .jpeg[Q=85]   (Debian 8.14)
#     - pyvips dzsave(tile_size=254, overlap=1, Q=85), sequential access (direct mode: bench/lib.sh)
#       (libvips 8.18 from PyPI's pyvips-binary, in a venv; skipped with a note without it)
#   each under /usr/bin/time -v: wall clock and peak RSS, medians over the runs; the tile files
#   each wrote are counted, and the runs stop if vortex-tiler's set of file names differs from
#   vips'.
#
# Usage, from the repository root:  bench/dzi-vs-vips.sh     (RUNS=3 by default; PYVIPS=0
# skips the PyPI peer). Works in bench/work/ (git-ignored), as bench/split-vs-vips.sh does.
set -euo pipefail

cd "$(dirname "$0")/.."
source bench/lib.sh
RUNS=${RUNS:-3}
PYVIPS=${PYVIPS:-1}

bench_setup # vips, time, bin/vortex-tiler, src16k.tif, REV
VIPS_VERSION=$(vips --version)
PYVIPS_VERSION=
[ "$PYVIPS" = 1 ] && pyvips_setup

cd "$WORK"
OUT=$WORK/out-dzi
rm -rf "$OUT"
mkdir -p "$OUT"
RESULTS=$WORK/dzi-runs.tsv # tool run wall_s rss_kib tiles
: >"$RESULTS"
VT=$WORK/bin/vortex-tiler
tiles() { find "$1" -type f -name '*.jpeg' | wc -l; }

run_tool() {
  local tool=$1 run=$2 dest=$OUT/$1-$2
  local result
  case $tool in
    vortex-box) result=$(measure "$WORK/$tool.log" "$VT" split src16k.tif --layout dzi -o "$dest" --tile-size 254 --overlap 1 --quality 85 --filter box -q) ;;
    vortex-linear) result=$(measure "$WORK/$tool.log" "$VT" split src16k.tif --layout dzi -o "$dest" --tile-size 254 --overlap 1 --quality 85 -q) ;;
    vips) mkdir -p "$dest" && result=$(measure "$WORK/$tool.log" vips dzsave src16k.tif "$dest/src16k" --tile-size 254 --overlap 1 --suffix '.jpeg[Q=85]') ;;
    pyvips) mkdir -p "$dest" && result=$(measure "$WORK/$tool.log" "$PY" -c "import pyvips; pyvips.Image.new_from_file('src16k.tif', access='sequential').dzsave('$dest/src16k', tile_size=254, overlap=1, Q=85)") ;;
  esac
  printf '%s\t%s\t%s\t%s\t%s\n' "$tool" "$run" "${result% *}" "${result#* }" "$(tiles "$dest")" >>"$RESULTS"
  log "$tool run $run: ${result% *} s, $((${result#* } / 1024)) MiB peak"
}

cat src16k.tif >/dev/null # warm the page cache
TOOLS=(vortex-box vortex-linear vips)
[ -n "$PYVIPS_VERSION" ] && TOOLS+=(pyvips)
for run in $(seq 1 "$RUNS"); do
  for tool in "${TOOLS[@]}"; do run_tool "$tool" "$run"; done
done

# The same files as vips: names of tiles and descriptor (vips adds vips-properties.xml).
names() { (cd "$1" && find . -type f ! -name vips-properties.xml | sort); }
if ! diff -q <(names "$OUT/vortex-box-1") <(names "$OUT/vips-1") >/dev/null; then
  echo "error: split --layout dzi wrote other files than vips dzsave" >&2
  exit 1
fi

REPORT=$WORK/dzi-report.md
{
  echo "Measured $(date -u +%Y-%m-%d) with \`bench/dzi-vs-vips.sh\` (vortex-tiler $REV, RUNS=$RUNS, medians; $(nproc) cores):"
  echo "the 16384 x 16384 RGB BigTIFF into Deep Zoom tiles of 254 texels with overlap 1, JPEG quality 85."
  echo "Both write the same $(tiles "$OUT/vips-1") tile files (names checked here; tile sizes by \`tests/it/viewers.rs\`)."
  echo
  echo "| tool | wall | peak RSS | vips 8.14 / tool (wall) |"
  echo "|---|---:|---:|---:|"
  vips_wall=$(median "$RESULTS" vips 3)
  for tool in "${TOOLS[@]}"; do
    wall=$(median "$RESULTS" "$tool" 3)
    rss=$(median "$RESULTS" "$tool" 4)
    case $tool in
      vortex-box) label="vortex-tiler \`--filter box\`" ;;
      vortex-linear) label="vortex-tiler (default: linear light)" ;;
      vips) label="vips dzsave $VIPS_VERSION" ;;
      pyvips) label="pyvips dzsave $PYVIPS_VERSION" ;;
    esac
    echo "| $label | $(calc '%.2f' "$wall") s | $(calc '%.0f' "$rss / 1024") MiB | $(calc '%.2f' "$vips_wall / $wall")x |"
  done
  if [ -n "$PYVIPS_VERSION" ]; then
    echo
    echo "Against $PYVIPS_VERSION: vortex-tiler \`--filter box\` is $(calc '%.2f' "$(median "$RESULTS" pyvips 3) / $(median "$RESULTS" vortex-box 3)")x its speed."
  fi
} >"$REPORT"
splice dzi-vs-vips "$REPORT" "## Deep Zoom: split --layout dzi against vips dzsave"
cat "$REPORT"
rm -rf "$OUT"
