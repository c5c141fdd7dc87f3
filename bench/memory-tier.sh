#!/usr/bin/env bash
# bench/memory-tier.sh: what the memory tier saves when a view comes back (issue 17).
#
# bench/scenes/away-and-back.json over the 16384² pack of bench/render-scenes.sh (136-texel tiles,
# 4-texel border, JPEG; made if missing, or PACK=PATH to use one already made): a window looks at
# region A, flies to region B at the other corner, stays, and flies back to A, with a cache of 8²
# slots, so that B's pages evict A's. Every page read takes 20 ms more (`--io-latency 20ms`, a
# slow disk or a network share). Two runs, the memory tier on (64 MiB) and off (0), each 200
# frames in real time (frames never wait; the scene's path ends at frame 64, the rest is the
# still camera at A): from each report, the bytes read and the tier's hits and misses, all told
# and on the way back (frames 48 on, when the camera leaves B), the frames that fell back on the
# way back, and the frames to converge once the camera is still at A; for the tier, the RAM it
# held at the end. 8 loader threads. Results go to docs/benchmarks.md (or $DOC) between
# `<!-- memory-tier:begin -->` and `:end -->`.
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
  echo "$(date -u +%F), $(nproc) cores, rev $REV; pack: $(basename "$PACK") (16384², 136-texel tiles, 4-texel border, JPEG), every read +20 ms."
  echo
  echo "| memory tier | bytes read | on the way back | tier hits / misses | on the way back | frames falling back on the way back | frames to converge at A | tier RAM at the end |"
  echo "|---|---:|---:|---:|---:|---:|---|---:|"
} >"$REPORT"
for tier in 64 0; do
  json=$WORK/memory-tier-$tier.json
  "$WORK/bin/vortex-tiler" render --pack "$PACK" --scene "$ROOT/bench/scenes/away-and-back.json" --frame-count 200 \
    --io-latency 20ms --threads 8 --memory-tier "$tier" --report "$json" --force -q
  python3 - "$json" "$tier" >>"$REPORT" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
back = [f for f in r["frames"] if f["frame"] >= 48]
mib = lambda b: f"{b / 2**20:.1f} MiB"
conv = r["frames_to_converge"]
tier = f"{sys.argv[2]} MiB" if sys.argv[2] != "0" else "off"
print(f"| {tier} | {mib(r['bytes_read'])} | {mib(sum(f['bytes_read'] for f in back))} "
      f"| {r['tier_hits']} / {r['tier_misses']} | {sum(f['tier_hits'] for f in back)} / {sum(f['tier_misses'] for f in back)} "
      f"| {sum(1 for f in back if f['fallback_fraction'] > 0)} | {'never' if conv is None else conv} "
      f"| {mib(r['memory_tier_held'])} |")
PY
  log "memory tier $tier done"
done
echo >>"$REPORT"
echo "Adapter: $(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['adapter'])" "$WORK/memory-tier-0.json")." >>"$REPORT"
splice memory-tier "$REPORT" "## Memory tier: a view that comes back (\`bench/memory-tier.sh\`)"
cat "$REPORT"
