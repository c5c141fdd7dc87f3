#!/usr/bin/env bash
# bench/split-vs-vips.sh: vortex-tiler split against libvips dzsave on the same images, and
# optionally against another vortex-tiler build (an earlier commit) in the same run.
#
# What it measures (results go to docs/benchmarks.md, or $DOC: case 1 between the
# split-vs-vips markers, case 2 between the split-tall markers, left as they are with BIG=0):
#   Case 1, 16384 x 16384 RGB 8-bit uncompressed BigTIFF (268.4 Mpx, ~805 MB, from
#   gen_image of crates/vortex-bench: gradients, zone plate, discs, per-pixel noise), cut into 256-texel
#   JPEG tiles at quality 85 with no border/overlap, alternately RUNS times by
#     - vortex-tiler split SRC -o OUT --tile-size 256 --border 0 --codec jpeg --quality 85 --filter box --quiet
#       (levels averaged in stored values, as vips does), and the same with the default filter,
#       linear-premultiplied (averaged in linear light); both again with the VORTEX_BEFORE
#       build when it is set, each before-run next to its after-run
#     - vips dzsave SRC OUT --tile-size 256 --overlap 0 --suffix .jpg[Q=85]   (Debian libvips 8.14)
#     - pyvips dzsave(tile_size=256, overlap=0, Q=85), sequential access   (newest libvips from
#       PyPI, pyvips-binary, in a venv; skipped with a note if pip cannot install it)
#   each under /usr/bin/time -v: wall clock, peak RSS; medians over the runs. Output size is the
#   sum of the tile files' sizes (tiles only: no info.json, .dzi or vips-properties.xml).
#   PSNR of the finest level against the source over all RGB samples (crates/vortex-bench/src/bin/psnr.rs).
#   Case 2, tall image: 16384 x 131072 (2147.5 Mpx, ~6.4 GB), the same options (vortex-tiler
#   with --filter box and without --quiet, for its summary line), TALL_RUNS times (default 1)
#   per tool: VORTEX_BEFORE when set, vortex-tiler, vips, pyvips. Tiles written (files
#   counted), their bytes, wall clock and peak RSS; no PSNR. Skipped with a note if the disk
#   lacks room (about 10 GB of outputs, 15 with VORTEX_BEFORE, plus 7 for the source).
#   Every vortex-tiler output's tile count is checked against the two grids it can be: per-axis
#   (LOD k has ceil(w_k/256) x ceil(h_k/256) tiles: 5461 and 43,695) or the square power-of-two
#   grid of builds before issue 13 (5461 and 349,525); any other count stops the script.
#
# Usage, from the repository root:
#     bench/split-vs-vips.sh
# Before/after a change, with a build of the earlier commit in its own worktree:
#     git worktree add /tmp/before COMMIT
#     (cd /tmp/before && CARGO_TARGET_DIR=/tmp/target-before cargo build --release -p vortex-tiler)
#     VORTEX_BEFORE=/tmp/target-before/release/vortex-tiler BEFORE_LABEL=COMMIT bench/split-vs-vips.sh
# Environment: RUNS (default 5), TALL_RUNS (default 1), KEEP=1 keeps the 6.4 GB image, BIG=0
# skips case 2, PYVIPS=0 skips the PyPI libvips peer; VORTEX=PATH times that binary instead of
# the repository's build (VORTEX_LABEL names it, see bench/lib.sh); VORTEX_BEFORE=PATH adds an
# earlier build (BEFORE_LABEL names it). Installs libvips-tools and time with apt-get when
# missing (needs root or sudo). Works in bench/work/ (git-ignored); the source images stay
# there between runs (src16k.tif is reused, srcbig.tif is deleted unless KEEP=1).
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
source bench/lib.sh
RUNS=${RUNS:-5}
TALL_RUNS=${TALL_RUNS:-1}
KEEP=${KEEP:-0}
BIG=${BIG:-1}
PYVIPS=${PYVIPS:-1}
BEFORE=${VORTEX_BEFORE:-}
SIDE=16384
BIG_H=131072
TILE=256

