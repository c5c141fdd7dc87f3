#!/usr/bin/env bash
# bench/render-layers.sh: what a layer stack costs (issue 17): the built-in plane scene over the
# 16384² JPEG pack (bench/lib.sh world_pack) as one layer, then with one and two data layers
# added. The lossless PNG pack of the same image and grid (bench/transcode-cost.sh makes it)
# stands in for the data layers: what a layer costs is its reads, decoding and uploads, not what
# its texels mean. Offline pacing, so every run loads the same pages; 120 frames each. From each
# report: wall time (the median of 3 runs, after a warm-up run) and that run's peak memory
# (/usr/bin/time -v), frame CPU p50/p99, pages loaded and page-table entries written (both the
# same whatever the layers), bytes read, and frames to converge. Results go to docs/benchmarks.md (or $DOC) between `<!-- render-layers:begin -->`
# and `:end -->`.
#     bench/render-layers.sh
set -euo pipefail
cd "$(dirname "$0")/.."
source bench/lib.sh
bench_setup
PACK=$(world_pack)
DATA=$(world_png_pack)
REPORT=$WORK/layers-report.md
{
  echo "$(date -u +%F), $(nproc) cores, rev $REV; the built-in plane scene, 512x384, 120 frames, offline; layer 0: src16k.tif at 136-texel tiles, 4-texel border, JPEG Q85 (BC1 cache); data layers: the same grid as PNG (RGBA8 caches)."
  echo
  echo "| layers | wall (median of 3) | peak RSS | frame CPU p50 | p99 | pages loaded | page-table entries written | MiB read | frames to converge |"
  echo "|---|---:|---:|---:|---:|---:|---:|---:|---|"
} >"$REPORT"
# A first run reads the packs into the page cache, so that no configuration pays for a cold disk.
"$WORK/bin/vortex-tiler" render --pack "$PACK" --layer "data:$DATA" --frame-count 120 -q --report "$WORK/layers-warm.json" --force
for layers in 1 2 3; do
  args=(--pack "$PACK" --frame-count 120 --pacing offline -q)
  for _ in $(seq 2 "$layers"); do args+=(--layer "data:$DATA"); done
  json=$WORK/layers-$layers.json
  log "$layers layer(s), 3 runs"
  runs=()
  for _ in 1 2 3; do
    runs+=("$(measure "$WORK/layers.log" "$WORK/bin/vortex-tiler" render "${args[@]}" --report "$json" --force)")
  done
  # The run of median wall time (its peak memory with it).
  read -r wall rss < <(printf '%s\n' "${runs[@]}" | sort -g | sed -n 2p)
  python3 - "$json" "$layers" "$wall" "$rss" >>"$REPORT" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
layers, wall, rss = sys.argv[2], float(sys.argv[3]), int(sys.argv[4])
loaded = sum(f["loaded"] for f in r["frames"])
writes = sum(f["table_writes"] for f in r["frames"])
conv = r["frames_to_converge"]
print(f"| {layers} | {wall:.2f} s | {rss / 1024:.0f} MiB | {r['cpu_ms_p50']:.2f} ms | {r['cpu_ms_p99']:.2f} ms | {loaded} | {writes} "
      f"| {r['bytes_read'] / 2**20:.1f} | {'never' if conv is None else conv} |")
PY
done
cat "$REPORT"
splice render-layers "$REPORT" "## Layer stacks: what each layer costs (\`bench/render-layers.sh\`)"
