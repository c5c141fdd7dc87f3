#!/usr/bin/env bash
# bench/split-vs-vips.sh: vortex-tiler split against libvips dzsave on the same image.
#
# What it measures (results go to docs/benchmarks.md between the split-vs-vips markers):
#   Case 1, 16384 x 16384 RGB 8-bit uncompressed BigTIFF (268.4 Mpx, ~805 MB, from
#   examples/gen_image: gradients, zone plate, discs, per-pixel noise), cut into 256-texel
#   JPEG tiles at quality 85 with no border/overlap, alternately RUNS times by
#     - vortex-tiler split SRC -o OUT --tile-size 256 --border 0 --codec jpeg --quality 85 --filter box --quiet
#       (levels averaged in stored values, as vips does), and the same with the default filter,
#       linear-premultiplied (averaged in linear light)
#     - vips dzsave SRC OUT --tile-size 256 --overlap 0 --suffix .jpg[Q=85]   (Debian libvips 8.14)
#     - pyvips dzsave(tile_size=256, overlap=0, Q=85), sequential access   (newest libvips from
#       PyPI, pyvips-binary, in a venv; skipped with a note if pip cannot install it)
#   each under /usr/bin/time -v: wall clock, peak RSS; medians over the runs. Output size is the
#   sum of the tile files' sizes (du -b, tiles only: no info.json, .dzi or vips-properties.xml).
#   PSNR of the finest level against the source over all RGB samples (examples/psnr.rs).
#   Case 2, "memory is flat in height": 16384 x 131072 (2147.5 Mpx, ~6.4 GB), vortex-tiler once;
#   skipped with a note if less than 20 GB are free.
#
# Usage, from the repository root:
#     bench/split-vs-vips.sh
# Environment: RUNS (default 5), KEEP=1 keeps the 6.4 GB image, BIG=0 skips case 2, PYVIPS=0
# skips the PyPI libvips peer. Installs libvips-tools and time with apt-get when missing (needs
# root or sudo). Works in bench/work/ (git-ignored); the source images stay there between runs
# (src16k.tif is reused, srcbig.tif is deleted unless KEEP=1).
#
# The page cache is warmed before timing, so this measures decode + pyramid + encode + write,
# not the disk read of the source. Runs alternate between tools, so background load (e.g. a
# compile) is spread over all of them rather than hitting one.
#
# Every run writes to a fresh directory under bench/work/out/, and nothing is deleted until all
# timed runs are done: on ext4 without a journal, creating files soon (60-300 s) after many
# were deleted makes the inode allocator skip every "recently deleted" inode, which turned
# 1.3 s runs into 5-9 s of kernel time. For the same reason the script waits until a minute has
# passed since its previous clean-up (bench/work/.cleaned) before timing anything.
set -euo pipefail

cd "$(dirname "$0")/.."
ROOT=$PWD
WORK=$ROOT/bench/work
DOC=$ROOT/docs/benchmarks.md
RUNS=${RUNS:-5}
KEEP=${KEEP:-0}
BIG=${BIG:-1}
PYVIPS=${PYVIPS:-1}
SIDE=16384
BIG_H=131072
mkdir -p "$WORK"

log() { printf '[%(%H:%M:%S)T] %s\n' -1 "$*" >&2; }
as_root() { if [ "$(id -u)" = 0 ]; then "$@"; else sudo "$@"; fi; }