# ---------------------------------------------------------------------------------------------
# 1. Peers, build, binaries and the square source image
bench_setup # vips, time, bin/{vortex-tiler,gen_image,psnr}, src16k.tif, REV
VIPS_VERSION=$(vips --version)
if [ -n "$BEFORE" ]; then
  [ -x "$BEFORE" ] || { echo "error: VORTEX_BEFORE=$BEFORE is not an executable" >&2; exit 1; }
  cp "$BEFORE" "$WORK/bin/vortex-tiler-before"
  BEFORE_REV=${BEFORE_LABEL:-$BEFORE}
fi

PYVIPS_VERSION=
[ "$PYVIPS" = 1 ] && pyvips_setup

cd "$WORK"
OUT=$WORK/out
if [ -e "$OUT" ]; then # left by an interrupted run
  log "removing stale $OUT"
  rm -rf "$OUT"
  sync
  touch .cleaned
fi
SRC=src16k.tif

# ---------------------------------------------------------------------------------------------
# 2. Timing
RESULTS=$WORK/results.tsv # tool run wall_s rss_kib user_s sys_s tile_bytes load1 tiles
: >"$RESULTS"

# Seconds from /usr/bin/time's "h:mm:ss" or "m:ss.ss".
to_seconds() { awk -F: '{ s = 0; for (i = 1; i <= NF; i++) s = s * 60 + $i; printf "%.2f", s }' <<<"$1"; }
# "BYTES COUNT" of the tile files (JPEG) under the given paths.
tile_stats() { find "$@" -type f \( -name '*.jpg' -o -name '*.jpeg' \) -printf '%s\n' | awk '{ s += $1; n++ } END { printf "%.0f %d\n", s, n }'; }
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
  local wall rss user sys bytes tiles
  wall=$(to_seconds "$(field 'Elapsed (wall clock) time (h:mm:ss or m:ss)' "$WORK/time.txt")")
  rss=$(field 'Maximum resident set size (kbytes)' "$WORK/time.txt")
  user=$(field 'User time (seconds)' "$WORK/time.txt")
  sys=$(field 'System time (seconds)' "$WORK/time.txt")
  read -r bytes tiles < <(tile_stats "${outs[@]}")
  printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$tool" "$run" "$wall" "$rss" "$user" "$sys" "$bytes" "$load" "$tiles" >>"$RESULTS"
  log "$tool run $run: ${wall} s, $((rss / 1024)) MiB peak, $tiles tiles, load before $load"
}

# grid_tiles W H SQUARE: tiles over all LODs of a W x H image in $TILE-texel tiles, on the
# per-axis grid (SQUARE=0: ceil(w/T) x ceil(h/T) at LOD 0, halving per axis, rounding up, down
# to one tile) or on the square power-of-two grid that builds before issue 13 wrote (SQUARE=1).
grid_tiles() {
  awk -v w="$1" -v h="$2" -v t="$TILE" -v sq="$3" 'BEGIN {
    c = int((w + t - 1) / t); r = int((h + t - 1) / t)
    if (sq) { n = 1; while (n < c || n < r) n *= 2; c = n; r = n }
    total = 0
    while (1) { total += c * r; if (c == 1 && r == 1) break; c = int((c + 1) / 2); r = int((r + 1) / 2) }
    print total }'
}
# check_grid TOOL W H: names the grid that TOOL's last run wrote, or stops on a wrong tile count.
check_grid() {
  local tiles per_axis square
  tiles=$(awk -F'\t' -v t="$1" '$1 == t { n = $9 } END { print n }' "$RESULTS")
  per_axis=$(grid_tiles "$2" "$3" 0)
  square=$(grid_tiles "$2" "$3" 1)
  if [ "$tiles" = "$per_axis" ] && [ "$tiles" = "$square" ]; then
    GRID[$1]="per-axis = square"
  elif [ "$tiles" = "$per_axis" ]; then
    GRID[$1]=per-axis
  elif [ "$tiles" = "$square" ]; then
    GRID[$1]="square power-of-two"
  else
    echo "error: $1 wrote $tiles tiles for a $2 x $3 image: expected $per_axis (per-axis grid) or $square (square grid)" >&2
    exit 1
  fi
}
declare -A GRID

