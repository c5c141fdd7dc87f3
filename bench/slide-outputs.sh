#!/usr/bin/env bash
# bench/slide-outputs.sh: a slide into three outputs from one read, against three runs of one
# output each (issue 42).
#
# What it measures (results go to docs/benchmarks.md between the slide-outputs markers): the
# slide-like JPEG-tiled TIFF of bench/slide-dzi.sh (SIZE, default 50000x40000, made by
# bench/lib.sh's make_slide) into
#   - Deep Zoom, 256-texel tiles with no overlap (--layout dzi --overlap 0),
#   - a pack (256-texel pages, --border 0),
#   both JPEG: the slide's stored tiles are copied into both (the finest level's whole tiles;
#   its edge tiles cropped losslessly for Deep Zoom), the levels above encoded once for both;
#   - OME-Zarr 0.5 (256-texel zstd chunks, the box filter: a pyramid of its own, every tile
#     decoded),
# alternately RUNS times (default 3), each under /usr/bin/time -v (wall, user+system CPU, peak
# RSS):
#   all       vortex-tiler split SLIDE -o OUT/web --layout dzi --overlap 0 --pack OUT/x.vtpk
#             --border 0 -o OUT/x.ome.zarr --tile-size 256 --json
#   dzi, pack, ome-zarr   each output in a run of its own, with the same flags
# Medians over the runs, and the tiles each output copied and encoded (from --json). On the
# first run every output of the one run is checked against its run of its own, byte for byte.
#
# Usage, from the repository root:  bench/slide-outputs.sh   (RUNS=3, SIZE=50000x40000).
# VORTEX_PYVIPS=PYTHON names a Python with pyvips (the CI venv), else bench/lib.sh installs one.
# Needs a release build (`cargo build --release -p vortex-tiler`; CARGO_TARGET_DIR is honoured)
# and about 8 GB of disk in bench/work.
set -euo pipefail

cd "$(dirname "$0")/.."
source bench/lib.sh
RUNS=${RUNS:-3}
SIZE=${SIZE:-50000x40000}
W=${SIZE%x*}
H=${SIZE#*x}
splice_check slide-outputs

snapshot_release # VT, REV
pyvips_setup

cd "$WORK"
SLIDE=slide-$SIZE.tif
make_slide "$W" "$H" "$SLIDE"
OUT=$WORK/out-slide-outputs
rm -rf "$OUT"
mkdir -p "$OUT"
RESULTS=$WORK/slide-outputs-runs.tsv # tool run wall_s rss_kib cpu_s copied encoded
: >"$RESULTS"
COMMON=(--tile-size 256 --json)

cpu() { awk -F': ' '/User time|System time/ { s += $2 } END { printf "%.2f", s }' "$WORK/time.txt"; }
# figure LOG KEY: KEY's values in a run's --json, summed over its outputs' pyramids (an output
# that shares a pyramid repeats its figures, so each pyramid is counted once).
figure() {
  "$PY" - "$1" "$2" <<'PY'
import json, sys
doc = json.loads(open(sys.argv[1]).read())
outputs = doc.get("outputs", [doc])
seen = {}
for o in outputs:
    seen.setdefault(o.get("pyramid", 0), o.get(sys.argv[2], 0))
print(sum(seen.values()))
PY
}

run_tool() {
  local tool=$1 run=$2 dest=$OUT/$1-$2
  local result
  mkdir -p "$dest"
  case $tool in
    all) result=$(measure "$WORK/$tool.log" "$VT" split "$SLIDE" -o "$dest/web" --layout dzi --overlap 0 \
      --pack "$dest/x.vtpk" --border 0 -o "$dest/x.ome.zarr" "${COMMON[@]}") ;;
    dzi) result=$(measure "$WORK/$tool.log" "$VT" split "$SLIDE" -o "$dest/web" --layout dzi --overlap 0 "${COMMON[@]}") ;;
    pack) result=$(measure "$WORK/$tool.log" "$VT" split "$SLIDE" --pack "$dest/x.vtpk" --border 0 "${COMMON[@]}") ;;
    ome-zarr) result=$(measure "$WORK/$tool.log" "$VT" split "$SLIDE" -o "$dest/x.ome.zarr" "${COMMON[@]}") ;;
  esac
  local copied encoded
  copied=$(figure "$WORK/$tool.log" copied)
  encoded=$(figure "$WORK/$tool.log" encoded)
  printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$tool" "$run" "${result% *}" "${result#* }" "$(cpu)" "$copied" "$encoded" >>"$RESULTS"
  log "$tool run $run: ${result% *} s, $((${result#* } / 1024)) MiB peak, $(cpu) s CPU, copied $copied, encoded $encoded"
  [ "$run" = 1 ] || rm -rf "$dest"
}