# ---------------------------------------------------------------------------------------------
# 1. Peers and tools
need_apt=()
command -v vips >/dev/null || need_apt+=(libvips-tools)
[ -x /usr/bin/time ] || need_apt+=(time)
if [ ${#need_apt[@]} -gt 0 ]; then
  log "installing ${need_apt[*]}"
  as_root env DEBIAN_FRONTEND=noninteractive apt-get update -qq
  as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${need_apt[@]}" >/dev/null
fi
VIPS_VERSION=$(vips --version)

PY=$WORK/venv/bin/python
PYVIPS_VERSION=
if [ "$PYVIPS" = 1 ]; then
  if ! "$PY" -c 'import pyvips' 2>/dev/null; then
    log "installing pyvips + pyvips-binary into $WORK/venv"
    if ! { python3 -m venv "$WORK/venv" && "$WORK/venv/bin/pip" install -q pyvips pyvips-binary; } >"$WORK/pip.log" 2>&1; then
      echo "note: could not install pyvips/pyvips-binary (see $WORK/pip.log); skipping the PyPI libvips peer" >&2
    fi
  fi
  if "$PY" -c 'import pyvips' 2>/dev/null; then
    PYVIPS_VERSION=$("$PY" -c 'import pyvips; print("libvips-%d.%d.%d" % tuple(pyvips.version(i) for i in range(3)))')
  fi
fi

# ---------------------------------------------------------------------------------------------
# 2. Build and the source image
log "building"
cargo build --release --quiet
cargo build --release --quiet --example gen_image --example psnr
REV="$(git rev-parse --short HEAD 2>/dev/null || echo unknown)$(git diff --quiet HEAD -- src Cargo.toml Cargo.lock 2>/dev/null || echo +uncommitted)"
# Snapshot the binaries: a concurrent `cargo build` must not swap them between runs.
mkdir -p "$WORK/bin"
cp target/release/vortex-tiler target/release/examples/gen_image target/release/examples/psnr "$WORK/bin/"
TILER=$WORK/bin/vortex-tiler
GEN=$WORK/bin/gen_image
PSNR=$WORK/bin/psnr

cd "$WORK"
OUT=$WORK/out
if [ -e "$OUT" ]; then # left by an interrupted run
  log "removing stale $OUT"
  rm -rf "$OUT"
  sync
  touch .cleaned
fi
SRC=src16k.tif
if [ ! -s "$SRC" ]; then
  log "generating $SRC (${SIDE}x${SIDE})"
  "$GEN" $SIDE $SIDE part16k.tif # gen_image picks the format from the extension
  mv part16k.tif "$SRC"
fi

# ---------------------------------------------------------------------------------------------
# 3. Timed runs
RESULTS=$WORK/results.tsv # tool run wall_s rss_kib user_s sys_s tile_bytes load1
: >"$RESULTS"

# Seconds from /usr/bin/time's "h:mm:ss" or "m:ss.ss".
to_seconds() { awk -F: '{ s = 0; for (i = 1; i <= NF; i++) s = s * 60 + $i; printf "%.2f", s }' <<<"$1"; }
# Summed size of the tile files (JPEG) under the given paths.
tile_bytes() { find "$@" -type f \( -name '*.jpg' -o -name '*.jpeg' \) -print0 | du -cb --files0-from=- | tail -1 | cut -f1; }
field() { sed -n "s/^[[:space:]]*$1: //p" "$2"; }

# timed TOOL RUN OUTPUT... -- COMMAND...: runs COMMAND under /usr/bin/time -v, appends a line.
timed() {
  local tool=$1 run=$2
  shift 2
  local outs=()
  while [ "$1" != -- ]; do outs+=("$1"); shift; done
  shift
  rm -rf "${outs[@]}" # only an earlier attempt's: every run has its own directory
  sync # flush the previous run's tiles so that its writeback does not land in this run
  local load
  load=$(cut -d' ' -f1 /proc/loadavg)
  if ! /usr/bin/time -v -o "$WORK/time.txt" "$@" >"$WORK/$tool.log" 2>&1; then
    echo "error: $tool run $run failed:" >&2
    cat "$WORK/$tool.log" "$WORK/time.txt" >&2
    exit 1
  fi
  local wall rss user sys bytes
  wall=$(to_seconds "$(field 'Elapsed (wall clock) time (h:mm:ss or m:ss)' "$WORK/time.txt")")
  rss=$(field 'Maximum resident set size (kbytes)' "$WORK/time.txt")
  user=$(field 'User time (seconds)' "$WORK/time.txt")
  sys=$(field 'System time (seconds)' "$WORK/time.txt")
  bytes=$(tile_bytes "${outs[@]}")
  printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$tool" "$run" "$wall" "$rss" "$user" "$sys" "$bytes" "$load" >>"$RESULTS"
  log "$tool run $run: ${wall} s, $((rss / 1024)) MiB peak, load before $load"
}

PYSCRIPT='import sys, pyvips
src, out = sys.argv[1], sys.argv[2]
im = pyvips.Image.new_from_file(src, access="sequential")
im.dzsave(out, tile_size=256, overlap=0, Q=85)'

export VIPS_WARNING=0 # vips 8.14 warns about the TIFF Predictor tag (317) the tiff crate writes
mkdir -p "$OUT"
if [ -e .cleaned ]; then
  wait_s=$((65 - $(date +%s) + $(stat -c %Y .cleaned)))
  if [ "$wait_s" -gt 0 ]; then
    log "waiting ${wait_s} s for the previous clean-up's inodes to age (see the header)"
    sleep "$wait_s"
  fi
fi
cat "$SRC" >/dev/null # warm the page cache
TOOLS=(vortex vortex-default vips)
[ -n "$PYVIPS_VERSION" ] && TOOLS+=(pyvips)
for run in $(seq 1 "$RUNS"); do
  for tool in "${TOOLS[@]}"; do
    case $tool in
      vortex) timed vortex "$run" "$OUT/vortex-$run" -- "$TILER" split "$SRC" -o "$OUT/vortex-$run" --tile-size 256 --border 0 --codec jpeg --quality 85 --filter box --quiet ;;
      vortex-default) timed vortex-default "$run" "$OUT/vortex-default-$run" -- "$TILER" split "$SRC" -o "$OUT/vortex-default-$run" --tile-size 256 --border 0 --codec jpeg --quality 85 --quiet ;;
      vips) timed vips "$run" "$OUT/vips-${run}_files" "$OUT/vips-$run.dzi" -- vips dzsave "$SRC" "$OUT/vips-$run" --tile-size 256 --overlap 0 --suffix '.jpg[Q=85]' ;;
      pyvips) timed pyvips "$run" "$OUT/pyvips-${run}_files" "$OUT/pyvips-$run.dzi" -- "$PY" -c "$PYSCRIPT" "$SRC" "$OUT/pyvips-$run" ;;
    esac
  done