PYSCRIPT='import sys, pyvips
src, out = sys.argv[1], sys.argv[2]
im = pyvips.Image.new_from_file(src, access="sequential")
im.dzsave(out, tile_size=256, overlap=0, Q=85)'

# run_tool TOOL RUN SOURCE PREFIX [FLAG...]: one timed run of TOOL; vortex-tiler gets FLAG...
run_tool() {
  local tool=$1 run=$2 src=$3 id=$4$1 o=$OUT/$4-$1-$2
  shift 4
  case $tool in
    vortex*|before*)
      local bin=$WORK/bin/vortex-tiler
      [[ $tool == before* ]] && bin=$WORK/bin/vortex-tiler-before
      local filter=(--filter box)
      [[ $tool == *-default ]] && filter=()
      timed "$id" "$run" "$o" -- "$bin" split "$src" -o "$o" --tile-size $TILE --border 0 --codec jpeg --quality 85 "${filter[@]}" "$@" ;;
    vips) timed "$id" "$run" "${o}_files" "$o.dzi" -- vips dzsave "$src" "$o" --tile-size $TILE --overlap 0 --suffix '.jpg[Q=85]' ;;
    pyvips) timed "$id" "$run" "${o}_files" "$o.dzi" -- "$PY" -c "$PYSCRIPT" "$src" "$o" ;;
  esac
}

mkdir -p "$OUT"
if [ -e .cleaned ]; then
  wait_s=$((65 - $(date +%s) + $(stat -c %Y .cleaned)))
  if [ "$wait_s" -gt 0 ]; then
    log "waiting ${wait_s} s for the previous clean-up's inodes to age (see the header)"
    sleep "$wait_s"
  fi
fi

# ---------------------------------------------------------------------------------------------
# 3. Case 1: the square image
cat "$SRC" >/dev/null # warm the page cache
TOOLS=()
[ -n "$BEFORE" ] && TOOLS+=(before)
TOOLS+=(vortex)
[ -n "$BEFORE" ] && TOOLS+=(before-default)
TOOLS+=(vortex-default vips)
[ -n "$PYVIPS_VERSION" ] && TOOLS+=(pyvips)
for run in $(seq 1 "$RUNS"); do
  for tool in "${TOOLS[@]}"; do
    run_tool "$tool" "$run" "$SRC" sq --quiet
    case $tool in vortex*|before*) check_grid "sq$tool" $SIDE $SIDE ;; esac
  done
done

declare -A PSNR_DB
log "PSNR"
for tool in "${TOOLS[@]}"; do
  case $tool in
    vips|pyvips) PSNR_DB[$tool]=$(bin/psnr "$SRC" --dzi "$OUT/sq-$tool-${RUNS}_files") ;;
    *) PSNR_DB[$tool]=$(bin/psnr "$SRC" --vortex "$OUT/sq-$tool-$RUNS") ;;
  esac
done

