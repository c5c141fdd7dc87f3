#!/usr/bin/env bash
# bench/render-scenes.sh: the standard scenes through `vortex-tiler render` over a 16384² pack.
#
# The 16384 x 16384 BigTIFF of bench/split-vs-vips.sh (generated if missing) is packed into
# 136-texel tiles with a 4-texel border (128-texel pages: 128 x 128 pages at LOD 0, 8 LODs,
# 21,845 pages), then each scene is rendered headless (lavapipe where there is no GPU) with its
# report: the built-in plane (zoom and pan, then still), docs/scene-example.json (terrain and a
# box, trilinear) and bench/scenes/zoom.json (a 2D viewer zooming 50x into one spot). Reports
# frames to converge, pages touched of all pages, bytes read, time per frame and peak memory
# into docs/benchmarks.md (or $DOC).
#     bench/render-scenes.sh
set -euo pipefail
cd "$(dirname "$0")/.."
source bench/lib.sh
bench_setup
PACK=$(world_pack)
REPORT=$WORK/render-report.md
{
  echo "$(date -u +%F), $(nproc) cores, rev $REV."
  echo "Pack: src16k.tif at 136-texel tiles, 4-texel border, JPEG Q85 ($(calc '%.0f' "$(stat -c %s "$PACK") / 1048576") MiB)."
  echo
  echo "| scene | size | frames | ms/frame | peak RSS | pages touched / total | MiB read | most loads in a frame | frames to converge |"
  echo "|---|---|---|---|---|---|---|---|---|"
} >"$REPORT"
for scene in default docs/scene-example.json bench/scenes/zoom.json; do
  args=()
  [ "$scene" != default ] && args=(--scene "$ROOT/$scene")
  json=$WORK/render-$(basename "$scene" .json).json
  read -r wall rss < <(measure "$WORK/render.log" "$WORK/bin/vortex-tiler" render --pack "$PACK" "${args[@]}" --report "$json" -q)
  log "$scene: $wall s, $((rss / 1024)) MiB"
  python3 - "$json" "$scene" "$wall" "$rss" >>"$REPORT" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
scene, wall, rss = sys.argv[2], float(sys.argv[3]), int(sys.argv[4])
n = len(r["frames"])
conv = r["frames_to_converge"]
print(f"| {scene} | {r['size'][0]}x{r['size'][1]} | {n} | {wall * 1000 / n:.1f} | {rss // 1024} MiB "
      f"| {r['pages_touched']} / {r['pages_total']} ({100 * r['pages_touched'] / r['pages_total']:.2f}%) "
      f"| {r['bytes_read'] / 1048576:.1f} | {max(f['loaded'] for f in r['frames'])} "
      f"| {'never' if conv is None else conv} (camera still from frame {r['still_from']}) |")
PY
done
echo >>"$REPORT"
echo "Adapter: $(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['adapter'])" "$WORK/render-default.json")." >>"$REPORT"
splice render-scenes "$REPORT" "## The standard scenes through the runtime (\`bench/render-scenes.sh\`)"
cat "$REPORT"