done

# ---------------------------------------------------------------------------------------------
# 4. PSNR of the last run's finest level
declare -A PSNR_DB
log "PSNR"
PSNR_DB[vortex]=$("$PSNR" "$SRC" --vortex "$OUT/vortex-$RUNS")
PSNR_DB[vortex-default]=$("$PSNR" "$SRC" --vortex "$OUT/vortex-default-$RUNS")
PSNR_DB[vips]=$("$PSNR" "$SRC" --dzi "$OUT/vips-${RUNS}_files")
[ -n "$PYVIPS_VERSION" ] && PSNR_DB[pyvips]=$("$PSNR" "$SRC" --dzi "$OUT/pyvips-${RUNS}_files")

# ---------------------------------------------------------------------------------------------
# 5. Height case
BIG_NOTE=
BIG_SUMMARY=
if [ "$BIG" = 1 ]; then
  free_gb=$(df -BG --output=avail "$WORK" | tail -1 | tr -dc 0-9)
  if [ ! -s srcbig.tif ] && [ "$free_gb" -lt 20 ]; then
    BIG_NOTE="skipped: only ${free_gb} GB free in bench/work (needs 20 GB)"
    echo "note: height case $BIG_NOTE" >&2
  else
    if [ ! -s srcbig.tif ]; then
      log "generating srcbig.tif (${SIDE}x${BIG_H})"
      "$GEN" $SIDE $BIG_H partbig.tif
      mv partbig.tif srcbig.tif
    fi
    cat srcbig.tif >/dev/null # warm the page cache where it fits
    # Not --quiet: the summary line names the decoder path and its own peak memory.
    timed vortex-tall 1 "$OUT/tall" -- "$TILER" split srcbig.tif -o "$OUT/tall" --tile-size 256 --border 0 --codec jpeg --quality 85 --filter box
    BIG_SUMMARY=$(grep '^wrote' "$WORK/vortex-tall.log" || true)
    if [ "$KEEP" != 1 ]; then rm -f srcbig.tif; fi
  fi
