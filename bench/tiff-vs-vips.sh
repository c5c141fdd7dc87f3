#!/usr/bin/env bash
# bench/tiff-vs-vips.sh: pyramidal TIFF out (issue 43) against libvips 8.18's
# `tiffsave --tile --pyramid`, the command these users run after dzsave.
#
# What it measures (results go to docs/benchmarks.md between the tiff-vs-vips markers),
# alternately RUNS times (default 5), each under /usr/bin/time -v (wall, user+system CPU, peak
# RSS), all with 256-texel JPEG Q85 tiles:
#   strip     the 16384 x 16384 RGB strip BigTIFF of bench/lib.sh into
#     generic     vortex-tiler split src16k.tif -o OUT.tif --json
#                 (every level a page of its own; the default filter; the default quality,
#                 85: an explicit --quality asks for re-encoding, so a slide's tiles would
#                 not be copied)
#     ome         vortex-tiler split src16k.tif -o OUT.ome.tif --json
#                 (reduced levels as SubIFDs; the box filter, OME-TIFF's default)
#     vips        pyvips: tiffsave(tile=True, pyramid=True, compression="jpeg", Q=85,
#                 tile_width=256, tile_height=256, bigtiff=True), sequential access
#     vips-subifd the same with subifd=True (its OME-style pyramid)
#   slide     the JPEG-tiled slide of bench/slide-dzi.sh (SLIDE_SIZE, default 50000x40000,
#             256-texel JPEG Q90 tiles, RGB-coded, a pyramid of its own) into the generic
#             flavour: ours with the slide's own levels, every tile copied (the default,
#             --levels stored), and with our pyramid (--levels pow2: the full resolution's
#             tiles copied, the rest decoded and made), libvips decoding and encoding every
#             tile. Tiles copied from --json.
# Medians over the runs; the report gives our wall against libvips' (goals: at least 2x on the
# strip image, 4x on the slide, at no more than its peak memory).
#
# Usage, from the repository root:  bench/tiff-vs-vips.sh   (RUNS=5, SLIDE_SIZE=50000x40000,
# PARTS="strip slide"). Needs a release build (bench/lib.sh makes it) and libvips 8.18 from PyPI
# (VORTEX_PYVIPS=PYTHON, or a venv bench/lib.sh installs).
set -euo pipefail

cd "$(dirname "$0")/.."
source bench/lib.sh
RUNS=${RUNS:-5}
SLIDE_SIZE=${SLIDE_SIZE:-50000x40000}
PARTS=(${PARTS:-strip slide})
splice_check tiff-vs-vips

bench_setup # vips, time, bin/vortex-tiler, src16k.tif, REV
pyvips_setup
[ -n "$PYVIPS_VERSION" ] || { echo "error: libvips 8.18 (pyvips) is the peer of this benchmark" >&2; exit 1; }

cd "$WORK"
SLIDE=slide-$SLIDE_SIZE.tif
[[ " ${PARTS[*]} " == *" slide "* ]] && make_slide "${SLIDE_SIZE%x*}" "${SLIDE_SIZE#*x}" "$SLIDE"
OUT=$WORK/out-tiff
RESULTS=$WORK/tiff-runs.tsv # part tool run wall_s rss_kib cpu_s copied
: >"$RESULTS"
VT=$WORK/bin/vortex-tiler
TIFFSAVE='import sys, pyvips
im = pyvips.Image.new_from_file(sys.argv[1], access="sequential")
im.tiffsave(sys.argv[2], tile=True, pyramid=True, compression="jpeg", Q=85, tile_width=256,
            tile_height=256, bigtiff=True, subifd=sys.argv[3] == "1")'

cpu() { awk -F': ' '/User time|System time/ { s += $2 } END { printf "%.2f", s }' "$WORK/time.txt"; }

