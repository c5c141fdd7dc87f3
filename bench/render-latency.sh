#!/usr/bin/env bash
# bench/render-latency.sh: frame CPU time with and without slow reads (issue 16: the runtime never
# stalls).
#
# The 16384² pack of bench/render-scenes.sh (136-texel tiles, 4-texel border; made if missing) is
# rendered headless along the built-in plane scene and bench/scenes/zoom.json three ways:
#   offline                 each frame waits for the pages the previous one asked for;
#   real-time               no frame waits: pages are drawn when the loader has them;
#   real-time, 50 ms reads  the same with `--io-latency 50ms`: every page read takes 50 ms more.
# From each report: p50 and p99 of the frames' cpu_ms (recording and submitting the frame and
# Runtime::end_frame, without the wait for the picture, which a headless run reads back only
# when asked) and the longest (the timing the tests leave to this script: a busy machine must
# not fail a test, so crates/vortex-vt-wgpu/tests/it/latency.rs shows without a clock that
# frames go on while reads are held), the longest io_wait_ms (time a frame waited for pages),
# the frames that still
# fell back, and the frames to converge once the camera is still. Every run is 400 frames (the
# scenes' paths end by frame 44; the rest is a still camera, long enough for 50 ms reads to
# land while frames run at a few milliseconds each). 8 loader threads (the most
# `render` allows on 2 cores), as slow reads want more threads than cores. Results go to
# docs/benchmarks.md (or $DOC) between `<!-- render-latency:begin -->` and `:end -->`.
#     bench/render-latency.sh
set -euo pipefail
cd "$(dirname "$0")/.."
source bench/lib.sh
bench_setup
PACK=$(world_pack)
REPORT=$WORK/latency-report.md
{
  echo "$(date -u +%F), $(nproc) cores, rev $REV; pack: src16k.tif at 136-texel tiles, 4-texel border, JPEG Q85."
  echo
  echo "| scene | pacing | reads | frames | frame CPU p50 | p99 | longest | longest wait for pages | frames falling back | frames to converge |"
  echo "|---|---|---|---|---:|---:|---:|---:|---:|---|"
} >"$REPORT"
for scene in default bench/scenes/zoom.json; do
  for mode in offline real-time latency; do
    args=(--pack "$PACK" --frame-count 400 -q)
    [ "$scene" != default ] && args+=(--scene "$ROOT/$scene")
    case $mode in
      offline) args+=(--pacing offline) ;;
      real-time) args+=(--pacing real-time) ;;
      latency) args+=(--io-latency 50ms) ;;
    esac
    json=$WORK/latency-$(basename "$scene" .json)-$mode.json
    "$WORK/bin/vortex-tiler" render "${args[@]}" --threads 8 --report "$json" --force
    python3 - "$json" "$scene" "$mode" >>"$REPORT" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
scene, mode = sys.argv[2], sys.argv[3]
reads = "+50 ms" if mode == "latency" else "as stored"
falling = sum(1 for f in r["frames"] if f["fallback_fraction"] > 0)
conv = r["frames_to_converge"]
longest = max(f["cpu_ms"] for f in r["frames"])
print(f"| {scene} | {r['pacing']} | {reads} | {len(r['frames'])} | {r['cpu_ms_p50']:.2f} ms | {r['cpu_ms_p99']:.2f} ms | {longest:.2f} ms "
      f"| {r['io_wait_ms_max']:.1f} ms | {falling} | {'never' if conv is None else conv} (still from frame {r['still_from']}) |")
PY
    log "$scene $mode done"
  done
done
echo >>"$REPORT"
echo "Adapter: $(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['adapter'])" "$WORK/latency-default-offline.json")." >>"$REPORT"
splice render-latency "$REPORT" "## Slow reads: frame CPU time with and without latency (\`bench/render-latency.sh\`)"
cat "$REPORT"
