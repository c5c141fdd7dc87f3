#!/usr/bin/env bash
# bench/convert-vs-vips.sh: `vortex-tiler convert` against `vips arrayjoin` + `vips dzsave`.
#
# Input: 4096 JPEG tiles of 256² (a 64 x 64 grid, the LOD 0 of `split` run on the 16384²
# BigTIFF of bench/split-vs-vips.sh). Output: 128-texel pages with a 4-texel border, JPEG Q85,
# every LOD. vortex-tiler: `convert DIR --pack OUT.vtpk` (one pass, one pack file). vips, the
# way its users join tiles: `vips arrayjoin` of the 4096 files into one image (a .v file),
# then `vips dzsave --tile-size 120 --overlap 4`; both steps are timed, and the peak memory is
# the larger of the two. Runs alternate RUNS times (default 3); medians go into
# docs/benchmarks.md (or $DOC).
#     bench/convert-vs-vips.sh
set -euo pipefail
cd "$(dirname "$0")/.."
source bench/lib.sh
RUNS=${RUNS:-3}
bench_setup
cd "$WORK"
if [ ! -s tiles256/info.json ]; then
  log "making the 4096 input tiles"
  rm -rf tiles256
  bin/vortex-tiler split src16k.tif -o tiles256 --tile-size 256 --border 0 --codec jpeg --quality 90 --filter box -q
fi
FILES=$(for y in $(seq 0 63); do for x in $(seq 0 63); do printf 'tiles256/lod00-x%04d-y%04d.jpg ' "$x" "$y"; done; done)
find tiles256 -name 'lod00-*' -exec cat {} + >/dev/null # page cache
OUT=$WORK/out-convert
rm -rf "$OUT"
mkdir -p "$OUT"
RESULTS=$WORK/convert-results.tsv # tool run wall_s rss_kib output_bytes
: >"$RESULTS"
for run in $(seq 1 "$RUNS"); do
  read -r wall rss < <(measure vortex.log bin/vortex-tiler convert tiles256 --pack "$OUT/v$run.vtpk" --tile-size 128 --border 4 --codec jpeg --quality 85 --filter box -q)
  printf 'vortex\t%s\t%s\t%s\t%s\n' "$run" "$wall" "$rss" "$(stat -c %s "$OUT/v$run.vtpk")" >>"$RESULTS"
  log "vortex run $run: $wall s, $((rss / 1024)) MiB"
  read -r w1 r1 < <(measure join.log vips arrayjoin "$FILES" "$OUT/joined$run.v" --across 64)
  read -r w2 r2 < <(measure dz.log vips dzsave "$OUT/joined$run.v" "$OUT/d$run" --tile-size 120 --overlap 4 --suffix '.jpg[Q=85]')
  rm -f "$OUT/joined$run.v"
  printf 'vips\t%s\t%s\t%s\t%s\n' "$run" "$(calc %.2f "$w1 + $w2")" "$((r1 > r2 ? r1 : r2))" "$(du -sb "$OUT/d${run}_files" | cut -f1)" >>"$RESULTS"
  log "vips run $run: $w1 + $w2 s, $((r1 / 1024)) / $((r2 / 1024)) MiB"
done
rm -rf "$OUT"
sync
touch .cleaned

m() { median "$RESULTS" "$@"; }
VW=$(m vips 3) VR=$(m vips 4) OW=$(m vortex 3) OR=$(m vortex 4)
REPORT=$WORK/convert-report.md
{
  echo "Run $(date -u '+%Y-%m-%d %H:%M UTC'), $RUNS alternating runs; $(nproc) cores; $(vips --version); vortex-tiler at $REV."
  echo
  echo "| tool | median wall s | peak RSS MiB | output MiB | throughput vs vips | memory vs vips |"
  echo "|---|---:|---:|---:|---:|---:|"
  echo "| vortex-tiler convert --pack | $(calc %.2f "$OW") | $(calc %.0f "$OR / 1024") | $(calc %.1f "$(m vortex 5) / 1048576") | $(calc %.2fx "$VW / $OW") | $(calc %.2fx "$OR / $VR") |"
  echo "| vips arrayjoin + dzsave | $(calc %.2f "$VW") | $(calc %.0f "$VR / 1024") | $(calc %.1f "$(m vips 5) / 1048576") | 1.00x | 1.00x |"
  echo
  echo "<details><summary>Raw runs (tool, run, wall s, peak RSS KiB, output bytes)</summary>"
  echo
  sed 's/^/    /' "$RESULTS"
  echo
  echo "</details>"
} >"$REPORT"
splice convert-vs-vips "$REPORT" "$(printf '## convert against vips arrayjoin + dzsave\n\n4096 JPEG tiles of 256² (a 64 x 64 grid) re-tiled into 128-texel pages with a 4-texel border, JPEG Q85, every LOD, levels averaged in stored values as vips does (`--filter box`). Reproduce with `bench/convert-vs-vips.sh`.')"
cat "$REPORT"
