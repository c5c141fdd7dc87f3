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
# tools gen_image and psnr (crates/vortex-bench) always come from the repository. CARGO_TARGET_DIR is honoured.
# Sets REV, the vortex-tiler build's name in reports.
bench_setup() {
  if ! command -v vips >/dev/null || [ ! -x /usr/bin/time ]; then
    log "installing libvips-tools and time"
    as_root env DEBIAN_FRONTEND=noninteractive apt-get update -qq
    as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libvips-tools time >/dev/null
  fi
  local target=${CARGO_TARGET_DIR:-$ROOT/target}
  log "building"
  cargo build --release --quiet -p vortex-bench --bin gen_image --bin psnr
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
  cp "$target/release/gen_image" "$target/release/psnr" "$WORK/bin/"
  if [ ! -s "$WORK/src16k.tif" ]; then
    log "generating src16k.tif"
    "$WORK/bin/gen_image" 16384 16384 "$WORK/part16k.tif" # the format follows the extension
    mv "$WORK/part16k.tif" "$WORK/src16k.tif"
  fi
  export VIPS_WARNING=0 # vips 8.14 warns about the TIFF Predictor tag the tiff crate writes
}

# snapshot_release: copies the release build of vortex-tiler (already built: the slide scripts
# do not build) into $WORK/bin, so that a concurrent build cannot swap it between runs, and sets
# VT to the copy and REV to its name in reports. VORTEX=PATH times another build instead
# (VORTEX_LABEL names it, default its path); CARGO_TARGET_DIR is honoured.
snapshot_release() {
  local bin=${VORTEX:-${CARGO_TARGET_DIR:-$ROOT/target}/release/vortex-tiler}
  [ -x "$bin" ] || { echo "error: build it first: cargo build --release -p vortex-tiler" >&2; exit 1; }
  mkdir -p "$WORK/bin"
  cp "$bin" "$WORK/bin/vortex-tiler"
  VT=$WORK/bin/vortex-tiler
  REV="$(git rev-parse --short HEAD)$(git diff --quiet HEAD -- src crates Cargo.toml Cargo.lock || echo +uncommitted)"
  [ -z "${VORTEX:-}" ] || REV=${VORTEX_LABEL:-$VORTEX}
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
# INTRO the first time (none where INTRO is empty: the markers must be there). splice_check NAME:
# fails unless NAME's markers are in $DOC, once each and in order (before measuring anything).
# Both are crates/vortex-bench's `splice`, the one implementation of the convention.
splice() { cargo run --release --quiet --manifest-path "$ROOT/Cargo.toml" -p vortex-bench --bin splice -- "$DOC" "$1" "$2" "$3"; }
splice_check() { cargo run --release --quiet --manifest-path "$ROOT/Cargo.toml" -p vortex-bench --bin splice -- --check "$DOC" "$1"; }

# pyvips_setup: libvips 8.18 from PyPI (pyvips + pyvips-binary): VORTEX_PYVIPS's Python (as the
# tests use) where it is set, else $WORK/venv, installed the first time. Sets PY (its python) and
# PYVIPS_VERSION ("libvips-8.18.7"), both empty when it cannot be had (a note says why), and
# checks that the peer runs at its best (pyvips_direct_check).
pyvips_setup() {
  PY=${VORTEX_PYVIPS:-$WORK/venv/bin/python}
  PYVIPS_VERSION=
  if [ -z "${VORTEX_PYVIPS:-}" ] && ! "$PY" -c 'import pyvips' 2>/dev/null; then
    log "installing pyvips + pyvips-binary into $WORK/venv"
    if ! { python3 -m venv "$WORK/venv" && "$WORK/venv/bin/pip" install -q pyvips pyvips-binary; } >"$WORK/pip.log" 2>&1; then
      echo "note: could not install pyvips/pyvips-binary (see $WORK/pip.log); no libvips 8.18 peer" >&2
      PY=
      return
    fi
  fi
  PYVIPS_VERSION=$("$PY" -c 'import pyvips; print("libvips-%d.%d.%d" % tuple(pyvips.version(i) for i in range(3)))')
  pyvips_direct_check
}

# pyvips_direct_check: libvips 8.15 and later write JPEG tiles straight from dzsave's pyramid
# ("direct mode") when the quality is dzsave's own `Q` parameter; a quality given inside the
# tiles' suffix sends every tile through a generic save instead, at less than half the speed
# (issue 28: the peer of docs/benchmarks.md ran that way until 2026-11-26). Every peer call in
# bench/ passes `Q=` (tests/it/docs.rs checks the scripts); this makes sure the installed
# libvips has the direct mode: a version from 8.15 on whose dzsave takes `Q`, or the benchmark
# stops, since its peer column would be wrong.
pyvips_direct_check() {
  "$PY" - <<'PY' || { echo "error: libvips $PYVIPS_VERSION has no direct dzsave (8.15+ with Q): the peer would be handicapped" >&2; exit 1; }
import sys, pyvips
version = (pyvips.version(0), pyvips.version(1))
sys.exit(0 if version >= (8, 15) and "Q" in pyvips.Introspect.get("dzsave").optional_input else 1)
PY
}

# jpeg_tiled_source: the 16384² image saved by Debian's vips as a JPEG-tiled BigTIFF (256² RGB
# tiles, Q90: RGB, as libvips writes from Q90 on), made the first time; prints its path.
jpeg_tiled_source() {
  local f=$WORK/matrix/jtiff.tif
  if [ ! -s "$f" ]; then
    mkdir -p "$WORK/matrix"
    vips tiffsave "$WORK/src16k.tif" "$f.part.tif" --tile --tile-width 256 --tile-height 256 --compression jpeg --Q 90 --bigtiff
    mv "$f.part.tif" "$f"
  fi
  echo "$f"
}

# new_ext4 MOUNT [nojournal]: a new, empty ext4 (with a journal unless asked) on a 3 GB image,
# mounted at MOUNT through a loop device, replacing what was mounted there; root only. A run
# writing thousands of files measures its file system's recent deletions too (on a journal-less
# ext4 new inodes skip those freed in the last minutes: docs/benchmarks.md, "Creating files"),
# so directory outputs are timed on a new one. drop_ext4 MOUNT unmounts it and removes its image.
new_ext4() {
  drop_ext4 "$1"
  truncate -s 3G "$1.img"
  mkfs.ext4 -q -F $([ "${2:-}" = nojournal ] && echo "-O ^has_journal") "$1.img"
  mkdir -p "$1"
  mount -o loop "$1.img" "$1"
}
drop_ext4() { umount "$1" 2>/dev/null || true; rm -f "$1.img"; }
# can_mount: whether new_ext4 can work here (root, mkfs.ext4).
can_mount() { [ "$(id -u)" = 0 ] && command -v mkfs.ext4 >/dev/null; }

# split_variant_args NAME: how bench/split-matrix.sh's row NAME cuts its source: the variants of
# the strip BigTIFF that issue 28's goals name (`strip-box`: libvips' own 2x2 mean;
# `strip-border1`: our default border), every other row with no border.
split_variant_args() {
  case $1 in
    strip-box) echo "--border 0 --filter box" ;;
    strip-border1) echo "--border 1" ;;
    jtiff-fast) echo "--border 0 --fast-shrink" ;;
    *-dzi) echo "--overlap 0" ;;
    *) echo "--border 0" ;;
  esac
}
# peer_grid NAME: the peer's tile size and overlap giving the same 256-texel files as that row.
peer_grid() { [ "$1" = strip-border1 ] && echo "254 1" || echo "256 0"; }
# The peer's call: dzsave SOURCE into OUT (a .zip, else a Deep Zoom directory) at TILE_SIZE and OVERLAP, JPEG Q85 in direct mode.
PEER_DZSAVE='import sys, pyvips
im = pyvips.Image.new_from_file(sys.argv[1], access="sequential")
im.dzsave(sys.argv[2], tile_size=int(sys.argv[3]), overlap=int(sys.argv[4]), Q=85)'