fi

log "removing the outputs"
rm -rf "$OUT"
sync
touch .cleaned

# ---------------------------------------------------------------------------------------------
# 6. Report
median() { # median of column $2 for tool $1
  awk -F'\t' -v t="$1" -v c="$2" '$1 == t { print $c }' "$RESULTS" | sort -g |
    awk '{ v[NR] = $1 } END { if (NR % 2) print v[(NR + 1) / 2]; else print (v[NR / 2] + v[NR / 2 + 1]) / 2 }'
}
calc() { awk "BEGIN { printf \"$1\", $2 }"; }

declare -A NAME=([vortex]="vortex-tiler --filter box ($REV)" [vortex-default]="vortex-tiler, default filter linear-premultiplied ($REV)" [vips]="vips dzsave ($VIPS_VERSION, Debian)" [pyvips]="pyvips dzsave ($PYVIPS_VERSION, PyPI)")
MPX=$(calc %.4f "$SIDE * $SIDE / 1e6")
VIPS_WALL=$(median vips 3)
VIPS_RSS=$(median vips 4)
CPU_MODEL=$(sed -n 's/^model name[[:space:]]*: //p' /proc/cpuinfo | head -1)
MEM_GIB=$(awk '/^MemTotal/ { printf "%.0f", $2 / 1048576 }' /proc/meminfo)

REPORT=$WORK/report.md
{
  echo "Run $(date -u '+%Y-%m-%d %H:%M UTC'), $RUNS alternating runs per tool; machine: $(nproc) cores ($CPU_MODEL), $MEM_GIB GiB RAM, $(. /etc/os-release && echo "$PRETTY_NAME"); peers: $VIPS_VERSION (Debian libvips-tools)${PYVIPS_VERSION:+, $PYVIPS_VERSION (pyvips-binary from PyPI)}; vortex-tiler at $REV."
  echo
  echo "$SIDE x $SIDE RGB 8-bit BigTIFF ($MPX Mpx), 256-texel JPEG tiles at Q85, no border or overlap, all LODs:"
  echo
  echo "| tool | median wall s | Mpx/s | peak RSS MiB | output MiB | PSNR dB (finest level) | throughput vs vips 8.14 | memory vs vips 8.14 | median CPU s (user + sys) |"
  echo "|---|---:|---:|---:|---:|---:|---:|---:|---:|"
  for tool in "${TOOLS[@]}"; do
    wall=$(median "$tool" 3)
    rss=$(median "$tool" 4)
    bytes=$(median "$tool" 7)
    echo "| ${NAME[$tool]} | $(calc %.2f "$wall") | $(calc %.1f "$MPX / $wall") | $(calc %.0f "$rss / 1024") | $(calc %.1f "$bytes / 1048576") | ${PSNR_DB[$tool]} | $(calc %.2fx "$VIPS_WALL / $wall") | $(calc %.2fx "$rss / $VIPS_RSS") | $(median "$tool" 5) + $(median "$tool" 6) |"
  done
  echo
  echo "Throughput ratio = vips 8.14 median wall / tool median wall (above 1 is faster); memory ratio = tool peak RSS / vips 8.14 peak RSS (below 1 is leaner). Output = summed size of the tile files; vips also writes levels below one tile (down to 1x1), vortex-tiler stops at one 256-texel tile. PSNR is over every RGB sample of the finest level, tiles decoded by the \`image\` crate. Each run writes a fresh directory and outputs are deleted only after all runs (see the script's header on ext4 and recently deleted inodes)."
  echo
  echo "Memory against image height (vortex-tiler, one run each for the tall image):"
  echo
  echo "| image | Mpx | wall s | Mpx/s | peak RSS MiB | output MiB |"
  echo "|---|---:|---:|---:|---:|---:|"
  wall=$(median vortex 3)
  echo "| $SIDE x $SIDE (median of $RUNS) | $(calc %.1f "$MPX") | $(calc %.2f "$wall") | $(calc %.1f "$MPX / $wall") | $(calc %.0f "$(median vortex 4) / 1024") | $(calc %.1f "$(median vortex 7) / 1048576") |"
  if grep -q '^vortex-tall' "$RESULTS"; then
    read -r _ _ wall rss _ _ bytes _ < <(grep '^vortex-tall' "$RESULTS")
    bmpx=$(calc %.4f "$SIDE * $BIG_H / 1e6")
    echo "| $SIDE x $BIG_H | $(calc %.1f "$bmpx") | $(calc %.2f "$wall") | $(calc %.1f "$bmpx / $wall") | $(calc %.0f "$rss / 1024") | $(calc %.1f "$bytes / 1048576") |"
  else
    echo "| $SIDE x $BIG_H | ${BIG_NOTE:-not run (BIG=0)} | | | | |"
  fi
  if [ -n "$BIG_SUMMARY" ]; then
    echo
    echo "vortex-tiler's summary line for the tall image:"
    echo
    echo '```'
    echo "$BIG_SUMMARY"
    echo '```'
  fi
  echo
  echo "<details><summary>Raw runs (wall s, peak RSS MiB, user + system CPU s, tile bytes, 1-minute load average before the run)</summary>"
  echo
  while IFS=$'\t' read -r tool run wall rss user sys bytes load; do
    echo "- $tool run $run: wall $wall s, peak RSS $(calc %.1f "$rss / 1024") MiB, CPU $user + $sys s, tiles $bytes B, load $load"
  done <"$RESULTS"
  echo
  echo "</details>"
} >"$REPORT"

