#!/usr/bin/env bash
# bench/outputs.sh: four outputs from one read of the input against four runs of one output
# each, and against libvips writing one of them (issue 42).
#
# What it measures (results go to docs/benchmarks.md between the outputs markers): the 16384 x
# 16384 RGB strip BigTIFF of bench/lib.sh into
#   - Deep Zoom, 256-texel tiles with no overlap (--layout dzi --overlap 0),
#   - PMTiles (256-texel web-map tiles),
#   - a pack (256-texel pages, --border 0),
#   all three JPEG quality 85, which share one pyramid and each tile's encoding, plus
#   - OME-Zarr 0.5 (256-texel zstd chunks, the box filter: a pyramid of its own),
# alternately RUNS times (default 5), each under /usr/bin/time -v (wall, user+system CPU, peak
# RSS):
#   all       vortex-tiler split SRC -o OUT/web --layout dzi --overlap 0 --pmtiles OUT/x.pmtiles
#             --pack OUT/x.vtpk --border 0 -o OUT/x.ome.zarr --tile-size 256 --quality 85 -q
#   dzi, pmtiles, pack, ome-zarr   each output in a run of its own, with the same flags
#   pyvips    libvips 8.18 (PyPI) dzsave(tile_size=256, overlap=0, Q=85), sequential, direct
#             mode: the same Deep Zoom (skipped with a note without it; PYVIPS=0 skips it)
# Medians over the runs. The report gives the one run's wall against the slowest single
# output's (goal: at most 1.5x) and against the four separate runs' sum (goal: 2.5x faster),
# and checks on the first run that every output of the one run holds the same files as its
# run of its own, byte for byte.
#
# Usage, from the repository root:  bench/outputs.sh   (RUNS=5). Works in bench/work/
# (git-ignored) as the other scripts do; needs a release build, made by bench/lib.sh.
set -euo pipefail

cd "$(dirname "$0")/.."
source bench/lib.sh
RUNS=${RUNS:-5}
PYVIPS=${PYVIPS:-1}
splice_check outputs

bench_setup # vips, time, bin/vortex-tiler, src16k.tif, REV
PYVIPS_VERSION=
[ "$PYVIPS" = 1 ] && pyvips_setup

cd "$WORK"
OUT=$WORK/out-outputs
rm -rf "$OUT"
mkdir -p "$OUT"
RESULTS=$WORK/outputs-runs.tsv # tool run wall_s rss_kib cpu_s
: >"$RESULTS"
VT=$WORK/bin/vortex-tiler
COMMON=(--tile-size 256 --quality 85 -q)

# cpu LOG: user + system seconds of the last measured run (bench/lib.sh's measure keeps time.txt).
cpu() { awk -F': ' '/User time|System time/ { s += $2 } END { printf "%.2f", s }' "$WORK/time.txt"; }

run_tool() {
  local tool=$1 run=$2 dest=$OUT/$1-$2
  local result
  mkdir -p "$dest"
  case $tool in
    all) result=$(measure "$WORK/$tool.log" "$VT" split src16k.tif -o "$dest/web" --layout dzi --overlap 0 \
      --pmtiles "$dest/x.pmtiles" --pack "$dest/x.vtpk" --border 0 -o "$dest/x.ome.zarr" "${COMMON[@]}") ;;
    dzi) result=$(measure "$WORK/$tool.log" "$VT" split src16k.tif -o "$dest/web" --layout dzi --overlap 0 "${COMMON[@]}") ;;
    pmtiles) result=$(measure "$WORK/$tool.log" "$VT" split src16k.tif --pmtiles "$dest/x.pmtiles" "${COMMON[@]}") ;;
    pack) result=$(measure "$WORK/$tool.log" "$VT" split src16k.tif --pack "$dest/x.vtpk" --border 0 "${COMMON[@]}") ;;
    ome-zarr) result=$(measure "$WORK/$tool.log" "$VT" split src16k.tif -o "$dest/x.ome.zarr" --tile-size 256 -q) ;;
    pyvips) result=$(measure "$WORK/$tool.log" "$PY" -c "import pyvips; pyvips.Image.new_from_file('src16k.tif', access='sequential').dzsave('$dest/src16k', tile_size=256, overlap=0, Q=85)") ;;
  esac
  printf '%s\t%s\t%s\t%s\t%s\n' "$tool" "$run" "${result% *}" "${result#* }" "$(cpu)" >>"$RESULTS"
  log "$tool run $run: ${result% *} s, $((${result#* } / 1024)) MiB peak, $(cpu) s CPU"
  # Keep the first run's outputs for the check; later ones only take disk.
  [ "$run" = 1 ] || rm -rf "$dest"
}