# ---------------------------------------------------------------------------------------------
# 4. Case 2: the tall image
BIG_NOTE=
TALL_TOOLS=()
declare -A SUMMARY
if [ "$BIG" = 1 ]; then
  need_gb=10
  [ -n "$BEFORE" ] && need_gb=15
  [ -s srcbig.tif ] || need_gb=$((need_gb + 7))
  free_gb=$(df -BG --output=avail "$WORK" | tail -1 | tr -dc 0-9)
  if [ "$free_gb" -lt "$need_gb" ]; then
    BIG_NOTE="skipped: only ${free_gb} GB free in bench/work (needs $need_gb GB)"
    echo "note: tall case $BIG_NOTE" >&2
  else
    if [ ! -s srcbig.tif ]; then
      log "generating srcbig.tif (${SIDE}x${BIG_H})"
      bin/gen_image $SIDE $BIG_H partbig.tif
      mv partbig.tif srcbig.tif
    fi
    [ -n "$BEFORE" ] && TALL_TOOLS+=(before)
    TALL_TOOLS+=(vortex vips)
    [ -n "$PYVIPS_VERSION" ] && TALL_TOOLS+=(pyvips)
    for run in $(seq 1 "$TALL_RUNS"); do
      for tool in "${TALL_TOOLS[@]}"; do
        cat srcbig.tif >/dev/null # (re)warm the page cache: the previous run's output may have evicted some
        run_tool "$tool" "$run" srcbig.tif tall # not --quiet: the summary line names the decoder path
        case $tool in
          vortex|before)
            check_grid "tall$tool" $SIDE $BIG_H
            SUMMARY[$tool]=$(grep '^wrote' "$WORK/tall$tool.log" || true) ;;
        esac
      done
    done
    if [ "$KEEP" != 1 ]; then rm -f srcbig.tif; fi
  fi
fi

log "removing the outputs"
rm -rf "$OUT"
sync
touch .cleaned

# ---------------------------------------------------------------------------------------------
# 5. Reports
m() { median "$RESULTS" "$@"; }
CPU_MODEL=$(sed -n 's/^model name[[:space:]]*: //p' /proc/cpuinfo | head -1)
MEM_GIB=$(awk '/^MemTotal/ { printf "%.0f", $2 / 1048576 }' /proc/meminfo)
LOADS=$(cut -f8 "$RESULTS" | sort -g | awk 'NR == 1 { lo = $1 } { hi = $1 } END { print lo "-" hi }')
declare -A NAME=(
  [vortex]="vortex-tiler --filter box ($REV)"
  [vortex-default]="vortex-tiler, default filter linear-premultiplied ($REV)"
  [before]="vortex-tiler --filter box (${BEFORE_REV:-}, before)"
  [before-default]="vortex-tiler, default filter linear-premultiplied (${BEFORE_REV:-}, before)"
  [vips]="vips dzsave ($VIPS_VERSION, Debian)"
  [pyvips]="pyvips dzsave ($PYVIPS_VERSION, PyPI)")
# ratio_range A B: "median x, range lo-hi" of A's wall / B's wall in the same round: pairs
# that ran seconds apart, so less exposed to load that drifts over the run than the medians.
ratio_range() {
  awk -F'\t' -v a="$1" -v b="$2" '$1 == a { x[$2] = $3 } $1 == b { y[$2] = $3 }
    END { for (r in x) if (r in y && y[r] > 0) print x[r] / y[r] }' "$RESULTS" | sort -g |
    awk '{ v[NR] = $1 } END { med = NR % 2 ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2
          printf "median %.3f, range %.2f-%.2f", med, v[1], v[NR] }'
}
MPX=$(calc %.4f "$SIDE * $SIDE / 1e6")
VIPS_WALL=$(m sqvips 3)
VIPS_RSS=$(m sqvips 4)
REPORT=$WORK/report.md

# raw_runs PREFIX: the runs of the tools whose names start with PREFIX, as a folded list.
raw_runs() {
  echo "<details><summary>Raw runs (wall s, peak RSS MiB, user + system CPU s, tile bytes, tiles, 1-minute load average before the run)</summary>"
  echo
  while IFS=$'\t' read -r tool run wall rss user sys bytes load tiles; do
    [[ $tool == "$1"* ]] || continue
    echo "- ${tool#"$1"} run $run: wall $wall s, peak RSS $(calc %.1f "$rss / 1024") MiB, CPU $user + $sys s, tiles $bytes B in $tiles files, load $load"
  done <"$RESULTS"
  echo
  echo "</details>"
}