# make_slide W H PATH: a slide-like pyramidal TIFF of 256-texel JPEG tiles (Q90, shared tables), as
# a scanner saves one, unless PATH exists. One lazy pipeline (no full-size intermediates): three
# Perlin fields, two for the stain's hue and one for where tissue is, over a near-white
# background, with grain on top. Needs pyvips_setup's $PY.
make_slide() {
  [ -s "$3" ] && return
  log "making $3"
  "$PY" - "$1" "$2" "$3" <<'PY'
import sys, pyvips
w, h, out = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
p1 = pyvips.Image.perlin(w, h, cell_size=512, seed=1)
p2 = pyvips.Image.perlin(w, h, cell_size=128, seed=2)
t = (pyvips.Image.perlin(w, h, cell_size=2048, seed=3) * 3 + 0.5).cast("float")
t = (t > 1).ifthenelse(1, (t < 0).ifthenelse(0, t))
stain = (p1 * 70 + 180).bandjoin([p2 * 60 + 120, p1 * -40 + 200])
mix = stain * t + (1 - t) * 242 + pyvips.Image.gaussnoise(w, h, sigma=6, mean=0)
mix.cast("uchar").copy(interpretation="srgb").tiffsave(out, tile=True, tile_width=256, tile_height=256, pyramid=True, compression="jpeg", Q=90, bigtiff=True)
PY
}
