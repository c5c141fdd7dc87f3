#!/usr/bin/env bash
# bench/slide-dicom.sh: a whole-slide-like JPEG-tiled TIFF into a DICOM WSI series (issue 44),
# against wsidicomizer (PyPI), the converter of the DICOM pathology world.
#
# The input: SIZE (default 46000x32914, CMU-1's size) texels made as bench/slide-dzi.sh makes
# its slide (bench/lib.sh's make_slide: `vips tiffsave --tile --pyramid --compression jpeg
# --Q 90`, 256-texel JPEG tiles with shared tables, RGB, reduced levels). Then, alternately
# RUNS times, each under /usr/bin/time -v (wall, user+system CPU, peak RSS):
#   vortex        vortex-tiler split slide.tif --layout dicom -o OUT --pixel-size 0.25um
#                 (--levels stored, the default: every level of the slide an instance, every
#                 stored tile copied as a frame, nothing decoded)
#   vortex-pow2   the same with --levels pow2 (our power-of-two pyramid: the full resolution's
#                 whole tiles copied, the rest encoded)
#   vortex-dzi    DICOM (levels copied) and Deep Zoom (-o OUT2 --layout dzi) in one run
#   wsidicomizer  wsidicomizer -i slide.tif -o OUT (PyPI, in its own venv: it pins an older
#                 wsidicom than the tests' venv), its own defaults
# Medians over the runs, the instances and frames each wrote. On the first run of `vortex`, a
# check: its frames are the slide's stored tiles (the frame count equals the stored tiles', none
# encoded, and a sample of frames carries the stored tiles' entropy-coded data).
#
# Usage, from the repository root:  bench/slide-dicom.sh  (RUNS=3, SIZE=46000x32914; TOOLS to
# pick some). VORTEX_PYVIPS=PYTHON names a Python with pyvips and pydicom (the CI venv), else
# bench/lib.sh installs pyvips. WSIDICOMIZER=PATH names a wsidicomizer executable, else it is
# installed into $WORK/wsidicomizer-venv. Needs a release build (`cargo build --release -p
# vortex-tiler`; CARGO_TARGET_DIR is honoured) and about 3 GB of disk in bench/work. NO_SPLICE=1
# leaves docs/benchmarks.md alone (the report stays in bench/work/dicom-report.md).
set -euo pipefail

cd "$(dirname "$0")/.."
source bench/lib.sh
RUNS=${RUNS:-3}
SIZE=${SIZE:-46000x32914}
W=${SIZE%x*}
H=${SIZE#*x}
TOOLS=(${TOOLS:-vortex vortex-pow2 vortex-dzi wsidicomizer})

snapshot_release # VT, REV
pyvips_setup
export VIPS_WARNING=0
WZ=${WSIDICOMIZER:-$WORK/wsidicomizer-venv/bin/wsidicomizer}
if [[ " ${TOOLS[*]} " == *" wsidicomizer "* ]] && [ ! -x "$WZ" ]; then
  log "installing wsidicomizer into $WORK/wsidicomizer-venv"
  python3 -m venv "$WORK/wsidicomizer-venv" && "$WORK/wsidicomizer-venv/bin/pip" install -q wsidicomizer
fi

cd "$WORK"
SLIDE=slide-$SIZE.tif
make_slide "$W" "$H" "$SLIDE"

OUT=$WORK/out-dicom
RESULTS=$WORK/dicom-runs.tsv # tool run wall_s rss_kib cpu_s instances frames
: >"$RESULTS"
cpu() { awk -F': ' '/User time|System time/ { s += $2 } END { printf "%.1f", s }' "$WORK/time.txt"; }
# Instances and frames of the series in $1, by pydicom.
count() {
  "$PY" - "$1" <<'PY'
import glob, sys, pydicom
paths = glob.glob(sys.argv[1] + "/**/*.dcm", recursive=True)
frames = sum(int(pydicom.dcmread(p, stop_before_pixels=True).get("NumberOfFrames", 1)) for p in paths)
print(len(paths), frames)
PY
}

run_tool() {
  local tool=$1 run=$2 dest=$OUT/$1 result
  rm -rf "$OUT" && mkdir -p "$OUT"
  case $tool in
    vortex) result=$(measure "$WORK/$tool.log" "$VT" split "$SLIDE" --layout dicom -o "$dest" --pixel-size 0.25um --json) ;;
    vortex-pow2) result=$(measure "$WORK/$tool.log" "$VT" split "$SLIDE" --layout dicom -o "$dest" --pixel-size 0.25um --levels pow2 --json) ;;
    vortex-dzi) result=$(measure "$WORK/$tool.log" "$VT" split "$SLIDE" --layout dicom -o "$dest" -o "$OUT/web" --layout dzi --tile-size 256 --overlap 0 --pixel-size 0.25um --json) ;;
    wsidicomizer) result=$(measure "$WORK/$tool.log" "$WZ" -i "$SLIDE" -o "$dest") ;;
  esac
  [ "$tool" = vortex ] && [ "$run" = 1 ] && check_copies "$dest"
  local counted
  counted=$(count "$dest")
  printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$tool" "$run" "${result% *}" "${result#* }" "$(cpu)" "${counted% *}" "${counted#* }" >>"$RESULTS"
  log "$tool run $run: ${result% *} s, $(cpu) s CPU, $((${result#* } / 1024)) MiB peak, ${counted% *} instances, ${counted#* } frames"
}

