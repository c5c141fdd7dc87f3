#!/usr/bin/env bash
# bench/render-remote.sh: a pack streamed over HTTP (issue 32): frames to converge with the pack
# on local disk, on nginx over loopback, and on nginx behind a proxy adding 50 ms to every
# request (crates/vortex-bench's delay_proxy), all real time (no frame waits), 8 loader threads.
# From each report: frames to converge once the camera is still, the longest io_wait_ms (0: no
# frame waited on I/O), frames falling back, and the report's `remote` counters (requests, bytes
# received, reads merged into another's request).
#     bench/render-remote.sh                      the 16384² pack of bench/lib.sh, release build
#     BIN=target/debug/vortex-tiler PROXY=target/debug/delay_proxy PACK=x.vtpk bench/render-remote.sh
#                                                 a given build and pack (no set-up, no splice)
set -euo pipefail
cd "$(dirname "$0")/.."
source bench/lib.sh
if [ -z "${BIN:-}" ]; then
  bench_setup
  cargo build --release --quiet -p vortex-bench --bin delay_proxy
  BIN=$WORK/bin/vortex-tiler PROXY=${CARGO_TARGET_DIR:-$ROOT/target}/release/delay_proxy PACK=$(world_pack)
  SPLICE=1
  WHAT="$(date -u +%F), $(nproc) cores, rev $REV; pack: src16k.tif at 136-texel tiles, 4-texel border, JPEG Q85."
else
  SPLICE=
  WHAT="$(date -u +%F), $(nproc) cores, $BIN; pack: $PACK."
fi
NGINX_DIR=$(mktemp -d)
trap 'kill $(cat "$NGINX_DIR/pids" 2>/dev/null) 2>/dev/null || true; rm -rf "$NGINX_DIR"' EXIT
free_port() { python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'; }
PORT=$(free_port)
PROXY_PORT=$(free_port)
cat >"$NGINX_DIR/nginx.conf" <<CONF
daemon off; master_process off; worker_processes 1; pid $NGINX_DIR/nginx.pid; error_log $NGINX_DIR/error.log;
events { worker_connections 256; }
http { access_log off; client_body_temp_path $NGINX_DIR/b; proxy_temp_path $NGINX_DIR/p;
  fastcgi_temp_path $NGINX_DIR/f; uwsgi_temp_path $NGINX_DIR/u; scgi_temp_path $NGINX_DIR/s;
  server { listen 127.0.0.1:$PORT; root $(dirname "$(realpath "$PACK")"); } }
CONF
/usr/sbin/nginx -p "$NGINX_DIR" -c "$NGINX_DIR/nginx.conf" -e "$NGINX_DIR/error.log" &
echo $! >>"$NGINX_DIR/pids"
"$PROXY" "127.0.0.1:$PROXY_PORT" "127.0.0.1:$PORT" 50 2>/dev/null &
echo $! >>"$NGINX_DIR/pids"
NAME=$(basename "$PACK")
until python3 -c "import socket,sys; [socket.create_connection(('127.0.0.1', int(p))) for p in sys.argv[1:]]" "$PORT" "$PROXY_PORT" 2>/dev/null; do :; done
REPORT=$WORK/remote-report.md
{
  echo "$WHAT"
  echo
  echo "| pack on | frames | frames to converge | longest wait for pages | frames falling back | requests | bytes received | reads merged |"
  echo "|---|---:|---|---:|---:|---:|---:|---:|"
} >"$REPORT"
for where in "local disk:$PACK" "nginx, loopback:http://127.0.0.1:$PORT/$NAME" "nginx +50 ms:http://127.0.0.1:$PROXY_PORT/$NAME"; do
  json=$WORK/remote-${where%%:*}.json
  json=${json// /-}
  "$BIN" render --pack "${where#*:}" --pacing real-time --threads 8 --frame-count 400 -q --report "$json" --force
  python3 - "$json" "${where%%:*}" >>"$REPORT" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
falling = sum(1 for f in r["frames"] if f["fallback_fraction"] > 0)
conv = r["frames_to_converge"]
remote = r.get("remote", {})
get = lambda k, f="{}": f.format(remote[k]) if k in remote else "-"
print(f"| {sys.argv[2]} | {len(r['frames'])} | {'never' if conv is None else conv} (still from frame {r['still_from']}) "
      f"| {r['io_wait_ms_max']:.1f} ms | {falling} | {get('requests')} | {get('bytes', '{:,}')} | {get('merged_reads')} |")
PY
  log "${where%%:*} done"
done
if [ -n "$SPLICE" ]; then
  splice render-remote "$REPORT" "## Remote packs: frames to converge over HTTP (\`bench/render-remote.sh\`)"
fi
cat "$REPORT"
