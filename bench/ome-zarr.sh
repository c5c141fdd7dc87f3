#!/usr/bin/env bash
# bench/ome-zarr.sh: vortex-tiler --layout ome-zarr against the Python writers of that world,
# in the same run, and the label filters against a numpy 2x2 mode (docs/benchmarks.md,
# docs/ome-zarr.md).
#
# Inputs (bench/ome-zarr.py gen, made once in bench/work/oz/, about 5.5 GB), SIDE x SIDE
# (default 16384): RGB 8-bit and 4 channels of 16 bits, gradients and waves with per-pixel
# noise; uint16 and uint8 label images of jittered cells (a few thousand objects). Each as an
# uncompressed TIFF in strips of 64 rows (RGB contiguous, the 4 channels in separate planes)
# for vortex-tiler, and as a .npy the peers memory-map.
#
# Writers, each to OME-Zarr 0.4 and 0.5 (sharded: 16 x 16 chunks per shard), 256-texel chunks,
# levels down to one chunk (7 at 16384), alternately RUNS times (default 3), medians:
#   - vortex-tiler split SRC --layout ome-zarr [--ome-zarr-version 0.4] -o OUT -q
#     (box filter; the 4 channels in one pass each, read from the TIFF's planes)
#   - ome-zarr-py: ome_zarr.writer.write_image from the memory-mapped .npy (its default
#     resize method, anti-aliased), storage_options chunks (and shards for 0.5)
#   - ngff-zarr: to_multiscales (method dask_bin_shrink, the 2x2 mean) + to_ngff_zarr
# each under /usr/bin/time -v: wall clock, peak RSS; files written (find -type f).
# Labels: vortex-tiler --filter mode, nearest and box into OME-Zarr 0.5 (uint16 and uint8),
# RUNS times; numpy's vectorised 2x2 mode over the same levels (in memory, the array loaded
# first) and scipy.stats.mode over 2x2 blocks of a 2048^2 crop, in source Mpx/s.
#
# Usage, from the repository root: bench/ome-zarr.sh
# Environment: LIMIT (900 s a run), RUNS (3), PEER_RUNS (RUNS: the peers run in the first PEER_RUNS rounds only,
# they being slow), SIDE (16384), PYTHON (target/pyvips/bin/python, made by .ci/run, with
# ome-zarr, ngff-zarr, tifffile, scipy). Prints a Markdown table; results go into the docs by hand.
set -euo pipefail
source bench/lib.sh

RUNS=${RUNS:-3}
PEER_RUNS=${PEER_RUNS:-$RUNS}
SIDE=${SIDE:-16384}
PY=${PYTHON:-$ROOT/target/pyvips/bin/python}
HERE=$ROOT/bench/ome-zarr.py
OZ=$WORK/oz
mkdir -p "$OZ" "$WORK/bin"
[ -x /usr/bin/time ] || { echo "error: needs GNU time (apt-get install time)" >&2; exit 1; }
"$PY" -c "import ome_zarr, ngff_zarr, tifffile, scipy" || {
  echo "error: $PY lacks ome-zarr, ngff-zarr, tifffile or scipy (.ci/run installs them)" >&2
  exit 1
}

target=${CARGO_TARGET_DIR:-$ROOT/target}
if [ -z "${VORTEX:-}" ]; then
  log "building"
  # The command line alone (split's code is the same; no GPU or server crates to build).
  cargo build --release --quiet -p vortex-tiler --no-default-features --features cli
  VORTEX=$target/release/vortex-tiler
fi
cp "$VORTEX" "$WORK/bin/vortex-tiler-oz"
V=$WORK/bin/vortex-tiler-oz

