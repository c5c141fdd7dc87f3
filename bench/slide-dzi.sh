#!/usr/bin/env bash
# bench/slide-dzi.sh: a whole-slide-like JPEG-tiled TIFF into Deep Zoom, copying the stored
# tiles (issue 30) against the tools pathology users run today, writing the same tiles.
#
# The input: SIZE (default 50000x40000) texels made with vips from a generated image (Perlin
# noise in three bands, tissue-like blotches on a near-white background, a little grain), saved
# as a scanner saves a slide: `vips tiffsave --tile --tile-width 256 --tile-height 256
# --pyramid --compression jpeg --Q 90` (JPEG tiles with shared tables, RGB as libvips writes
# them from Q90 on, reduced levels OpenSlide uses); and the same image (its decoded texels) as an LZW tiled TIFF.
# Then, alternately RUNS times, each under /usr/bin/time -v (wall, user+system CPU, peak RSS):
#   vortex        vortex-tiler split slide.tif --layout dzi --tile-size 256 --overlap 0 -q
#                 (the finest level's whole tiles copied, the rest encoded at --quality default)
#   vortex-reenc  the same with --reencode (every tile decoded and encoded)
#   vortex-lzw    the same from the LZW TIFF (no JPEG to copy or to decode)
#   vips          vips dzsave slide.tif OUT --tile-size 256 --overlap 0 --suffix .jpeg[Q=85] (Debian 8.14)
#   pyvips        libvips 8.18 (PyPI) dzsave(tile_size=256, overlap=0, Q=85), sequential, direct mode
#   openslide     OpenSlide's DeepZoomGenerator(tile_size=256, overlap=0, limit_bounds=False),
#                 its tiles saved by PIL at quality 85 by nproc processes, as OpenSlide's
#                 examples/deepzoom/deepzoom_tile.py does (Debian's python3-openslide).
#                 It is some 40x slower than the others, so it runs OPENSLIDE_RUNS times
#                 (default 1) on a slide of OPENSLIDE_SIZE (default half of SIZE each way: a
#                 quarter of the texels), made the same way; its row says so, and the Mpx/s
#                 column compares it with the others per texel.
# Medians over the runs, the tile files each wrote, tiles copied (of them cropped at the edge)
# vs encoded (from --json), and a check of the copies on the first run: the whole finest tiles
# among the first 64 are the stored streams, and the cropped edge tiles (a sample of the right
# column and bottom row) decode, with libvips 8.18, to exactly the stored tiles' texels there.
#
# Usage, from the repository root:  bench/slide-dzi.sh   (RUNS=3, SIZE=50000x40000; TOOLS to
# pick some, e.g. TOOLS="vortex vortex-reenc pyvips"). VORTEX_PYVIPS=PYTHON names a Python with
# pyvips (the CI venv), else bench/lib.sh installs one. Needs a release build
# (`cargo build --release -p vortex-tiler`) and about 12 GB of disk in bench/work. Measured on
# 2 quiet cores (2026-11-27): 9 minutes once the 50000x40000 slide exists (1.5 of them making
# the LZW copy and the quarter-size slide), 3 runs of the five tools, one of OpenSlide.
set -euo pipefail

