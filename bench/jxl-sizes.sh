#!/usr/bin/env bash
# JPEG XL tiles against JPEG (issue 46): bytes, time and PSNR of the 16384² image's Deep Zoom
# pyramid (256-texel tiles, no overlap) as JPEG Q85 and as JPEG XL at several qualities and
# efforts, and the lossless recompression of a slide's stored JPEG tiles. What accuracy and
# size cost in time: each row says the bytes of all tiles, the PSNR of the full-resolution
# level against the source (bench's psnr), the wall and CPU seconds and the peak memory.
#
# The slide is bench/lib.sh's make_slide (libvips 8.18, RGB JPEG at Q=90 in 256-texel tiles):
# its stored tiles are copied by the JPEG run and recompressed by the JXL run, whose summary
# (`--json` storedTiles.recompressed) says the bytes saved.
#
# Usage, from the repository root:  bench/jxl-sizes.sh
#   QUALITIES (JXL --quality values, default "90 85 80 75"), EFFORTS (default "1 3 5 7", at
#   quality 85), SIZE (the slide, default 46000x32914), VORTEX_PYVIPS (a Python with pyvips,
#   to make the slide; else bench/lib.sh installs one, and without one the slide rows are left
#   out), PARTS (default "image slide": which tables to measure). Run it on a quiet machine.
set -euo pipefail
source bench/lib.sh
bench_setup
VT=$WORK/bin/vortex-tiler
QUALITIES=${QUALITIES:-90 85 80 75}
EFFORTS=${EFFORTS:-1 3 5 7}
SRC=$WORK/src16k.tif
OUT=$WORK/jxl-sizes
PARTS=${PARTS:-image slide}
mkdir -p "$OUT"

# row LABEL ARGS...: one Deep Zoom run of $SRC; prints a table row.
row() {
  local label=$1
  shift
  local dir=$OUT/dzi
  rm -rf "$dir"
  local m
  m=$(measure "$OUT/run.log" "$VT" split "$SRC" -o "$dir" --layout dzi --overlap 0 --tile-size 256 -q "$@")
  local cpu
  cpu=$(awk -F': ' '/User time/ { u = $2 } /System time/ { s = $2 } END { printf "%.1f", u + s }' "$WORK/time.txt")
  local bytes
  bytes=$(find "$dir" -type f \( -name '*.jpeg' -o -name '*.jxl' \) -printf '%s\n' | awk '{ s += $1 } END { print s }')
  local psnr
  psnr=$("$WORK/bin/psnr" "$SRC" --dzi "$dir/src16k_files")
  read -r wall rss <<<"$m"
  printf '| %s | %s | %s | %s | %s | %s |\n' "$label" "$bytes" "$psnr" "$wall" "$cpu" "$((rss / 1024))"
  rm -rf "$dir"
}

[[ " $PARTS " == *" image "* ]] && {
  echo "| tiles | bytes | PSNR (dB) | wall (s) | CPU (s) | peak (MiB) |"
  echo "|---|---:|---:|---:|---:|---:|"
  log "JPEG Q85"
  row "JPEG Q85 4:2:0" --codec jpeg --quality 85
  for q in $QUALITIES; do
    log "JXL quality $q"
    row "JXL quality $q, effort 5" --codec jxl --quality "$q"
  done
  for e in $EFFORTS; do
    [ "$e" = 5 ] && continue
    log "JXL effort $e"
    row "JXL quality 85, effort $e" --codec jxl --quality 85 --jxl-effort "$e"
  done
} | tee "$OUT/image.md"

[[ " $PARTS " == *" slide "* ]] || exit 0
pyvips_setup # PY: a Python with pyvips, to make the slide
if [ -z "$PY" ]; then
  log "no pyvips: the slide rows are left out"
  exit 0
fi
SIZE=${SIZE:-46000x32914}
W=${SIZE%x*}
H=${SIZE#*x}
SLIDE=$WORK/slide-$SIZE.tif
make_slide "$W" "$H" "$SLIDE"
{
  echo
  echo "| slide $SIZE to Deep Zoom | wall (s) | peak (MiB) | stored tiles | their JPEG bytes | as JPEG XL | saved |"
  echo "|---|---:|---:|---:|---:|---:|---:|"
  for codec in jpeg jxl; do
    log "slide, $codec"
    rm -rf "$OUT/slide"
    m=$(measure "$OUT/slide.json" "$VT" split "$SLIDE" -o "$OUT/slide" --layout dzi --overlap 0 --tile-size 256 --codec "$codec" --json)
    read -r wall rss <<<"$m"
    python3 - "$OUT/slide.json" "$codec" "$wall" "$((rss / 1024))" <<'EOF'
import json, sys
path, codec, wall, rss = sys.argv[1:5]
text = open(path).read()  # the run's output: its --json report, after any libjxl traces
report = json.JSONDecoder().raw_decode(text[text.index("{"):])[0]
stored = report.get("storedTiles", {})
r = stored.get("recompressed", {})
if codec == "jxl":
    saved = 1 - r["jxlBytes"] / r["jpegBytes"] if r.get("jpegBytes") else 0
    print(f"| JPEG XL (copied tiles recompressed, {r.get('refused', 0)} refused) | {wall} | {rss} | {r.get('tiles', 0)} | {r.get('jpegBytes', 0)} | {r.get('jxlBytes', 0)} | {saved:.1%} |")
else:
    print(f"| JPEG (copied tiles as stored) | {wall} | {rss} | {stored.get('copied', 0)} | | | |")
EOF
  done
  rm -rf "$OUT/slide"
} | tee "$OUT/slide.md"