# The series of the slide's own levels: one instance a level, as many frames as stored tiles,
# none encoded, and every 97th frame of each level the stored tile's entropy-coded data.
check_copies() {
  grep -q '"encoded":0' "$WORK/vortex.log" || { echo "error: frames encoded" >&2; exit 1; }
  "$PY" - "$SLIDE" "$1" <<'PY' || { echo "error: a frame is not the stored tile" >&2; exit 1; }
import sys, pydicom, tifffile
slide, series = sys.argv[1], sys.argv[2]
scan = lambda j: j[j.find(b"\xff\xda"): j.rfind(b"\xff\xd9") + 2]
with tifffile.TiffFile(slide) as t:
    pages = [p for p in t.pages if p.is_tiled]
    for k, page in enumerate(pages):
        ds = pydicom.dcmread("%s/level-%d.dcm" % (series, k))
        assert (ds.TotalPixelMatrixColumns, ds.TotalPixelMatrixRows) == (page.imagewidth, page.imagelength), k
        assert int(ds.NumberOfFrames) == len(page.dataoffsets), k
        frames = list(pydicom.encaps.generate_frames(ds.PixelData, number_of_frames=ds.NumberOfFrames))
        for i in range(0, len(frames), 97):
            t.filehandle.seek(page.dataoffsets[i])
            assert scan(frames[i]) == scan(t.filehandle.read(page.databytecounts[i])), (k, i)
PY
}

for run in $(seq 1 "$RUNS"); do
  for tool in "${TOOLS[@]}"; do
    run_tool "$tool" "$run"
  done
done
rm -rf "$OUT"

REPORT=$WORK/dicom-report.md
{
  echo "Measured $(date -u +%Y-%m-%d) with \`bench/slide-dicom.sh\` (vortex-tiler $REV, RUNS=$RUNS, medians; $(nproc) cores${LOADED:+, $LOADED}):"
  echo "a ${W} x ${H} slide-like TIFF ($(du -m "$SLIDE" | cut -f1) MiB: 256-texel JPEG tiles, Q90, RGB, pyramidal, made by libvips) into a DICOM WSI series."
  echo
  echo "| tool | wall | CPU (user+sys) | peak RSS | instances | frames | wsidicomizer wall / tool |"
  echo "|---|---:|---:|---:|---:|---:|---:|"
  ref=
  grep -q '^wsidicomizer' "$RESULTS" && ref=$(median "$RESULTS" wsidicomizer 3)
  for tool in "${TOOLS[@]}"; do
    wall=$(median "$RESULTS" "$tool" 3)
    rss=$(median "$RESULTS" "$tool" 4)
    cpu_s=$(median "$RESULTS" "$tool" 5)
    counts=$(awk -F'\t' -v t="$tool" '$1 == t { print "| " $6 " | " $7; exit }' "$RESULTS")
    case $tool in
      vortex) label="vortex-tiler \`--layout dicom\` (the slide's levels copied)" ;;
      vortex-pow2) label="vortex-tiler \`--layout dicom --levels pow2\`" ;;
      vortex-dzi) label="vortex-tiler DICOM (levels copied) + Deep Zoom in one run" ;;
      wsidicomizer) label="wsidicomizer $("${WZ%/wsidicomizer}/python" -c 'import importlib.metadata as m; print(m.version("wsidicomizer"))' 2>/dev/null || echo '?')" ;;
    esac
    ratio=-
    [ -n "$ref" ] && ratio="$(calc '%.1f' "$ref / $wall")x"
    echo "| $label | $(calc '%.2f' "$wall") s | $(calc '%.1f' "$cpu_s") s | $(calc '%.0f' "$rss / 1024") MiB $counts | $ratio |"
  done
} >"$REPORT"
[ -n "${NO_SPLICE:-}" ] || splice slide-dicom "$REPORT" "## A slide into DICOM: the slide's own levels copied (issue 44)"
cat "$REPORT"
