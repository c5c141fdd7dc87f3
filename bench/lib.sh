# Shared by the bench/*.sh scripts: set-up, timing and the report splice. Source it from the
# repository root after `set -euo pipefail`.

ROOT=$PWD
WORK=$ROOT/bench/work
DOC=${DOC:-$ROOT/docs/benchmarks.md}
mkdir -p "$WORK"

log() { printf '[%(%H:%M:%S)T] %s\n' -1 "$*" >&2; }
as_root() { if [ "$(id -u)" = 0 ]; then "$@"; else sudo "$@"; fi; }

# Installs vips and GNU time if missing, builds, snapshots the binaries into $WORK/bin (a
# concurrent `cargo build` must not swap them between runs), generates the 16384² BigTIFF.
# VORTEX=PATH times that vortex-tiler binary instead of the repository's own release build (to
# compare builds of two commits; VORTEX_LABEL names it in the report, default its path); the
# examples gen_image and psnr always come from the repository. CARGO_TARGET_DIR is honoured.
# Sets REV, the vortex-tiler build's name in reports.
bench_setup() {
  if ! command -v vips >/dev/null || [ ! -x /usr/bin/time ]; then
    log "installing libvips-tools and time"
    as_root env DEBIAN_FRONTEND=noninteractive apt-get update -qq
    as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libvips-tools time >/dev/null
  fi
  local target=${CARGO_TARGET_DIR:-$ROOT/target}
  log "building"
  cargo build --release --quiet -p vortex-tiler --example gen_image --example psnr
  mkdir -p "$WORK/bin"
  if [ -n "${VORTEX:-}" ]; then
    [ -x "$VORTEX" ] || { echo "error: VORTEX=$VORTEX is not an executable" >&2; exit 1; }
    cp "$VORTEX" "$WORK/bin/vortex-tiler"
    REV=${VORTEX_LABEL:-$VORTEX}
  else
    cargo build --release --quiet
    cp "$target/release/vortex-tiler" "$WORK/bin/"
    REV="$(git rev-parse --short HEAD)$(git diff --quiet HEAD -- src crates Cargo.toml Cargo.lock || echo +uncommitted)"
  fi
  cp "$target/release/examples/gen_image" "$target/release/examples/psnr" "$WORK/bin/"
  if [ ! -s "$WORK/src16k.tif" ]; then
    log "generating src16k.tif"
    "$WORK/bin/gen_image" 16384 16384 "$WORK/part16k.tif" # the format follows the extension
    mv "$WORK/part16k.tif" "$WORK/src16k.tif"
  fi
  export VIPS_WARNING=0 # vips 8.14 warns about the TIFF Predictor tag the tiff crate writes
}

# measure LOG COMMAND...: runs COMMAND under /usr/bin/time -v, prints "wall_s peak_rss_kib".
measure() {
  local log=$1
  shift
  sync # the previous run's writeback must not land in this one
  /usr/bin/time -v -o "$WORK/time.txt" "$@" >"$log" 2>&1 || { cat "$log" >&2; exit 1; }
  local wall
  wall=$(sed -n 's/^[[:space:]]*Elapsed (wall clock) time (h:mm:ss or m:ss): //p' "$WORK/time.txt")
  wall=$(awk -F: '{ s = 0; for (i = 1; i <= NF; i++) s = s * 60 + $i; printf "%.2f", s }' <<<"$wall")
  echo "$wall $(sed -n 's/^[[:space:]]*Maximum resident set size (kbytes): //p' "$WORK/time.txt")"
}

# median FILE TOOL COLUMN: the median of COLUMN over FILE's lines whose first field is TOOL.
median() {
  awk -F'\t' -v t="$2" -v c="$3" '$1 == t { print $c }' "$1" | sort -g |
    awk '{ v[NR] = $1 } END { if (NR % 2) print v[(NR + 1) / 2]; else print (v[NR / 2] + v[NR / 2 + 1]) / 2 }'
}

# The runtime benchmarks' pack: src16k.tif at 136-texel tiles with a 4-texel border (128-texel
# pages), made once; prints its path.
world_pack() {
  local pack=$WORK/world16k.vtpk
  if [ ! -s "$pack" ]; then
    log "packing src16k.tif"
    "$WORK/bin/vortex-tiler" split "$WORK/src16k.tif" --pack "$pack" --tile-size 136 --border 4 -q
  fi
  echo "$pack"
}
# world_png_pack: the same image and grid as world_pack, lossless (PNG tiles), made the first time.
world_png_pack() {
  local pack=$WORK/world16k-png.vtpk
  if [ ! -s "$pack" ]; then
    log "packing src16k.tif losslessly"
    "$WORK/bin/vortex-tiler" split "$WORK/src16k.tif" --pack "$pack" --tile-size 136 --border 4 --codec png -q
  fi
  echo "$pack"
}
calc() { awk "BEGIN { printf \"$1\", $2 }"; }

# splice NAME REPORT INTRO: puts REPORT between NAME's markers in $DOC, adding a section with
# INTRO the first time.
splice() {
  local begin="<!-- $1:begin -->" end="<!-- $1:end -->"
  grep -qF "$begin" "$DOC" || printf '\n%s\n\n%s\n%s\n' "$3" "$begin" "$end" >>"$DOC"
  awk -v b="$begin" -v e="$end" -v rep="$2" '
    $0 == b { print; print ""; while ((getline l < rep) > 0) print l; print ""; skip = 1; next }
    $0 == e { skip = 0 }
    !skip { print }' "$DOC" >"$DOC.tmp"
  mv "$DOC.tmp" "$DOC"
}
