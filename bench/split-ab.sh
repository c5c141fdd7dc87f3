#!/usr/bin/env bash
# bench/split-ab.sh: two builds of vortex-tiler on one cell of bench/split-matrix.sh, run
# alternately, for a change that must cut CPU without changing a byte (issue 28). On a machine
# shared with other work, wall time is noise; CPU-seconds (user + sys, from /usr/bin/time -v)
# and peak RSS are what a change moves, so the report gives their medians beside the wall's,
# and checks that both builds wrote the same pack (`contentHash` of `split --json`).
#     bench/split-ab.sh OLD_BINARY NEW_BINARY                  # strip BigTIFF, JPEG Q85, 5 runs each
#     RUNS=7 SOURCE=tiled CODEC=png bench/split-ab.sh old new
#     EXTRA="--filter box" bench/split-ab.sh old new
# Sources and codecs are split-matrix.sh's (`strip` is bench/work/src16k.tif, the others are made
# by split-matrix.sh under bench/work/matrix); OUT_DIR=/dev/shm keeps the packs off the disk.
set -euo pipefail
cd "$(dirname "$0")/.."
[ $# = 2 ] || { echo "usage: $0 OLD_BINARY NEW_BINARY" >&2; exit 2; }
WORK=$PWD/bench/work
M=$WORK/matrix
OUT=${OUT_DIR:-$WORK}
RUNS=${RUNS:-5}
SOURCE=${SOURCE:-strip}
CODEC=${CODEC:-jpeg}
case $SOURCE in
  strip) src=$WORK/src16k.tif ;;
  tiled | deflate | lzw) src=$M/$SOURCE.tif ;;
  png | jpeg | ppm) src=$M/src.$([ "$SOURCE" = jpeg ] && echo jpg || echo "$SOURCE") ;;
  *) echo "error: unknown source $SOURCE" >&2; exit 2 ;;
esac
[ -s "$src" ] || { echo "error: $src is missing: run bench/split-matrix.sh (or bench_setup) first" >&2; exit 1; }
case $CODEC in
  jpeg) codec=(--codec jpeg --quality 85) ;;
  png) codec=(--codec png --png-compression fast) ;;
  bc7) codec=(--codec bc7 --bc7-effort ultra-fast) ;;
  *) codec=(--codec "$CODEC") ;;
esac
# Copies, so that a build finishing meanwhile cannot swap a binary between runs.
mkdir -p "$WORK/ab"
cp "$1" "$WORK/ab/old"
cp "$2" "$WORK/ab/new"
cat "$src" >/dev/null # in the page cache: this measures the work, not the disk
RAW=$WORK/ab/runs.tsv
: >"$RAW"
for round in $(seq "$RUNS"); do
  for build in old new; do
    rm -f "$OUT/ab.vtpk"
    sync # the previous run's writeback must not land in this one
    # shellcheck disable=SC2086 # EXTRA is word-split on purpose
    /usr/bin/time -v -o "$WORK/ab/time.txt" "$WORK/ab/$build" split "$src" --pack "$OUT/ab.vtpk" --force \
      --tile-size 256 --border 0 "${codec[@]}" ${EXTRA:-} --json >"$WORK/ab/out.json"
    t=$WORK/ab/time.txt
    wall=$(sed -n 's/^[[:space:]]*Elapsed (wall clock) time (h:mm:ss or m:ss): //p' "$t" |
      awk -F: '{ s = 0; for (i = 1; i <= NF; i++) s = s * 60 + $i; printf "%.2f", s }')
    user=$(sed -n 's/^[[:space:]]*User time (seconds): //p' "$t")
    sys=$(sed -n 's/^[[:space:]]*System time (seconds): //p' "$t")
    rss=$(sed -n 's/^[[:space:]]*Maximum resident set size (kbytes): //p' "$t")
    printf '%s\t%s\t%s\t%s\t%s\t%s\n' "$build" "$wall" "$user" "$sys" "$rss" "$(tr -d '\n' <"$WORK/ab/out.json")" >>"$RAW"
  done
done
rm -f "$OUT/ab.vtpk"
python3 - "$RAW" "$SOURCE" "$CODEC" "${EXTRA:-}" <<'PY'
import json, statistics, sys
raw, source, codec, extra = sys.argv[1:5]
runs = {}
for line in open(raw):
    build, wall, user, sys_, rss, out = line.rstrip("\n").split("\t", 5)
    runs.setdefault(build, []).append((float(wall), float(user) + float(sys_), float(user), int(rss), json.loads(out)))
mpx = 16384 * 16384 / 1e6
print(f"{source} {codec} {extra}".strip() + f": medians of {len(runs['old'])} runs each, alternating")
print("| build | wall | CPU (user + sys) | CPU ms / Mpx | user | peak RSS | pyramid | cut | read |")
print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
hashes = {}
for build in ("old", "new"):
    rs = runs[build]
    med = lambda f: statistics.median(f(r) for r in rs)
    st = lambda k: med(lambda r: r[4]["stages"].get(k, 0))
    hashes[build] = {r[4]["pack"]["contentHash"] for r in rs}
    print(f"| {build} | {med(lambda r: r[0]):.2f} s | {med(lambda r: r[1]):.2f} s | {med(lambda r: r[1]) / mpx * 1e3:.2f} "
          f"| {med(lambda r: r[2]):.2f} s | {med(lambda r: r[3]) / 1024:.1f} MiB | {st('pyramidSeconds'):.2f} | {st('cutSeconds'):.2f} | {st('readSeconds'):.2f} |")
same = len(hashes["old"]) == 1 and hashes["old"] == hashes["new"]
print(f"contentHash: {'the same, ' + next(iter(hashes['old'])) if same else 'DIFFERENT: ' + repr(hashes)}")
sys.exit(0 if same else 1)
PY
