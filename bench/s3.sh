#!/usr/bin/env bash
# bench/s3.sh: `split` straight to S3 against the same run to local disk (issue 47's goal: at
# least 0.8x the local throughput).
#
# The 16384² strip BigTIFF of bench/lib.sh (in the page cache) cut into Deep Zoom (254-texel
# tiles, overlap 1: 5,730 files, one PUT each) and into a pack (256-texel pages with the default
# border of 1: one multipart upload), JPEG Q85, each
# written to local disk and to two S3 servers on 127.0.0.1, RUNS times alternating (default
# 3); medians of the wall time, our CPU time, the server's CPU time and our peak RSS. The local
# Deep Zoom runs write to a new ext4 each where root can (bench/lib.sh's new_ext4: on this
# machine's disk, creating files just after others were deleted measures that deletion too).
# The servers share the two cores with us, so the S3 rows measure our uploading and that
# server's cost together; a real bucket is over a network instead. The two:
# - moto (Python; objects in memory), the server of the tests: from VORTEX_MOTO (the bin/ of a
#   venv with `moto[server]` and boto3, as .ci/run makes in target/moto), else installed into
#   bench/work/moto the first time;
# - s3s-fs (Rust; objects as files on local disk, crates.io, Apache-2.0), installed into
#   bench/work/s3s-fs with `cargo install` the first time (some 3 minutes): a server whose own
#   cost is small, so that its rows show ours.
# Results go to docs/object-storage.md (or $DOC) between `<!-- s3:begin -->` and `<!-- s3:end -->`.
#     bench/s3.sh           # about 6 minutes on 2 quiet cores (and 3 to install s3s-fs)
set -euo pipefail
cd "$(dirname "$0")/.."
DOC=${DOC:-$PWD/docs/object-storage.md}
source bench/lib.sh
RUNS=${RUNS:-3}
splice_check s3
bench_setup

MOTO=${VORTEX_MOTO:-$WORK/moto/bin}
if ! "$MOTO/python" -c 'import moto.server, boto3' 2>/dev/null; then
  [ -z "${VORTEX_MOTO:-}" ] || { echo "error: VORTEX_MOTO=$VORTEX_MOTO has no moto.server and boto3" >&2; exit 1; }
  log "installing moto[server] and boto3 into $WORK/moto"
  python3 -m venv "$WORK/moto" && "$WORK/moto/bin/pip" install -q 'moto[server]' boto3
fi
# s3s-fs 0.14.1: the last release that builds with Rust 1.95 (0.17 needs 1.96).
S3S=$WORK/s3s-fs/bin/s3s-fs
if [ ! -x "$S3S" ]; then
  log "installing s3s-fs into $WORK/s3s-fs"
  cargo install -q s3s-fs@0.14.1 --features binary --locked --root "$WORK/s3s-fs"