{
  echo "Run $(date -u '+%Y-%m-%d %H:%M UTC'), $RUNS alternating runs per tool; machine: $(nproc) cores ($CPU_MODEL), $MEM_GIB GiB RAM, $(. /etc/os-release && echo "$PRETTY_NAME"), 1-minute load average $LOADS before the runs; peers: $VIPS_VERSION (Debian libvips-tools)${PYVIPS_VERSION:+, $PYVIPS_VERSION (pyvips-binary from PyPI)}; vortex-tiler at $REV${BEFORE:+ and, before, at $BEFORE_REV}."
  echo
  echo "$SIDE x $SIDE RGB 8-bit BigTIFF ($MPX Mpx), 256-texel JPEG tiles at Q85, no border or overlap, all LODs:"
  echo
  echo "| tool | median wall s | Mpx/s | peak RSS MiB | tiles | output MiB | PSNR dB (finest level) | throughput vs vips 8.14 | memory vs vips 8.14 | median CPU s (user + sys) |"
  echo "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
  for tool in "${TOOLS[@]}"; do
    wall=$(m "sq$tool" 3)
    rss=$(m "sq$tool" 4)
    echo "| ${NAME[$tool]} | $(calc %.2f "$wall") | $(calc %.1f "$MPX / $wall") | $(calc %.0f "$rss / 1024") | $(m "sq$tool" 9) | $(calc %.1f "$(m "sq$tool" 7) / 1048576") | ${PSNR_DB[$tool]} | $(calc %.2fx "$VIPS_WALL / $wall") | $(calc %.2fx "$rss / $VIPS_RSS") | $(m "sq$tool" 5) + $(m "sq$tool" 6) |"
  done
  echo
  if [ -n "$BEFORE" ]; then
    echo "After/before ($REV / $BEFORE_REV), median wall over median wall (below 1 is faster): --filter box $(calc %.3f "$(m sqvortex 3) / $(m sqbefore 3)") (per round: $(ratio_range sqvortex sqbefore)), default filter $(calc %.3f "$(m sqvortex-default 3) / $(m sqbefore-default 3)") (per round: $(ratio_range sqvortex-default sqbefore-default)); CPU time (user + sys, medians) $(calc %.3f "($(m sqvortex 5) + $(m sqvortex 6)) / ($(m sqbefore 5) + $(m sqbefore 6))") and $(calc %.3f "($(m sqvortex-default 5) + $(m sqvortex-default 6)) / ($(m sqbefore-default 5) + $(m sqbefore-default 6))"); peak RSS $(calc %.3f "$(m sqvortex 4) / $(m sqbefore 4)") and $(calc %.3f "$(m sqvortex-default 4) / $(m sqbefore-default 4)"). Both builds wrote $(m sqvortex 9) tiles here (grid: ${GRID[sqvortex]}), $(m sqbefore 7) and $(m sqvortex 7) bytes with --filter box."
    echo
  fi
  echo "Throughput ratio = vips 8.14 median wall / tool median wall (above 1 is faster); memory ratio = tool peak RSS / vips 8.14 peak RSS (below 1 is leaner). Tiles = files written; output = their summed size; vips also writes levels below one tile (down to 1x1), vortex-tiler stops at one 256-texel tile. PSNR is over every RGB sample of the finest level, tiles decoded by the \`image\` crate. Each run writes a fresh directory and outputs are deleted only after all runs (see the script's header on ext4 and recently deleted inodes)."
  echo
  raw_runs sq
} >"$REPORT"

