#!/usr/bin/env bash
# bench/serve.sh: requests per second and latency of `vortex-tiler serve`, measured with oha.
#
# An 8192 x 8192 RGB image (gen_image of crates/vortex-bench, generated once into bench/work) is cut into a
# JPEG Q85 pack of 256-texel pages with a border of 1 (Deep Zoom tiles of 254 + overlap 1, the
# vips default): Deep Zoom level 13 is 33 x 33 tiles. Then, for DURATION (default 10s) at CONNS
# connections (default 32), oha asks the release build for random tiles of level 13 from
#   (a) the 31 x 31 interior tiles: the stored JPEG bytes, straight from the memory map;
#   (b) the 33 tiles of the last column, cropped to 65 texels and re-encoded: with the cache
#       off (--cache 0: every request decodes and encodes) and warm (the default 64M, after
#       one pass over those tiles).
# Prints one line per case and, with SPLICE=1, rewrites the table in docs/benchmarks.md
# between the serve markers. Needs oha (OHA=path, default `oha` on PATH; install it with
# `cargo install oha --locked`) and python3. CARGO_TARGET_DIR is honoured.
#     bench/serve.sh
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
WORK=$ROOT/bench/work
TARGET=${CARGO_TARGET_DIR:-$ROOT/target}
OHA=${OHA:-oha}
DURATION=${DURATION:-10s}
CONNS=${CONNS:-32}
mkdir -p "$WORK"
log() { printf '[%(%H:%M:%S)T] %s\n' -1 "$*" >&2; }

command -v "$OHA" >/dev/null || { echo "error: oha not found (OHA=$OHA); cargo install oha --locked" >&2; exit 1; }
log "building"
cargo build --release --quiet -p vortex-tiler --bin vortex-tiler
cargo build --release --quiet -p vortex-bench --bin gen_image
BIN=$TARGET/release/vortex-tiler
if [ ! -s "$WORK/serve8k.ppm" ]; then
  log "generating serve8k.ppm"
  "$TARGET/release/gen_image" 8192 8192 "$WORK/serve8k.part.ppm"
  mv "$WORK/serve8k.part.ppm" "$WORK/serve8k.ppm"
fi
PACK=$WORK/serve8k.vtpk
if [ ! -s "$PACK" ]; then
  log "splitting into serve8k.vtpk"
  "$BIN" split "$WORK/serve8k.ppm" --pack "$PACK" --tile-size 256 --border 1 --codec jpeg --quality 85 -q
fi

# serve_with FLAGS...: starts the server, sets PORT and PID.
serve_with() {
  "$BIN" serve "$PACK" --addr 127.0.0.1:0 "$@" >"$WORK/serve.out" 2>"$WORK/serve.err" &
  PID=$!
  for _ in $(seq 100); do
    PORT=$(sed -n 's#^serving 1 input on http://127.0.0.1:\([0-9]*\)/$#\1#p' "$WORK/serve.out")
    [ -n "$PORT" ] && return
    sleep 0.1
  done
  echo "error: the server did not start" >&2
  cat "$WORK/serve.err" >&2
  exit 1
}
stop() { kill -TERM "$PID"; wait "$PID"; }

# run NAME URL_REGEX (oha generates URLs from the regex; write dots as [.]): oha for DURATION, one line "NAME rps p50_ms p99_ms success".
run() {
  local name=$1 url=$2
  "$OHA" -z "$DURATION" -c "$CONNS" --no-tui --output-format json --rand-regex-url "$url" >"$WORK/oha-$name.json"
  python3 - "$name" "$WORK/oha-$name.json" <<'PY'
import json, sys
name, path = sys.argv[1], sys.argv[2]
r = json.load(open(path))
s, p = r["summary"], r["latencyPercentiles"]
codes = r.get("statusCodeDistribution", {})
if set(codes) != {"200"}:
    sys.exit(f"error: {name}: answers other than 200: {codes}")
print(f"{name}\t{s['requestsPerSec']:.0f}\t{p['p50'] * 1000:.2f}\t{p['p99'] * 1000:.2f}\t{sum(codes.values())}\t{s.get('sizePerRequest') or 0}")
PY
}

N='([1-9]|[12][0-9]|3[01])'            # interior columns and rows: 1..31
E='([0-9]|[12][0-9]|3[0-2])'           # every row: 0..32
RESULTS=$WORK/serve-results.tsv
: >"$RESULTS"
serve_with
re="http://127[.]0[.]0[.]1:$PORT/serve8k_files/13"
run stored "$re/${N}_${N}[.]jpeg" >>"$RESULTS"
for row in $(seq 0 32); do curl -sf -o /dev/null "http://127.0.0.1:$PORT/serve8k_files/13/32_$row.jpeg"; done # warm the cache
run edge-warm "$re/32_${E}[.]jpeg" >>"$RESULTS"
stop
serve_with --cache 0
re="http://127[.]0[.]0[.]1:$PORT/serve8k_files/13"
run edge-cold "$re/32_${E}[.]jpeg" >>"$RESULTS"
stop
log "results (case, requests/s, p50 ms, p99 ms, responses, all 200, bytes per response):"
cat "$RESULTS"
