#!/usr/bin/env bash
# bench/memory-tier.sh: what the memory tier saves when a view comes back (issue 17).
#
# bench/scenes/away-and-back.json over the 16384² pack of bench/render-scenes.sh (136-texel tiles,
# 4-texel border, JPEG; made if missing, or PACK=PATH to use one already made): a window looks at
# region A, flies to region B at the other corner, stays, and flies back to A, with a cache of 8²
# slots, so that B's pages evict A's. Every page read takes 20 ms more (`--io-latency 20ms`, a
# slow disk or a network share). Runs of 200 frames (the scene's path ends at frame 64, the
# rest is the still camera at A), the memory tier on (64 MiB) and off (0), each in real time
# (frames never wait: the picture falls back to coarser pages until reads land; when they land
# varies, so the median of 5 runs) and offline (each frame waits for the pages the previous one
# asked for: the wait is what the reads cost).
# From each report: the bytes read, all told and on the way back (frames 48 on, when the camera
# leaves B), the tier's hits and misses on the way back, the frames that fell back on the way back
# (real time), the time frames waited for reads on the way back (offline), the frames to
# converge once the camera is still at A, and the RAM the tier held at the end. 8 loader threads.
# Results go to docs/benchmarks.md (or $DOC) between `<!-- memory-tier:begin -->` and `:end -->`.
#     bench/memory-tier.sh
#     PACK=../main/bench/work/world16k.vtpk bench/memory-tier.sh
set -euo pipefail
cd "$(dirname "$0")/.."
source bench/lib.sh
if [ -n "${PACK:-}" ]; then
  # A pack made elsewhere: only vortex-tiler is needed.
  log "building"
  cargo build --release --quiet
  mkdir -p "$WORK/bin"
  cp "${CARGO_TARGET_DIR:-$ROOT/target}/release/vortex-tiler" "$WORK/bin/"
  REV="$(git rev-parse --short HEAD)$(git diff --quiet HEAD -- src crates Cargo.toml Cargo.lock || echo +uncommitted)"
else
  bench_setup
  PACK=$(world_pack)
fi
REPORT=$WORK/memory-tier-report.md
{
  echo "$(date -u +%F), $(nproc) cores, rev $REV; pack: $(basename "$PACK") (16384², 136-texel tiles, 4-texel border, JPEG), every read +20 ms; 8 loader threads."
  echo
  echo "| pacing | memory tier | bytes read | on the way back | tier hits / misses on the way back | frames falling back on the way back | waiting for reads on the way back | frames to converge at A | tier RAM at the end |"
  echo "|---|---|---:|---:|---:|---:|---:|---|---:|"
} >"$REPORT"
for pacing in real-time offline; do
  # Real time depends on when reads land: the median of 5 runs. Offline is the same every run.
  runs=1
  [ "$pacing" = real-time ] && runs=5
  for tier in 64 0; do
    jsons=()
    for run in $(seq "$runs"); do
      json=$WORK/memory-tier-$pacing-$tier-$run.json
      "$WORK/bin/vortex-tiler" render --pack "$PACK" --scene "$ROOT/bench/scenes/away-and-back.json" --frame-count 200 \
        --pacing "$pacing" --io-latency 20ms --threads 8 --memory-tier "$tier" --report "$json" --force -q >/dev/null
      jsons+=("$json")
    done
    python3 - "$tier" "${jsons[@]}" >>"$REPORT" <<'PY'
import json, statistics, sys
tier, paths = sys.argv[1], sys.argv[2:]
def row(r):
    back = [f for f in r["frames"] if f["frame"] >= 48]
    conv = r["frames_to_converge"]
    return [r["bytes_read"], sum(f["bytes_read"] for f in back), sum(f["tier_hits"] for f in back),
            sum(f["tier_misses"] for f in back), sum(1 for f in back if f["fallback_fraction"] > 0),
            sum(f["io_wait_ms"] for f in back), float("inf") if conv is None else conv, r["memory_tier_held"]]
reports = [json.load(open(p)) for p in paths]
m = [statistics.median(column) for column in zip(*map(row, reports))]
kib = lambda b: f"{b / 1024:.0f} KiB"
pacing = reports[0]["pacing"] + (f" (median of {len(paths)})" if len(paths) > 1 else "")
print(f"| {pacing} | {tier + ' MiB' if tier != '0' else 'off'} | {kib(m[0])} | {kib(m[1])} | {m[2]:g} / {m[3]:g} "
      f"| {m[4]:g} | {m[5]:.0f} ms | {'never' if m[6] == float('inf') else f'{m[6]:g}'} | {kib(m[7])} |")
PY
    log "$pacing, memory tier $tier done"
  done
done
echo >>"$REPORT"
echo "Adapter: $(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['adapter'])" "$WORK/memory-tier-offline-0.json")." >>"$REPORT"
splice memory-tier "$REPORT" "## Memory tier: a view that comes back (\`bench/memory-tier.sh\`)"
cat "$REPORT"