if [ ! -s "$OZ/done-$SIDE" ]; then
  log "generating the ${SIDE}² inputs"
  rm -f "$OZ"/*
  "$PY" "$HERE" gen "$OZ" "$SIDE"
  touch "$OZ/done-$SIDE"
fi

# Levels down to one 256-texel chunk, as every writer here makes them.
LEVELS=1
for ((s = SIDE; s > 256; s /= 2)); do LEVELS=$((LEVELS + 1)); done
RESULTS=$WORK/oz-results.tsv
: >"$RESULTS"
: >"$WORK/oz-mode.txt"
out=$WORK/oz-out

# run NAME COMMAND...: one timed run into $out (removed before and after), stopped after
# LIMIT seconds (default 900); appends "NAME wall rss files" to RESULTS ("timeout" for wall
# where it was stopped).
run() {
  local name=$1
  shift
  rm -rf "$out"
  sync # the previous run's writeback must not land in this one
  local wall rss files
  if /usr/bin/time -v -o "$WORK/time.txt" timeout "${LIMIT:-900}" "$@" >"$WORK/oz-$name.log" 2>&1; then
    wall=$(sed -n 's/^[[:space:]]*Elapsed (wall clock) time (h:mm:ss or m:ss): //p' "$WORK/time.txt")
    wall=$(awk -F: '{ s = 0; for (i = 1; i <= NF; i++) s = s * 60 + $i; printf "%.2f", s }' <<<"$wall")
  elif grep -q "status 124" "$WORK/time.txt"; then
    wall=timeout
  else
    cat "$WORK/oz-$name.log" >&2
    exit 1
  fi
  rss=$(sed -n 's/^[[:space:]]*Maximum resident set size (kbytes): //p' "$WORK/time.txt")
  files=$( (find "$out" -type f 2>/dev/null || true) | wc -l)
  printf '%s\t%s\t%s\t%s\n' "$name" "$wall" "$rss" "$files" >>"$RESULTS"
  log "$name: $wall s, $rss KiB, $files files"
  rm -rf "$out"
}

for i in $(seq "$RUNS"); do
  for image in rgb c4; do
    for v in 0.4 0.5; do
      run "vortex-$image-$v" "$V" split "$OZ/$image.tif" --layout ome-zarr --ome-zarr-version "$v" -o "$out" -q
      [ "$i" -le "$PEER_RUNS" ] || continue
      run "ome-zarr-py-$image-$v" "$PY" "$HERE" ome-zarr-py "$OZ/$image.npy" "$out" "$v"
      run "ngff-zarr-$image-$v" "$PY" "$HERE" ngff-zarr "$OZ/$image.npy" "$out" "$v"
    done
  done
  for lab in labels16 labels8; do
    for f in mode nearest box; do
      run "vortex-$lab-$f" "$V" split "$OZ/$lab.tif" --layout ome-zarr --filter "$f" -o "$out" -q
    done
    [ "$i" -le "$PEER_RUNS" ] || continue
    "$PY" "$HERE" mode "$OZ/$lab.npy" "$LEVELS" | sed "s/^/$lab /" >>"$WORK/oz-mode.txt"
  done
done

mpx=$(awk -v s="$SIDE" 'BEGIN { printf "%.1f", s * s / 1e6 }')
echo
echo "| ${SIDE}² ($mpx Mpx) | OME-Zarr | wall s | peak RSS MiB | files |"
echo "| --- | --- | ---: | ---: | ---: |"
for image in rgb c4; do
  for tool in vortex ome-zarr-py ngff-zarr; do
    for v in 0.4 0.5; do
      n="$tool-$image-$v"
      printf '| %s %s | %s | %s | %.0f | %s |\n' "$tool" "$image" "$v" "$(median "$RESULTS" "$n" 2)" \
        "$(awk -v k="$(median "$RESULTS" "$n" 3)" 'BEGIN { print k / 1024 }')" "$(median "$RESULTS" "$n" 4)"
    done
  done
done
echo
echo "| labels | filter | wall s | source Mpx/s | peak RSS MiB |"
echo "| --- | --- | ---: | ---: | ---: |"
for lab in labels16 labels8; do
  for f in mode nearest box; do
    n="vortex-$lab-$f"
    w=$(median "$RESULTS" "$n" 2)
    printf '| %s | %s | %s | %.1f | %.0f |\n' "$lab" "$f" "$w" "$(awk -v s="$SIDE" -v w="$w" 'BEGIN { print s * s / w / 1e6 }')" \
      "$(awk -v k="$(median "$RESULTS" "$n" 3)" 'BEGIN { print k / 1024 }')"
  done
done
echo
echo "numpy / scipy 2x2 mode (per run):"
cat "$WORK/oz-mode.txt"
rm -f "$WORK/oz-mode.txt"