run_tool() {
  local part=$1 tool=$2 run=$3 src result copied=-
  src=$([ "$part" = strip ] && echo src16k.tif || echo "$SLIDE")
  rm -rf "$OUT" && mkdir -p "$OUT"
  case $tool in
    generic) result=$(measure "$WORK/$tool.log" "$VT" split "$src" -o "$OUT/x.tif" --json) ;;
    ome) result=$(measure "$WORK/$tool.log" "$VT" split "$src" -o "$OUT/x.ome.tif" --json) ;;
    pow2) result=$(measure "$WORK/$tool.log" "$VT" split "$src" -o "$OUT/x.tif" --levels pow2 --json) ;;
    vips) result=$(measure "$WORK/$tool.log" "$PY" -c "$TIFFSAVE" "$src" "$OUT/x.tif" 0) ;;
    vips-subifd) result=$(measure "$WORK/$tool.log" "$PY" -c "$TIFFSAVE" "$src" "$OUT/x.tif" 1) ;;
  esac
  case $tool in
    generic | ome | pow2) copied=$(grep -o '"copied":[0-9]*' "$WORK/$tool.log" | head -1 | cut -d: -f2) ;;
  esac
  printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$part" "$tool" "$run" "${result% *}" "${result#* }" "$(cpu)" "${copied:--}" >>"$RESULTS"
  log "$part $tool run $run: ${result% *} s, $((${result#* } / 1024)) MiB peak, $(cpu) s CPU, copied ${copied:--}"
}

tools_of() { [ "$1" = strip ] && echo "generic ome vips vips-subifd" || echo "generic pow2 vips"; }
for part in "${PARTS[@]}"; do
  cat "$([ "$part" = strip ] && echo src16k.tif || echo "$SLIDE")" >/dev/null # warm the page cache
  for run in $(seq 1 "$RUNS"); do
    for tool in $(tools_of "$part"); do run_tool "$part" "$tool" "$run"; done
  done
done
rm -rf "$OUT"

# med PART TOOL COLUMN: the median of COLUMN (4 wall, 5 RSS, 6 CPU) over PART's runs of TOOL.
med() { awk -F'\t' -v p="$1" -v t="$2" -v c="$3" '$1 == p && $2 == t { print $c }' "$RESULTS" | sort -n |
  awk '{ v[NR] = $1 } END { print (NR % 2) ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2 }'; }
REPORT=$WORK/tiff-report.md
{
  echo "Measured $(date -u +%Y-%m-%d) with \`bench/tiff-vs-vips.sh\` (vortex-tiler $REV, $PYVIPS_VERSION, RUNS=$RUNS,"
  echo "medians; $(nproc) cores): 256-texel JPEG Q85 tiles, BigTIFF."
  echo
  echo "| input | tool | wall | CPU (user + system) | peak RSS | tiles copied |"
  echo "|---|---|---:|---:|---:|---:|"
  for part in "${PARTS[@]}"; do
    label=$([ "$part" = strip ] && echo "16384² strip BigTIFF" || echo "slide $SLIDE_SIZE (JPEG tiles)")
    for tool in $(tools_of "$part"); do
      case $tool in
        generic) name="vortex-tiler -o x.tif (generic)" ;;
        ome) name="vortex-tiler -o x.ome.tif (SubIFDs)" ;;
        pow2) name="vortex-tiler -o x.tif --levels pow2" ;;
        vips) name="libvips tiffsave --pyramid" ;;
        vips-subifd) name="libvips tiffsave --pyramid --subifd" ;;
      esac
      copied=$(awk -F'\t' -v p="$part" -v t="$tool" '$1 == p && $2 == t { print $7; exit }' "$RESULTS")
      echo "| $label | $name | $(calc '%.2f' "$(med "$part" "$tool" 4)") s | $(calc '%.2f' "$(med "$part" "$tool" 6)") s | $(calc '%.0f' "$(med "$part" "$tool" 5) / 1024") MiB | $copied |"
    done
  done
  echo
  for part in "${PARTS[@]}"; do
    g=$(med "$part" generic 4)
    v=$(med "$part" vips 4)
    goal=$([ "$part" = strip ] && echo 2 || echo 4)
    echo "- $part, generic flavour: $(calc '%.2f' "$v / $g")x libvips' wall (goal: at least ${goal}x), peak memory $(calc '%.2f' "$(med "$part" generic 5) / $(med "$part" vips 5)")x its."
    if [ "$part" = slide ]; then
      echo "- slide, --levels pow2 (our pyramid, level 0 copied): $(calc '%.2f' "$v / $(med slide pow2 4)")x libvips' wall."
    fi
    if [ "$part" = strip ]; then
      echo "- strip, OME flavour: $(calc '%.2f' "$(med strip vips-subifd 4) / $(med strip ome 4)")x libvips' \`--subifd\` wall, peak memory $(calc '%.2f' "$(med strip ome 5) / $(med strip vips-subifd 5)")x its."
    fi
  done
} >"$REPORT"
splice tiff-vs-vips "$REPORT" "## Pyramidal TIFF out against libvips (bench/tiff-vs-vips.sh, issue 43)"
cat "$REPORT"
