#!/usr/bin/env bash
# bench/pack-vs-vips.sh: `vortex-tiler split --pack` against `vips dzsave` at GPU page sizes.
#
# The 16384 x 16384 RGB BigTIFF of bench/split-vs-vips.sh (generated if missing) is cut into
# 128-texel pages with a 4-texel border (a 120-texel payload, as in id Tech 5), JPEG Q85, every
# LOD: vortex-tiler writes one pack file (with `--filter box`, levels averaged in stored values
# as vips does, and with its default filter, linear-premultiplied), vips writes one file per
# tile (`--tile-size 120 --overlap 4`, 128-pixel files). Runs alternate RUNS times (default 5), each
# under /usr/bin/time -v, into fresh outputs deleted only at the end (see split-vs-vips.sh on
# ext4 and recently deleted inodes). Medians go into docs/benchmarks.md (or $DOC).
#     bench/pack-vs-vips.sh
set -euo pipefail
cd "$(dirname "$0")/.."
source bench/lib.sh
RUNS=${RUNS:-5}
bench_setup
cd "$WORK"
cat src16k.tif >/dev/null # page cache
OUT=$WORK/out-pack
rm -rf "$OUT"
mkdir -p "$OUT"
RESULTS=$WORK/pack-results.tsv # tool run wall_s rss_kib output_bytes
: >"$RESULTS"
for run in $(seq 1 "$RUNS"); do
  read -r wall rss < <(measure vortex.log bin/vortex-tiler split src16k.tif --pack "$OUT/v$run.vtpk" --tile-size 128 --border 4 --codec jpeg --quality 85 --filter box -q)
  printf 'vortex\t%s\t%s\t%s\t%s\n' "$run" "$wall" "$rss" "$(stat -c %s "$OUT/v$run.vtpk")" >>"$RESULTS"
  log "vortex run $run: $wall s, $((rss / 1024)) MiB"
  read -r wall rss < <(measure vortex-default.log bin/vortex-tiler split src16k.tif --pack "$OUT/w$run.vtpk" --tile-size 128 --border 4 --codec jpeg --quality 85 -q)
  printf 'vortex-default\t%s\t%s\t%s\t%s\n' "$run" "$wall" "$rss" "$(stat -c %s "$OUT/w$run.vtpk")" >>"$RESULTS"
  log "vortex-default run $run: $wall s, $((rss / 1024)) MiB"
  read -r wall rss < <(measure vips.log vips dzsave src16k.tif "$OUT/d$run" --tile-size 120 --overlap 4 --suffix '.jpg[Q=85]')
  printf 'vips\t%s\t%s\t%s\t%s\n' "$run" "$wall" "$rss" "$(du -sb "$OUT/d${run}_files" | cut -f1)" >>"$RESULTS"
  log "vips run $run: $wall s, $((rss / 1024)) MiB"
done
TILES=$(find "$OUT/d${RUNS}_files" -type f | wc -l)
INFO=$(bin/vortex-tiler info "$OUT/v$RUNS.vtpk" | sed -n '/^ *lod /,$p') # level table and contents
rm -rf "$OUT"
sync
touch .cleaned

m() { median "$RESULTS" "$@"; }
VW=$(m vips 3) VR=$(m vips 4) OW=$(m vortex 3) OR=$(m vortex 4) DW=$(m vortex-default 3) DR=$(m vortex-default 4)
REPORT=$WORK/pack-report.md
{
  echo "Run $(date -u '+%Y-%m-%d %H:%M UTC'), $RUNS alternating runs; $(nproc) cores; $(vips --version); vortex-tiler at $REV."
  echo
  echo "| tool | output | median wall s | Mpx/s | peak RSS MiB | output MiB | throughput vs vips | memory vs vips |"
  echo "|---|---|---:|---:|---:|---:|---:|---:|"
  echo "| vortex-tiler split --pack --filter box | 1 file | $(calc %.2f "$OW") | $(calc %.1f "268.4355 / $OW") | $(calc %.0f "$OR / 1024") | $(calc %.1f "$(m vortex 5) / 1048576") | $(calc %.2fx "$VW / $OW") | $(calc %.2fx "$OR / $VR") |"
  echo "| vortex-tiler split --pack (default filter, linear-premultiplied) | 1 file | $(calc %.2f "$DW") | $(calc %.1f "268.4355 / $DW") | $(calc %.0f "$DR / 1024") | $(calc %.1f "$(m vortex-default 5) / 1048576") | $(calc %.2fx "$VW / $DW") | $(calc %.2fx "$DR / $VR") |"
  echo "| vips dzsave | $TILES files | $(calc %.2f "$VW") | $(calc %.1f "268.4355 / $VW") | $(calc %.0f "$VR / 1024") | $(calc %.1f "$(m vips 5) / 1048576") | 1.00x | 1.00x |"
  echo
  echo "The pack's level table and contents (\`vortex-tiler info\`, last run of \`--filter box\`); vips's $TILES files include its levels below one tile (down to 1x1):"
  echo
  echo '```'
  echo "$INFO"
  echo '```'
  echo
  echo "<details><summary>Raw runs (tool, run, wall s, peak RSS KiB, output bytes)</summary>"
  echo
  sed 's/^/    /' "$RESULTS"
  echo
  echo "</details>"
} >"$REPORT"
splice pack-vs-vips "$REPORT" "$(printf '## split --pack against vips dzsave at 128-texel pages\n\nvortex-tiler runs with `--filter box` (levels averaged in stored values, as vips does) and with its default filter, `linear-premultiplied`. Reproduce with `bench/pack-vs-vips.sh`.')"
cat "$REPORT"
