#!/usr/bin/env bash
# bench/convert-vs-vips.sh: `vortex-tiler convert` against `vips arrayjoin` + `vips dzsave`.
#
# Input: 4096 JPEG tiles of 256² (a 64 x 64 grid, the LOD 0 of `split` run on the 16384²
# BigTIFF of bench/split-vs-vips.sh). Output: 128-texel pages with a 4-texel border, JPEG Q85,
# every LOD. vortex-tiler: `convert DIR --pack OUT.vtpk` (one pass, one pack file). vips, the
# way its users join tiles: `vips arrayjoin` of the 4096 files into one image (a .v file),
# then `vips dzsave --tile-size 120 --overlap 4`; both steps are timed, and the peak memory is
# the larger of the two. Runs alternate RUNS times (default 3); medians go into
# docs/benchmarks.md between the convert-vs-vips markers.
#     bench/convert-vs-vips.sh
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
WORK=$ROOT/bench/work
DOC=$ROOT/docs/benchmarks.md
RUNS=${RUNS:-3}
mkdir -p "$WORK"
log() { printf '[%(%H:%M:%S)T] %s\n' -1 "$*" >&2; }
command -v vips >/dev/null && [ -x /usr/bin/time ] || {
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq && apt-get install -y -qq libvips-tools time >/dev/null
}
cargo build --release --quiet
cargo build --release --quiet --example gen_image
REV="$(git rev-parse --short HEAD)$(git diff --quiet HEAD -- src crates Cargo.toml Cargo.lock || echo +uncommitted)"
mkdir -p "$WORK/bin"
cp target/release/vortex-tiler target/release/examples/gen_image "$WORK/bin/"
cd "$WORK"
[ -s src16k.tif ] || { log "generating src16k.tif"; bin/gen_image 16384 16384 part16k.tif; mv part16k.tif src16k.tif; }
if [ ! -s tiles256/info.json ]; then
  log "making the 4096 input tiles"
  rm -rf tiles256
  bin/vortex-tiler split src16k.tif -o tiles256 --tile-size 256 --border 0 --codec jpeg --quality 90 -q
fi
FILES=$(for y in $(seq 0 63); do for x in $(seq 0 63); do printf 'tiles256/lod00-x%04d-y%04d.jpg ' "$x" "$y"; done; done)
find tiles256 -name 'lod00-*' -exec cat {} + >/dev/null # page cache
OUT=$WORK/out-convert
rm -rf "$OUT"
mkdir -p "$OUT"
export VIPS_WARNING=0
RESULTS=$WORK/convert-results.tsv # tool run wall_s rss_kib output_bytes
: >"$RESULTS"
field() { sed -n "s/^[[:space:]]*$1: //p" "$2"; }
seconds() { awk -F: '{ s = 0; for (i = 1; i <= NF; i++) s = s * 60 + $i; printf "%.2f", s }' <<<"$1"; }
# measure LOG COMMAND...: prints "wall_s rss_kib"
measure() {
  local log=$1
  shift
  sync
  /usr/bin/time -v -o time.txt "$@" >"$log" 2>&1 || { cat "$log" >&2; exit 1; }
  echo "$(seconds "$(field 'Elapsed (wall clock) time (h:mm:ss or m:ss)' time.txt)") $(field 'Maximum resident set size (kbytes)' time.txt)"
}
for run in $(seq 1 "$RUNS"); do
  read -r wall rss < <(measure vortex.log bin/vortex-tiler convert tiles256 --pack "$OUT/v$run.vtpk" --tile-size 128 --border 4 --codec jpeg --quality 85 -q)
  printf 'vortex\t%s\t%s\t%s\t%s\n' "$run" "$wall" "$rss" "$(stat -c %s "$OUT/v$run.vtpk")" >>"$RESULTS"
  log "vortex run $run: $wall s, $((rss / 1024)) MiB"
  # shellcheck disable=SC2086
  read -r w1 r1 < <(measure join.log vips arrayjoin "$FILES" "$OUT/joined$run.v" --across 64)
  read -r w2 r2 < <(measure dz.log vips dzsave "$OUT/joined$run.v" "$OUT/d$run" --tile-size 120 --overlap 4 --suffix '.jpg[Q=85]')
  rm -f "$OUT/joined$run.v"
  printf 'vips\t%s\t%s\t%s\t%s\n' "$run" "$(awk "BEGIN { print $w1 + $w2 }")" "$((r1 > r2 ? r1 : r2))" "$(du -sb "$OUT/d${run}_files" | cut -f1)" >>"$RESULTS"
  log "vips run $run: $w1 + $w2 s, $((r1 / 1024)) / $((r2 / 1024)) MiB"
done
rm -rf "$OUT"
sync
touch .cleaned
median() { awk -F'\t' -v t="$1" -v c="$2" '$1 == t { print $c }' "$RESULTS" | sort -g |
  awk '{ v[NR] = $1 } END { if (NR % 2) print v[(NR + 1) / 2]; else print (v[NR / 2] + v[NR / 2 + 1]) / 2 }'; }
calc() { awk "BEGIN { printf \"$1\", $2 }"; }
VW=$(median vips 3) VR=$(median vips 4) OW=$(median vortex 3) OR=$(median vortex 4)
REPORT=$WORK/convert-report.md
{
  echo "Run $(date -u '+%Y-%m-%d %H:%M UTC'), $RUNS alternating runs; $(nproc) cores; $(vips --version); vortex-tiler at $REV."
  echo
  echo "| tool | median wall s | peak RSS MiB | output MiB | throughput vs vips | memory vs vips |"
  echo "|---|---:|---:|---:|---:|---:|"
  echo "| vortex-tiler convert --pack | $(calc %.2f "$OW") | $(calc %.0f "$OR / 1024") | $(calc %.1f "$(median vortex 5) / 1048576") | $(calc %.2fx "$VW / $OW") | $(calc %.2fx "$OR / $VR") |"
  echo "| vips arrayjoin + dzsave | $(calc %.2f "$VW") | $(calc %.0f "$VR / 1024") | $(calc %.1f "$(median vips 5) / 1048576") | 1.00x | 1.00x |"
  echo
  echo "<details><summary>Raw runs (tool, run, wall s, peak RSS KiB, output bytes)</summary>"
  echo
  sed 's/^/    /' "$RESULTS"
  echo
  echo "</details>"
} >"$REPORT"
BEGIN='<!-- convert-vs-vips:begin -->'
END='<!-- convert-vs-vips:end -->'
grep -qF "$BEGIN" "$DOC" || printf '\n## convert against vips arrayjoin + dzsave\n\n4096 JPEG tiles of 256² (a 64 x 64 grid) re-tiled into 128-texel pages with a 4-texel border, JPEG Q85, every LOD. Reproduce with `bench/convert-vs-vips.sh`.\n\n%s\n%s\n' "$BEGIN" "$END" >>"$DOC"
awk -v b="$BEGIN" -v e="$END" -v rep="$REPORT" '
  $0 == b { print; print ""; while ((getline l < rep) > 0) print l; print ""; skip = 1; next }
  $0 == e { skip = 0 }
  !skip { print }' "$DOC" >"$DOC.tmp"
mv "$DOC.tmp" "$DOC"
cat "$REPORT"
