#!/usr/bin/env bash
# bench/wide-images.sh: very wide and very tall images, in bounded memory (issue 13).
#
# What it measures (results go to docs/benchmarks.md between the wide-images markers):
#   Case 1, a 200000 x 2000 RGB PNG (gen_image of crates/vortex-bench: gradients, zone plate, discs, noise)
#   cut into 256-texel JPEG tiles at quality 85, RUNS times alternately
#     - with the default --max-memory (1G): one band over the whole width;
#     - with --max-memory 64M: vertical stripes of the fine LODs and one coarse pass;
#   each under /usr/bin/time -v (wall clock, peak RSS; medians), and the two outputs compared
#   file by file (`cmp` of every tile and info.json): they must be identical.
#   Case 2, a 16000000 x 1 and a 1 x 16000000 RGB PNG into a pack (`--pack`, 256-texel JPEG,
#   default --max-memory), once each: wall, peak RSS, tiles, stripes.
#
# Usage, from the repository root:
#     bench/wide-images.sh            # RUNS=3 by default
# Works in bench/work/ (git-ignored); the generated images stay there between runs.
set -euo pipefail

cd "$(dirname "$0")/.."
source bench/lib.sh
RUNS=${RUNS:-3}

[ -x /usr/bin/time ] || { export DEBIAN_FRONTEND=noninteractive; apt-get update -qq && apt-get install -y -qq time >/dev/null; }
cargo build --release --quiet
cargo build --release --quiet -p vortex-bench --bin gen_image
REV="$(git rev-parse --short HEAD)$(git diff --quiet HEAD -- src crates Cargo.toml Cargo.lock || echo +uncommitted)"
mkdir -p "$WORK/bin"
cp target/release/vortex-tiler target/release/gen_image "$WORK/bin/"
VT=$WORK/bin/vortex-tiler

for spec in 200000x2000 16000000x1 1x16000000; do
  if [ ! -s "$WORK/wide-$spec.png" ]; then
    log "generating wide-$spec.png"
    "$WORK/bin/gen_image" "${spec%x*}" "${spec#*x}" "$WORK/part.png"
    mv "$WORK/part.png" "$WORK/wide-$spec.png"
  fi
done

OUT=$WORK/out-wide
rm -rf "$OUT"
mkdir -p "$OUT"
RAW=$WORK/wide-runs.tsv
: >"$RAW"
JPEG=(--tile-size 256 --border 0 --codec jpeg --quality 85)

# summary LOG: vortex-tiler's summary line (printed without --quiet).
summary() { grep '^wrote' "$1"; }

for run in $(seq 1 "$RUNS"); do
  for mode in band stripes; do
    flags=()
    [ "$mode" = stripes ] && flags=(--max-memory 64M)
    log "200000x2000 $mode run $run"
    read -r wall rss < <(measure "$OUT/$mode-$run.log" "$VT" split "$WORK/wide-200000x2000.png" -o "$OUT/$mode-$run" "${JPEG[@]}" --quiet "${flags[@]}")
    printf '%s\t%s\t%s\t%s\n' "$mode" "$run" "$wall" "$rss" >>"$RAW"
  done
done
# One more run of each with the summary line, for the tile and stripe counts.
"$VT" split "$WORK/wide-200000x2000.png" -o "$OUT/band-line" "${JPEG[@]}" >"$OUT/band-line.log"
"$VT" split "$WORK/wide-200000x2000.png" -o "$OUT/stripes-line" "${JPEG[@]}" --max-memory 64M >"$OUT/stripes-line.log"
diff -r "$OUT/band-1" "$OUT/stripes-1" >/dev/null || { echo "stripes differ from one band" >&2; exit 1; }
files=$(find "$OUT/band-1" -type f | wc -l)

declare -A line
for spec in 16000000x1 1x16000000; do
  log "$spec into a pack"
  read -r wall rss < <(measure "$OUT/$spec.log" "$VT" split "$WORK/wide-$spec.png" --pack "$OUT/$spec.vtpk" "${JPEG[@]}")
  line[$spec]="$wall $rss"
done

REPORT=$WORK/wide-report.md
{
  echo "Run $(date -u '+%Y-%m-%d %H:%M') UTC, vortex-tiler at $REV, $RUNS alternating runs per mode; machine: $(nproc) cores, $(awk '/MemTotal/ { printf "%.0f GiB", $2 / 1048576 }' /proc/meminfo) RAM."
  echo
  echo "200000 x 2000 RGB 8-bit PNG (400 Mpx), 256-texel JPEG tiles at Q85, into a directory:"
  echo
  echo "| mode | median wall s | peak RSS MiB (median) | source reads |"
  echo "|---|---:|---:|---:|"
  for mode in band stripes; do
    reads=$(grep -o 'source read [0-9]* times' "$OUT/$mode-line.log" | grep -o '[0-9]*' || echo 1)
    label="one band (default --max-memory 1G)"
    [ "$mode" = stripes ] && label="--max-memory 64M: $(grep -o '[0-9]* vertical stripes' "$OUT/$mode-line.log") + coarse pass"
    printf '| %s | %s | %s | %s |\n' "$label" "$(median "$RAW" "$mode" 3)" "$(calc %.0f "$(median "$RAW" "$mode" 4) / 1024")" "${reads:-1}"
  done
  echo
  echo "Both write the same $files files, byte for byte (\`diff -r\`). Summary lines:"
  echo
  echo '```'
  summary "$OUT/band-line.log"
  summary "$OUT/stripes-line.log"
  echo '```'
  echo
  echo "Lines of one texel, into a pack (256-texel JPEG, default --max-memory), one run each:"
  echo
  echo "| image | wall s | peak RSS MiB |"
  echo "|---|---:|---:|"
  for spec in 16000000x1 1x16000000; do
    read -r wall rss <<<"${line[$spec]}"
    printf '| %s | %s | %s |\n' "${spec/x/ x }" "$wall" "$(calc %.0f "$rss / 1024")"
  done
  echo
  echo '```'
  for spec in 16000000x1 1x16000000; do summary "$OUT/$spec.log"; done
  echo '```'
} >"$REPORT"
splice wide-images "$REPORT" "## Wide and tall images

\`bench/wide-images.sh\` cuts a 200000 x 2000 scan with one band and in vertical stripes under
\`--max-memory 64M\` (same tiles, byte for byte), and one-texel lines of 16,000,000 texels each
way. Reproduce from the repository root with \`bench/wide-images.sh\`."
rm -rf "$OUT"
log "done: $DOC"