cd "$(dirname "$0")/.."
source bench/lib.sh
RUNS=${RUNS:-3}
SIZE=${SIZE:-50000x40000}
W=${SIZE%x*}
H=${SIZE#*x}
TOOLS=(${TOOLS:-vortex vortex-reenc vortex-lzw vips pyvips openslide})
OPENSLIDE_RUNS=${OPENSLIDE_RUNS:-1}
OPENSLIDE_SIZE=${OPENSLIDE_SIZE:-$((W / 2))x$((H / 2))}

snapshot_release # VT, REV
pyvips_setup
export VIPS_WARNING=0

cd "$WORK"
SLIDE=slide-$SIZE.tif
LZW=slide-$SIZE-lzw.tif
make_slide "$W" "$H" "$SLIDE"
OS_W=${OPENSLIDE_SIZE%x*}
OS_H=${OPENSLIDE_SIZE#*x}
OS_SLIDE=slide-$OPENSLIDE_SIZE.tif
[[ " ${TOOLS[*]} " == *" openslide "* ]] && make_slide "$OS_W" "$OS_H" "$OS_SLIDE"
if [ ! -s "$LZW" ] && [[ " ${TOOLS[*]} " == *" vortex-lzw "* ]]; then
  log "making $LZW (the slide's decoded texels, lossless)"
  vips tiffsave "$SLIDE" "$LZW" --tile --tile-width 256 --tile-height 256 --compression lzw --bigtiff
fi

OUT=$WORK/out-slide
RESULTS=$WORK/slide-runs.tsv # tool run wall_s rss_kib cpu_s tiles copied encoded cropped
: >"$RESULTS"
tiles() { find "$1" -type f -name '*.jpeg' | wc -l; }
cpu() { awk -F': ' '/User time|System time/ { s += $2 } END { printf "%.1f", s }' "$WORK/time.txt"; }

# deepzoom_tile.py's way: one DeepZoomGenerator per worker process, tiles handed out by level.
OPENSLIDE_PY=$(cat <<'PY'
import os, sys, multiprocessing, openslide, openslide.deepzoom
src, out = sys.argv[1], sys.argv[2]
def init():
    global dz
    dz = openslide.deepzoom.DeepZoomGenerator(openslide.OpenSlide(src), tile_size=256, overlap=0, limit_bounds=False)
def work(job):
    level, col, row = job
    dz.get_tile(level, (col, row)).save("%s/%d/%d_%d.jpeg" % (out, level, col, row), quality=85)
if __name__ == "__main__":
    init()
    jobs = []
    for level, (cols, rows) in enumerate(dz.level_tiles):
        os.makedirs("%s/%d" % (out, level))
        jobs += [(level, c, r) for r in range(rows) for c in range(cols)]
    with multiprocessing.Pool(os.cpu_count(), init) as pool:
        for _ in pool.imap_unordered(work, jobs, chunksize=64):
            pass
PY
)

run_tool() {
  local tool=$1 run=$2 dest=$OUT/$1 result copied=- encoded=- cropped=-
  rm -rf "$OUT" && mkdir -p "$dest"
  case $tool in
    vortex) result=$(measure "$WORK/$tool.log" "$VT" split "$SLIDE" --layout dzi -o "$dest/slide" --name slide --tile-size 256 --overlap 0 --json) ;;
    vortex-reenc) result=$(measure "$WORK/$tool.log" "$VT" split "$SLIDE" --layout dzi -o "$dest/slide" --name slide --tile-size 256 --overlap 0 --reencode --json) ;;
    vortex-lzw) result=$(measure "$WORK/$tool.log" "$VT" split "$LZW" --layout dzi -o "$dest/slide" --name slide --tile-size 256 --overlap 0 --json) ;;
    vips) result=$(measure "$WORK/$tool.log" vips dzsave "$SLIDE" "$dest/slide" --tile-size 256 --overlap 0 --suffix '.jpeg[Q=85]') ;;
    pyvips) result=$(measure "$WORK/$tool.log" "$PY" -c "import pyvips; pyvips.Image.new_from_file('$SLIDE', access='sequential').dzsave('$dest/slide', tile_size=256, overlap=0, Q=85)") ;;
    openslide) result=$(measure "$WORK/$tool.log" /usr/bin/python3 -c "$OPENSLIDE_PY" "$OS_SLIDE" "$dest/slide_files") ;;
  esac
  if [[ $tool == vortex* ]]; then
    copied=$(grep -o '"copied":[0-9]*' "$WORK/$tool.log" | head -1 | cut -d: -f2)
    encoded=$(grep -o '"encoded":[0-9]*' "$WORK/$tool.log" | head -1 | cut -d: -f2)
    cropped=$(grep -o '"cropped":[0-9]*' "$WORK/$tool.log" | head -1 | cut -d: -f2)
  fi
  [ "$tool" = vortex ] && [ "$run" = 1 ] && check_copies "$dest/slide/slide_files" "$cropped"
  printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$tool" "$run" "${result% *}" "${result#* }" "$(cpu)" "$(tiles "$dest")" "$copied" "$encoded" "$cropped" >>"$RESULTS"
  log "$tool run $run: ${result% *} s, $(cpu) s CPU, $((${result#* } / 1024)) MiB peak, copied $copied ($cropped cropped), encoded $encoded"
}