cat src16k.tif >/dev/null # warm the page cache
SINGLES=(dzi pmtiles pack ome-zarr)
TOOLS=(all "${SINGLES[@]}")
[ -n "$PYVIPS_VERSION" ] && TOOLS+=(pyvips)
for run in $(seq 1 "$RUNS"); do
  for tool in "${TOOLS[@]}"; do run_tool "$tool" "$run"; done
done

# The one run's outputs against the runs of their own.
same() { cmp -s "$1" "$2" || { echo "error: $1 differs from $2" >&2; exit 1; }; }
same "$OUT/all-1/x.vtpk" "$OUT/pack-1/x.vtpk"
same "$OUT/all-1/x.pmtiles" "$OUT/pmtiles-1/x.pmtiles"
diff -rq "$OUT/all-1/web" "$OUT/dzi-1/web" >/dev/null || { echo "error: the Deep Zoom outputs differ" >&2; exit 1; }
diff -rq "$OUT/all-1/x.ome.zarr" "$OUT/ome-zarr-1/x.ome.zarr" >/dev/null ||
  { echo "error: the OME-Zarr outputs differ" >&2; exit 1; }

REPORT=$WORK/outputs-report.md
{
  m() { median "$RESULTS" "$1" "$2"; }
  echo "Measured $(date -u +%Y-%m-%d) with \`bench/outputs.sh\` (vortex-tiler $REV, RUNS=$RUNS, medians; $(nproc) cores):"
  echo "the 16384 x 16384 RGB strip BigTIFF into Deep Zoom (256, no overlap), PMTiles and a pack (256, no border),"
  echo "JPEG quality 85, and OME-Zarr 0.5 (256-texel chunks), in one run and in a run each. The one run's"
  echo "files were checked against the runs of their own, byte for byte."
  echo
  echo "| run | wall | CPU (user + system) | peak RSS |"
  echo "|---|---:|---:|---:|"
  sum_wall=0
  sum_cpu=0
  slowest=0
  for tool in "${TOOLS[@]}"; do
    wall=$(m "$tool" 3)
    case $tool in
      all) label="one run, four outputs" ;;
      pyvips) label="pyvips dzsave $PYVIPS_VERSION (Deep Zoom only)" ;;
      *) label="$tool alone"
         sum_wall=$(calc '%.2f' "$sum_wall + $wall")
         sum_cpu=$(calc '%.2f' "$sum_cpu + $(m "$tool" 5)")
         slowest=$(calc '%.2f' "($wall > $slowest) ? $wall : $slowest") ;;
    esac
    echo "| $label | $(calc '%.2f' "$wall") s | $(calc '%.2f' "$(m "$tool" 5)") s | $(calc '%.0f' "$(m "$tool" 4) / 1024") MiB |"
  done
  echo "| the four runs of one output, added | $sum_wall s | $sum_cpu s | |"
  all_wall=$(m all 3)
  echo
  echo "The one run takes $(calc '%.2f' "$all_wall / $slowest")x the wall of the slowest single output (goal: at most 1.5x)"
  echo "and is $(calc '%.2f' "$sum_wall / $all_wall")x faster than the four runs (goal: 2.5x)."
  if [ -n "$PYVIPS_VERSION" ]; then
    echo "libvips writes the Deep Zoom alone in $(calc '%.2f' "$(m pyvips 3)") s: the four outputs take $(calc '%.2f' "$all_wall / $(m pyvips 3)")x its time."
  fi
} >"$REPORT"
splice outputs "$REPORT" "## Several outputs in one run (split -o ... -o ...)"
cat "$REPORT"
rm -rf "$OUT"
