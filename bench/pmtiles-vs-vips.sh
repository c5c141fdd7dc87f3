#!/usr/bin/env bash
# bench/pmtiles-vs-vips.sh: `split --pmtiles` (one PMTiles v3 archive of the z/x/y pyramid)
# against libvips 8.18's dzsave writing one .zip of 256-texel JPEG tiles (pyvips-binary, direct
# mode: `Q=85` as dzsave's own parameter), on the 16384² BigTIFF of bench/split-vs-vips.sh
# (src16k.tif, generated if missing). Both one file of 256-texel JPEG tiles at quality 85, no
# overlap. Per run, from /usr/bin/time -v: wall, CPU (user + sys) and peak RSS; RUNS runs each
# (default 3), ours and the peer alternately, medians. File sizes against the total of a
# `--layout dzi` directory of the same tiles (the upload-cost stand-in of docs/web.md).
#
#     bench/pmtiles-vs-vips.sh              # about a minute on 2 idle cores
#     RUNS=5 bench/pmtiles-vs-vips.sh
#
# The report goes to docs/benchmarks.md (or $DOC) between `<!-- pmtiles-vs-vips:begin -->` and
# `:end -->`.
set -euo pipefail
cd "$(dirname "$0")/.."
source bench/lib.sh
RUNS=${RUNS:-3}
# VORTEX=PATH (with src16k.tif made already) times that binary and builds nothing: on a busy
# machine, a build with `--no-default-features --features cli` has the same split path and
# skips the GPU and server crates.
if [ -n "${VORTEX:-}" ] && [ -s "${SRC:-$WORK/src16k.tif}" ]; then
  mkdir -p "$WORK/bin"
  cp "$VORTEX" "$WORK/bin/vortex-tiler"
  REV=${VORTEX_LABEL:-$(git rev-parse --short HEAD)}
else
  bench_setup
fi
# VORTEX_PYVIPS=PYTHON: a Python with pyvips (libvips 8.18) already, as the tests use.
pyvips_setup
[ -n "$PY" ] || { echo "error: no libvips 8.18 peer (pyvips); see $WORK/pip.log" >&2; exit 1; }
SRC=${SRC:-$WORK/src16k.tif} # SRC=PATH: another 16384² image
P=$WORK/pmtiles
mkdir -p "$P"
PEER='import sys, pyvips
im = pyvips.Image.new_from_file(sys.argv[1], access="sequential")
im.dzsave(sys.argv[2], tile_size=256, overlap=0, Q=85)'

RAW=$P/runs.tsv
: >"$RAW"
# run ID COMMAND...: one timed run, appends "ID wall cpu rss_kib" to $RAW.
run() {
  local id=$1
  shift
  sync
  /usr/bin/time -v -o "$P/time.txt" "$@" >"$P/out.txt" 2>&1 || { cat "$P/out.txt" >&2; exit 1; }
  local wall user sys rss
  wall=$(sed -n 's/^[[:space:]]*Elapsed (wall clock) time (h:mm:ss or m:ss): //p' "$P/time.txt" |
    awk -F: '{ s = 0; for (i = 1; i <= NF; i++) s = s * 60 + $i; printf "%.2f", s }')
  user=$(sed -n 's/^[[:space:]]*User time (seconds): //p' "$P/time.txt")
  sys=$(sed -n 's/^[[:space:]]*System time (seconds): //p' "$P/time.txt")
  rss=$(sed -n 's/^[[:space:]]*Maximum resident set size (kbytes): //p' "$P/time.txt")
  printf '%s\t%s\t%s\t%s\n' "$id" "$wall" "$(calc %.2f "$user + $sys")" "$rss" >>"$RAW"
  log "$id: ${wall} s, $(calc %.0f "$rss / 1024") MiB"
}

cat "$SRC" >/dev/null # in the page cache: this measures the work, not the disk
for round in $(seq "$RUNS"); do
  rm -f "$P/out.pmtiles" "$P/peer.zip"
  run ours "$WORK/bin/vortex-tiler" split "$SRC" --pmtiles "$P/out.pmtiles" --tile-size 256 --quality 85 -q
  run peer "$PY" -c "$PEER" "$SRC" "$P/peer.zip"
done
rm -rf "$P/dzi"
"$WORK/bin/vortex-tiler" split "$SRC" --layout dzi -o "$P/dzi" --tile-size 256 --overlap 0 --quality 85 -q
pm_bytes=$(stat -c %s "$P/out.pmtiles")
zip_bytes=$(stat -c %s "$P/peer.zip")
dzi_bytes=$(find "$P/dzi" -type f -printf '%s\n' | awk '{ s += $1 } END { print s }')
dzi_files=$(find "$P/dzi" -type f | wc -l)
rm -rf "$P/dzi" "$P/peer.zip"

REPORT=$P/report.md
python3 - "$RAW" "$PYVIPS_VERSION" "$REV" "$pm_bytes" "$zip_bytes" "$dzi_bytes" "$dzi_files" "$(uptime)" "$(basename "$SRC")" >"$REPORT" <<'PY'
import datetime, os, statistics, sys
raw, peer_version, rev = sys.argv[1:4]
pm, zipped, dzi, dzi_files = map(int, sys.argv[4:8])
load = sys.argv[8].rsplit("load average:", 1)[-1].strip()
src = sys.argv[9]
runs = {}
for line in open(raw):
    rid, wall, cpu, rss = line.split("\t")
    runs.setdefault(rid, []).append((float(wall), float(cpu), int(rss)))
med = {rid: [statistics.median(r[i] for r in rs) for i in range(3)] for rid, rs in runs.items()}
n = len(runs["ours"])
print(f"{datetime.date.today()}, {os.cpu_count()} cores (load average {load} at the end: shared with other jobs),"
      f" vortex-tiler {rev}, peer {peer_version} (pyvips-binary, direct mode: `Q=85`); medians of {n} runs each,"
      " alternating.")
print()
print("| tool | command | wall | CPU | peak RSS | file |")
print("|---|---|---:|---:|---:|---:|")
o, p = med["ours"], med["peer"]
print(f"| vortex-tiler | `split {src} --pmtiles out.pmtiles --tile-size 256 --quality 85` | {o[0]:.2f} s | {o[1]:.2f} s | {o[2] / 1024:.0f} MiB | {pm:,} bytes |")
print(f"| libvips | `dzsave(out.zip, tile_size=256, overlap=0, Q=85)` | {p[0]:.2f} s | {p[1]:.2f} s | {p[2] / 1024:.0f} MiB | {zipped:,} bytes |")
print()
print(f"Ours against the peer: {p[0] / o[0]:.2f}x the speed (wall), {p[1] / o[1]:.2f}x less CPU (on a loaded machine CPU time is the fairer measure), "
      f"{o[2] / p[2]:.2f}x its memory. Sizes against a `--layout dzi --tile-size 256 --overlap 0` directory of the same "
      f"tiles ({dzi_files:,} files, {dzi:,} bytes): the archive {pm / dzi:.3f}x, the peer's .zip {zipped / dzi:.3f}x.")
PY
cat "$REPORT"
splice pmtiles-vs-vips "$REPORT" "## PMTiles: split --pmtiles against libvips dzsave to a .zip (\`bench/pmtiles-vs-vips.sh\`)

One file of 256-texel JPEG tiles (quality 85, no overlap) from the 16384² BigTIFF each: our
PMTiles v3 archive (the z/x/y pyramid, clustered; the tiles spooled, then copied in tile-id
order) and libvips 8.18's nearest, a Deep Zoom .zip. Peak RSS and CPU from /usr/bin/time -v."