fi
S=$WORK/s3
rm -rf "$S" && mkdir -p "$S/s3s-root/bench"
free_port() { python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'; }
MOTO_PORT=$(free_port)
"$MOTO/moto_server" -H 127.0.0.1 -p "$MOTO_PORT" >"$S/moto.log" 2>&1 &
MOTO_PID=$!
S3S_PORT=$(free_port)
"$S3S" --host 127.0.0.1 --port "$S3S_PORT" --access-key bench --secret-key bench "$S/s3s-root" >"$S/s3s.log" 2>&1 &
S3S_PID=$!
MNT=
! can_mount || MNT=$S/mnt
trap 'kill $MOTO_PID $S3S_PID 2>/dev/null || true; [ -z "$MNT" ] || drop_ext4 "$MNT"' EXIT
export AWS_ACCESS_KEY_ID=bench AWS_SECRET_ACCESS_KEY=bench AWS_REGION=us-east-1 AWS_ALLOW_HTTP=true
for port in "$MOTO_PORT" "$S3S_PORT"; do
  until python3 -c "import socket; socket.create_connection(('127.0.0.1', $port))" 2>/dev/null; do sleep 0.2; done
done
AWS_ENDPOINT_URL=http://127.0.0.1:$MOTO_PORT "$MOTO/python" -c 'import boto3; boto3.client("s3").create_bucket(Bucket="bench")'

SRC=$WORK/src16k.tif
cat "$SRC" >/dev/null # in the page cache: the runs measure writing
RAW=$S/runs.tsv # output to run wall_s cpu_s server_cpu_s rss_kib
: >"$RAW"
# server_cpu PID: a server's CPU seconds so far (user + system, from /proc).
server_cpu() { awk -v hz="$(getconf CLK_TCK)" '{ printf "%.2f", ($14 + $15) / hz }' "/proc/$1/stat"; }

for run in $(seq "$RUNS"); do
  log "run $run"
  for output in dzi pack; do
    for to in local moto s3s; do
      case $output-$to in
        dzi-local)
          dest=$S/local-$run
          [ -z "$MNT" ] || { new_ext4 "$MNT"; dest=$MNT/dz; }
          args=(--layout dzi -o "$dest" --tile-size 254 --overlap 1)
          ;;
        dzi-*) args=(--layout dzi -o "s3://bench/dz-$run" --tile-size 254 --overlap 1) ;;
        pack-local) args=(--pack "$S/local-$run.vtpk" --tile-size 256) ;;
        pack-*) args=(--pack "s3://bench/pack-$run.vtpk" --tile-size 256) ;;
      esac
      case $to in
        moto) pid=$MOTO_PID port=$MOTO_PORT ;;
        s3s) pid=$S3S_PID port=$S3S_PORT ;;
        *) pid= port= ;;
      esac
      sync
      before=0
      [ -z "$pid" ] || before=$(server_cpu "$pid")
      AWS_ENDPOINT_URL=http://127.0.0.1:$port /usr/bin/time -f '%e %U %S %M' -o "$S/time.txt" \
        "$WORK/bin/vortex-tiler" split "$SRC" "${args[@]}" --quality 85 -q
      read -r wall user sys rss <"$S/time.txt"
      server=0
      [ -z "$pid" ] || server=$(calc %.2f "$(server_cpu "$pid") - $before")
      printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$output" "$to" "$run" "$wall" "$(calc %.2f "$user + $sys")" \
        "$server" "$rss" >>"$RAW"
      [ "$to" != local ] || { rm -rf "$S/local-$run" "$S/local-$run.vtpk"; [ -z "$MNT" ] || drop_ext4 "$MNT"; }
    done
  done
done

REPORT=$S/report.md
python3 - "$RAW" "$REV" "$("$MOTO/python" -c 'import moto; print(moto.__version__)')" >"$REPORT" <<'PY'
import statistics, sys, datetime, os
raw, rev, moto = sys.argv[1:4]
runs = {}
for line in open(raw):
    output, to, run, wall, cpu, server, rss = line.split("\t")
    runs.setdefault((output, to), []).append((float(wall), float(cpu), float(server), int(rss)))
med = lambda key, i: statistics.median(r[i] for r in runs[key])
print(f"{datetime.date.today()}, {os.cpu_count()} cores, vortex-tiler {rev}, moto {moto} and s3s-fs 0.14.1 on 127.0.0.1;"
      " the 16384² strip BigTIFF, JPEG tiles (Q85): Deep Zoom's 254 texels with an overlap of 1, the pack's 256 with a border of 1;"
      " medians of the runs.")
print()
print("| output | to | wall | our CPU | the server's CPU | peak RSS | throughput vs local |")
print("|---|---|---:|---:|---:|---:|---:|")
for output, name in (("dzi", "Deep Zoom (5,730 files)"), ("pack", "pack")):
    for to, where in (("local", "local disk"), ("moto", "S3: moto"), ("s3s", "S3: s3s-fs")):
        key = (output, to)
        if key not in runs:
            continue
        vs = med((output, "local"), 0) / med(key, 0)
        print(f"| {name} | {where} | {med(key, 0):.2f} s | {med(key, 1):.2f} s "
              f"| {med(key, 2):.2f} s | {med(key, 3) / 1024:.0f} MiB | {vs:.2f}x |")
PY
cat "$REPORT"
splice s3 "$REPORT" ""