BEGIN='<!-- split-vs-vips:begin -->'
END='<!-- split-vs-vips:end -->'
if [ ! -f "$DOC" ] || ! grep -qF "$BEGIN" "$DOC"; then
  mkdir -p "$(dirname "$DOC")"
  [ -s "$DOC" ] || printf '# Benchmarks\n\n' >"$DOC"
  cat >>"$DOC" <<EOF
## split against libvips dzsave

\`vortex-tiler split\` and libvips' \`dzsave\` (the usual tool for Deep Zoom pyramids) cut the same
uncompressed 16384 x 16384 RGB BigTIFF into 256-texel JPEG tiles at quality 85 with every
power-of-two level. vortex-tiler runs twice: with \`--filter box\`, which averages the levels in
stored (sRGB) values as vips does, and with its default filter, \`linear-premultiplied\`, which
averages in linear light (\`docs/accuracy.md\`). Measured per tool: wall-clock time and peak resident memory
(\`/usr/bin/time -v\`, median of alternating runs, source in the page cache), size of the tiles
written, and PSNR of the finest level against the source. A second case runs vortex-tiler on a
16384 x 131072 image to show that its memory does not grow with the image height.

Reproduce from the repository root (installs libvips-tools with apt-get when missing, builds,
generates the images in \`bench/work/\` and rewrites the section below):

    bench/split-vs-vips.sh          # RUNS=5 by default; KEEP=1 keeps the 6.4 GB tall image

$BEGIN
$END

Reading the numbers:

- The machine may be shared (another build running alongside), so runs alternate between
  tools and the table shows medians; the raw runs list the load average before each run.
- The tall image makes a square 131072-texel virtual texture, so about seven eighths of its
  LOD-0 tiles are edge padding to the right of the image. vortex-tiler encodes each distinct
  tile once but still writes every file (349525 of them, 3.9 GiB), so its Mpx/s there measures
  the padding too. Memory is what this case is about: peak RSS is the same as for the square
  image, set by the width and tile size, not the height.
- Tiles go to one directory per output. On ext4 without a journal, creating files within a
  minute or so of deleting many makes the inode allocator step over every recently deleted
  inode; the script therefore never deletes outputs between timed runs (see its header).
EOF
fi
awk -v b="$BEGIN" -v e="$END" -v rep="$REPORT" '
  $0 == b { print; print ""; while ((getline l < rep) > 0) print l; print ""; skip = 1; next }
  $0 == e { skip = 0 }
  !skip { print }' "$DOC" >"$DOC.tmp"
mv "$DOC.tmp" "$DOC"
cat "$REPORT"
log "wrote $DOC"
