#!/usr/bin/env bash
# bench/split-profile.sh: where one cell of bench/split-matrix.sh spends its CPU, per thread
# (issue 18). Samples `split --pack` of a source with a codec under `perf record` and prints,
# per thread, its CPU seconds and its busiest symbols; then the whole run's CPU per 100 ms
# (2.0 = both cores busy), which shows where the cores idle: at the start, the end, or all
# along. Needs `perf` (Debian: linux-perf) and the matrix's sources (made by split-matrix.sh).
#     bench/split-profile.sh strip jpeg
#     bench/split-profile.sh png raw
#     OUT_DIR=/dev/shm bench/split-profile.sh strip jpeg   # the pack on tmpfs: no disk
set -euo pipefail
cd "$(dirname "$0")/.."
source bench/lib.sh
[ $# = 2 ] || { echo "usage: $0 SOURCE CODEC (sources: strip tiled deflate lzw png jpeg ppm; codecs as split-matrix.sh)" >&2; exit 2; }
command -v perf >/dev/null || { echo "error: no perf (apt-get install linux-perf)" >&2; exit 1; }
M=$WORK/matrix
OUT=${OUT_DIR:-$M}
case $1 in
  strip) src=$WORK/src16k.tif ;;
  tiled | deflate | lzw) src=$M/$1.tif ;;
  png | jpeg | ppm) src=$M/src.$([ "$1" = jpeg ] && echo jpg || echo "$1") ;;
  *) echo "error: unknown source $1" >&2; exit 2 ;;
esac
[ -s "$src" ] || { echo "error: $src is missing: run bench/split-matrix.sh first" >&2; exit 1; }
case $2 in
  jpeg) codec=(--codec jpeg --quality 85) ;;
  png) codec=(--codec png --png-compression fast) ;;
  bc7) codec=(--codec bc7 --bc7-effort ultra-fast) ;;
  *) codec=(--codec "$2") ;;
esac
bin=${VORTEX:-$WORK/bin/vortex-tiler}
[ -x "$bin" ] || { echo "error: $bin is missing: run bench/split-matrix.sh first (or set VORTEX)" >&2; exit 1; }
cat "$src" >/dev/null # in the page cache
rm -f "$OUT/profile.vtpk"
sync
perf record -q -F 999 -o "$WORK/profile.data" -- "$bin" split "$src" --pack "$OUT/profile.vtpk" --force \
  --tile-size 256 --border 0 "${codec[@]}" --json >"$WORK/profile.json"
rm -f "$OUT/profile.vtpk"
perf script -i "$WORK/profile.data" -F comm,tid,time,ip,sym 2>/dev/null | python3 -c '
import collections, json, sys
HZ = 999
run = json.load(open(sys.argv[1]))
mpx = run["width"] * run["height"] / 1e6
threads, symbols, buckets = collections.Counter(), collections.defaultdict(collections.Counter), collections.Counter()
names, start = {}, None
for line in sys.stdin:
    parts = line.split()
    if len(parts) < 3:
        continue
    # comm tid time: ip sym (the thread name may hold spaces: the tid is the first number)
    i = next(k for k, p in enumerate(parts) if p.isdigit())
    comm, tid, t = " ".join(parts[:i]), parts[i], float(parts[i + 1].rstrip(":"))
    sym = " ".join(parts[i + 3:]) or "?"
    start = t if start is None else start
    names[tid] = comm
    threads[tid] += 1
    symbols[tid][sym] += 1
    buckets[int((t - start) * 10)] += 1
total = sum(threads.values()) / HZ
print(f"{total:.2f} s of CPU sampled, {total / mpx * 1e3:.1f} ms per source Mpx")
for tid, n in threads.most_common():
    if n < HZ // 20:
        continue
    top = ", ".join(f"{s[:48]} {c / n:.0%}" for s, c in symbols[tid].most_common(4))
    print(f"  {names[tid]:>14} {n / HZ:5.2f} s: {top}")
print("cores busy per 100 ms:", " ".join(f"{buckets[b] / (HZ / 10):.1f}" for b in range(max(buckets) + 1)))
' "$WORK/profile.json"