cat "$SLIDE" >/dev/null # warm the page cache
TOOLS=(all dzi pack ome-zarr)
for run in $(seq 1 "$RUNS"); do
  for tool in "${TOOLS[@]}"; do run_tool "$tool" "$run"; done
done

# The one run's outputs against the runs of their own, byte for byte.
cmp -s "$OUT/all-1/x.vtpk" "$OUT/pack-1/x.vtpk" || { echo "error: the packs differ" >&2; exit 1; }
diff -rq "$OUT/all-1/web" "$OUT/dzi-1/web" >/dev/null || { echo "error: the Deep Zoom outputs differ" >&2; exit 1; }
diff -rq "$OUT/all-1/x.ome.zarr" "$OUT/ome-zarr-1/x.ome.zarr" >/dev/null ||
  { echo "error: the OME-Zarr outputs differ" >&2; exit 1; }

REPORT=$WORK/slide-outputs-report.md
{
  m() { median "$RESULTS" "$1" "$2"; }
  echo "Measured $(date -u +%Y-%m-%d) with \`bench/slide-outputs.sh\` (vortex-tiler $REV, RUNS=$RUNS, medians; $(nproc) cores):"
  echo "the ${W} x ${H} slide-like TIFF of \`bench/slide-dzi.sh\` (256-texel JPEG tiles, Q90) into Deep Zoom (256, no"
  echo "overlap) and a pack (256, no border), the stored tiles copied into both, and OME-Zarr 0.5 (256-texel chunks),"
  echo "in one run and in a run each. The one run's files were checked against the runs of their own, byte for byte."
  echo
  echo "| run | wall | CPU (user + system) | peak RSS | tiles copied / encoded |"
  echo "|---|---:|---:|---:|---:|"
  sum_wall=0
  sum_cpu=0
  slowest=0
  for tool in "${TOOLS[@]}"; do
    wall=$(m "$tool" 3)
    case $tool in
      all) label="one run, three outputs" ;;
      *) label="$tool alone"
         sum_wall=$(calc '%.2f' "$sum_wall + $wall")
         sum_cpu=$(calc '%.2f' "$sum_cpu + $(m "$tool" 5)")
         slowest=$(calc '%.2f' "($wall > $slowest) ? $wall : $slowest") ;;
    esac
    echo "| $label | $(calc '%.2f' "$wall") s | $(calc '%.2f' "$(m "$tool" 5)") s | $(calc '%.0f' "$(m "$tool" 4) / 1024") MiB | $(m "$tool" 6) / $(m "$tool" 7) |"
  done
  echo "| the three runs of one output, added | $sum_wall s | $sum_cpu s | | |"
  all_wall=$(m all 3)
  echo
  echo "The one run takes $(calc '%.2f' "$all_wall / $slowest")x the wall of the slowest single output"
  echo "and is $(calc '%.2f' "$sum_wall / $all_wall")x faster than the three runs."
} >"$REPORT"
splice slide-outputs "$REPORT" "## A slide into several outputs in one run"
cat "$REPORT"
rm -rf "$OUT"
