#!/usr/bin/env bash
# bench/pack-vs-vips.sh: `vortex-tiler split --pack` against `vips dzsave` at GPU page sizes.
#
# The 16384 x 16384 RGB BigTIFF of bench/split-vs-vips.sh (generated if missing) is cut into
# 128-texel pages with a 4-texel border (a 120-texel payload, as in id Tech 5), JPEG Q85, every
# LOD: vortex-tiler writes one pack file, vips writes one file per tile
# (`--tile-size 120 --overlap 4`, 128-pixel files). Runs alternate RUNS times (default 5), each
# under /usr/bin/time -v, into fresh outputs deleted only at the end (see split-vs-vips.sh on
# ext4 and recently deleted inodes). Medians go into docs/benchmarks.md between the
# pack-vs-vips markers.
#     bench/pack-vs-vips.sh
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
WORK=$ROOT/bench/work
DOC=$ROOT/docs/benchmarks.md
RUNS=${RUNS:-5}
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
cat src16k.tif >/dev/null
OUT=$WORK/out-pack
rm -rf "$OUT"
mkdir -p "$OUT"
export VIPS_WARNING=0
RESULTS=$WORK/pack-results.tsv # tool run wall_s rss_kib output_bytes
: >"$RESULTS"
field() { sed -n "s/^[[:space:]]*$1: //p" time.txt; }
seconds() { awk -F: '{ s = 0; for (i = 1; i <= NF; i++) s = s * 60 + $i; printf "%.2f", s }' <<<"$1"; }
timed() {
  local tool=$1 run=$2 out=$3
  shift 3
  sync
  /usr/bin/time -v -o time.txt "$@" >"$tool.log" 2>&1 || { cat "$tool.log" >&2; exit 1; }
  local wall rss
  wall=$(seconds "$(field 'Elapsed (wall clock) time (h:mm:ss or m:ss)')")
  rss=$(field 'Maximum resident set size (kbytes)')
  printf '%s\t%s\t%s\t%s\t%s\n' "$tool" "$run" "$wall" "$rss" "$(du -scb $out | tail -1 | cut -f1)" >>"$RESULTS"
  log "$tool run $run: $wall s, $((rss / 1024)) MiB"
}
for run in $(seq 1 "$RUNS"); do
  timed vortex "$run" "$OUT/v$run.vtpk" bin/vortex-tiler split src16k.tif --pack "$OUT/v$run.vtpk" --tile-size 128 --border 4 --codec jpeg --quality 85 -q
  timed vips "$run" "$OUT/d${run}_files" vips dzsave src16k.tif "$OUT/d$run" --tile-size 120 --overlap 4 --suffix '.jpg[Q=85]'
done
TILES=$(find "$OUT/d${RUNS}_files" -type f | wc -l)
INFO=$(bin/vortex-tiler info "$OUT/v$RUNS.vtpk" | tail -4)
rm -rf "$OUT"
sync
touch .cleaned

median() { awk -F'\t' -v t="$1" -v c="$2" '$1 == t { print $c }' "$RESULTS" | sort -g |
  awk '{ v[NR] = $1 } END { if (NR % 2) print v[(NR + 1) / 2]; else print (v[NR / 2] + v[NR / 2 + 1]) / 2 }'; }
calc() { awk "BEGIN { printf \"$1\", $2 }"; }
VW=$(median vips 3) VR=$(median vips 4) OW=$(median vortex 3) OR=$(median vortex 4)
REPORT=$WORK/pack-report.md
{
  echo "Run $(date -u '+%Y-%m-%d %H:%M UTC'), $RUNS alternating runs; $(nproc) cores; $(vips --version); vortex-tiler at $REV."
  echo
  echo "| tool | output | median wall s | Mpx/s | peak RSS MiB | output MiB | throughput vs vips | memory vs vips |"
  echo "|---|---|---:|---:|---:|---:|---:|---:|"
  echo "| vortex-tiler split --pack | 1 file | $(calc %.2f "$OW") | $(calc %.1f "268.4355 / $OW") | $(calc %.0f "$OR / 1024") | $(calc %.1f "$(median vortex 5) / 1048576") | $(calc %.2fx "$VW / $OW") | $(calc %.2fx "$OR / $VR") |"
  echo "| vips dzsave | $TILES files | $(calc %.2f "$VW") | $(calc %.1f "268.4355 / $VW") | $(calc %.0f "$VR / 1024") | $(calc %.1f "$(median vips 5) / 1048576") | 1.00x | 1.00x |"
  echo
  echo "The pack holds the square power-of-two grid (256 x 256 pages at LOD 0, of which the image covers 137 x 137); padding pages are stored once or as one colour:"
  echo
  echo '```'
  echo "$INFO"
  echo '```'
  echo
  echo "<details><summary>Raw runs (tool, run, wall s, peak RSS KiB, output bytes)</summary>"
  echo
  sed 's/^/    /' "$RESULTS"
  echo
  echo "</details>"
} >"$REPORT"
BEGIN='<!-- pack-vs-vips:begin -->'
END='<!-- pack-vs-vips:end -->'
grep -qF "$BEGIN" "$DOC" || printf '\n## split --pack against vips dzsave at 128-texel pages\n\nReproduce with `bench/pack-vs-vips.sh`.\n\n%s\n%s\n' "$BEGIN" "$END" >>"$DOC"
awk -v b="$BEGIN" -v e="$END" -v rep="$REPORT" '
  $0 == b { print; print ""; while ((getline l < rep) > 0) print l; print ""; skip = 1; next }
  $0 == e { skip = 0 }
  !skip { print }' "$DOC" >"$DOC.tmp"
mv "$DOC.tmp" "$DOC"
cat "$REPORT"