BMPX=$(calc %.4f "$SIDE * $BIG_H / 1e6")
TALL_REPORT=$WORK/report-tall.md
{
  echo "Run $(date -u '+%Y-%m-%d %H:%M UTC'), all tools in the same run, $TALL_RUNS run$([ "$TALL_RUNS" = 1 ] || echo s) per tool$([ "$TALL_RUNS" = 1 ] || echo ', alternating, medians'); $(nproc) cores; $VIPS_VERSION${PYVIPS_VERSION:+, $PYVIPS_VERSION}; vortex-tiler at $REV${BEFORE:+ and, before, at $BEFORE_REV}."
  echo
  echo "$SIDE x $BIG_H RGB 8-bit BigTIFF ($BMPX Mpx, uncompressed, 64-row strips), 256-texel JPEG tiles at Q85, no border or overlap, all LODs, source in the page cache:"
  echo
  if [ ${#TALL_TOOLS[@]} = 0 ]; then
    echo "Not measured: ${BIG_NOTE:-BIG=0}."
  else
    echo "| tool | grid | tiles | output MiB | wall s | Mpx/s | peak RSS MiB | peak RSS on the ${SIDE}² image | CPU s (user + sys) | throughput vs vips 8.14 |"
    echo "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|"
    tvw=$(m tallvips 3)
    for tool in "${TALL_TOOLS[@]}"; do
      wall=$(m "tall$tool" 3)
      case $tool in vips|pyvips) grid="Deep Zoom, to 1x1" ;; *) grid=${GRID[tall$tool]} ;; esac
      echo "| ${NAME[$tool]} | $grid | $(m "tall$tool" 9) | $(calc %.1f "$(m "tall$tool" 7) / 1048576") | $(calc %.2f "$wall") | $(calc %.1f "$BMPX / $wall") | $(calc %.0f "$(m "tall$tool" 4) / 1024") | $(calc %.0f "$(m "sq$tool" 4) / 1024") | $(m "tall$tool" 5) + $(m "tall$tool" 6) | $(calc %.2fx "$tvw / $wall") |"
    done
    echo
    if [ -n "$BEFORE" ]; then
      echo "After/before ($REV / $BEFORE_REV): tiles $(calc %.3f "$(m tallvortex 9) / $(m tallbefore 9)"), bytes $(calc %.3f "$(m tallvortex 7) / $(m tallbefore 7)"), wall $(calc %.3f "$(m tallvortex 3) / $(m tallbefore 3)"), peak RSS $(calc %.3f "$(m tallvortex 4) / $(m tallbefore 4)")."
      echo
    fi
    echo "Grid: per-axis = ceil(w_k/256) x ceil(h_k/256) tiles at LOD k ($(grid_tiles $SIDE $BIG_H 0) in all); square power-of-two = the longer side's page count rounded up to a power of two on both axes ($(grid_tiles $SIDE $BIG_H 1)); the script checks every vortex-tiler output against these counts. vips writes only tiles that hold image too, and its levels go on below one tile down to 1x1. Peak RSS on the square image is the median of the square case in the same run of the script."
    for tool in "${TALL_TOOLS[@]}"; do
      [ -n "${SUMMARY[$tool]:-}" ] || continue
      echo
      echo "Summary line of ${NAME[$tool]}:"
      echo
      echo '```'
      echo "${SUMMARY[$tool]}"
      echo '```'
    done
    echo
    raw_runs tall
  fi
} >"$TALL_REPORT"

splice split-vs-vips "$REPORT" "$(cat <<'EOF'
## split against libvips dzsave

`vortex-tiler split` and libvips' `dzsave` cut the same uncompressed 16384 x 16384 RGB BigTIFF
into 256-texel JPEG tiles at quality 85 with every power-of-two level. Reproduce with
`bench/split-vs-vips.sh` (see its header).
EOF
)"
if [ "$BIG" = 1 ]; then
  splice split-tall "$TALL_REPORT" "$(cat <<'EOF'
## A tall image: 16384 x 131072

The same options on an image eight times as tall as it is wide, one run per tool. Reproduce
with `bench/split-vs-vips.sh`.
EOF
)"
fi
cat "$REPORT" "$TALL_REPORT"
log "wrote $DOC"