# The whole tiles among the first 64 finest tiles are the slide's stored tiles with its tables
# spliced in (and a colour marker where they have none); where the run cropped edge tiles ($2 of
# them), a sample of the right column and bottom row decode to the stored tiles' texels there,
# exactly (libvips 8.18 decodes both, through libjpeg-turbo: what tests/it/copy_tiles.rs checks
# in full on small files).
check_copies() {
  "$PY" - "$SLIDE" "$1" "$2" <<'PY' || { echo "error: a copied tile is not the stored one" >&2; exit 1; }
import sys, os, tifffile, pyvips
slide, files, cropped = sys.argv[1], sys.argv[2], int(sys.argv[3])
finest = max(int(d) for d in os.listdir(files))
ours = lambda col, row: "%s/%d/%d_%d.jpeg" % (files, finest, col, row)
with tifffile.TiffFile(slide) as t:
    page = t.pages[0]
    tables = page.jpegtables
    fh = t.filehandle
    width, height, side = page.imagewidth, page.imagelength, page.tilewidth
    cols, rows = -(-width // side), -(-height // side)
    whole = (width // side, height // side)
    for i, (offset, count) in enumerate(zip(page.dataoffsets[:64], page.databytecounts[:64])):
        if i % cols >= whole[0] or i // cols >= whole[1]:
            continue
        fh.seek(offset)
        tile = fh.read(count)
        stream = tile[:2] + tables[2:-2] + tile[2:]
        mine = open(ours(i % cols, i // cols), "rb").read()
        # The stored stream, or with a JFIF APP0 (YCbCr) or Adobe APP14 (RGB) added after SOI
        # where it has none (the libtiff in pyvips-binary writes an Adobe marker into RGB tiles).
        added = 2 + int.from_bytes(mine[4:6], "big")
        assert mine == stream or mine[:2] + mine[2 + added:] == stream, "tile %d" % i
right, bottom = width % side != 0, height % side != 0
edges = [(cols - 1, r) for r in range(rows) if right] + [(c, rows - 1) for c in range(cols - right) if bottom]
if cropped:
    assert cropped == len(edges), "%d edge tiles cropped, %d expected" % (cropped, len(edges))
    source = pyvips.Image.new_from_file(slide)
    for col, row in edges[:: max(1, len(edges) // 32)] + [edges[-1]]:
        x, y = col * side, row * side
        w, h = min(side, width - x), min(side, height - y)
        copy = pyvips.Image.new_from_file(ours(col, row))
        assert (copy.width, copy.height) == (w, h), "edge tile %d,%d is %dx%d" % (col, row, copy.width, copy.height)
        assert copy.write_to_memory() == source.crop(x, y, w, h).write_to_memory(), "edge tile %d,%d" % (col, row)
PY
}

for run in $(seq 1 "$RUNS"); do
  for tool in "${TOOLS[@]}"; do
    [ "$tool" = openslide ] && [ "$run" -gt "$OPENSLIDE_RUNS" ] && continue
    run_tool "$tool" "$run"
  done
done
rm -rf "$OUT"

REPORT=$WORK/slide-report.md
{
  echo "Measured $(date -u +%Y-%m-%d) with \`bench/slide-dzi.sh\` (vortex-tiler $REV, RUNS=$RUNS, medians; $(nproc) cores${LOADED:+, $LOADED}):"
  echo "a ${W} x ${H} slide-like TIFF ($(du -m "$SLIDE" | cut -f1) MiB: 256-texel JPEG tiles, Q90, RGB, pyramidal, made by libvips) into Deep Zoom tiles of 256 texels, overlap 0."
  echo
  echo "| tool | wall | CPU (user+sys) | peak RSS | source Mpx/s | tile files | copied (cropped) / encoded | pyvips 8.18 wall / tool |"
  echo "|---|---:|---:|---:|---:|---:|---:|---:|"
  ref=
  grep -q '^pyvips' "$RESULTS" && ref=$(median "$RESULTS" pyvips 3)
  for tool in "${TOOLS[@]}"; do
    wall=$(median "$RESULTS" "$tool" 3)
    rss=$(median "$RESULTS" "$tool" 4)
    cpu_s=$(median "$RESULTS" "$tool" 5)
    files=$(awk -F'\t' -v t="$tool" '$1 == t { print $6; exit }' "$RESULTS")
    counts=$(awk -F'\t' -v t="$tool" '$1 == t { print $7 " (" $9 ") / " $8; exit }' "$RESULTS")
    mpx=$((W * H))
    case $tool in
      vortex) label="vortex-tiler (stored tiles copied)" ;;
      vortex-reenc) label="vortex-tiler \`--reencode\`" ;;
      vortex-lzw) label="vortex-tiler, the LZW TIFF ($(du -m "$LZW" | cut -f1) MiB)" ;;
      vips) label="vips dzsave $(vips --version) \`--suffix .jpeg[Q=85]\`" ;;
      pyvips) label="pyvips dzsave $PYVIPS_VERSION (\`Q=85\`, direct)" ;;
      openslide)
        label="OpenSlide $(/usr/bin/python3 -c 'import openslide; print(openslide.__library_version__)') DeepZoomGenerator, $(nproc) processes, **on a ${OS_W} x ${OS_H} slide** ($OPENSLIDE_RUNS run$([ "$OPENSLIDE_RUNS" = 1 ] || echo s))"
        mpx=$((OS_W * OS_H)) ;;
    esac
    ratio=-
    # Only for tools that ran on the same slide as pyvips.
    [ -n "$ref" ] && [ "$mpx" = $((W * H)) ] && ratio="$(calc '%.2f' "$ref / $wall")x"
    [ "$counts" = "- (-) / -" ] && counts=-
    echo "| $label | $(calc '%.1f' "$wall") s | $(calc '%.1f' "$cpu_s") s | $(calc '%.0f' "$rss / 1024") MiB | $(calc '%.1f' "$mpx / $wall / 1000000") | $files | $counts | $ratio |"
  done
} >"$REPORT"
splice slide-dzi "$REPORT" "## A slide into Deep Zoom: stored JPEG tiles copied (issue 30)"
cat "$REPORT"
