#!/usr/bin/env bash
# bench/s3.sh: `split` straight to S3 against the same run to local disk (issue 47's goal: at
# least 0.8x the local throughput).
#
# The 16384² strip BigTIFF of bench/lib.sh (in the page cache) cut into Deep Zoom (254-texel
# tiles, overlap 1: 5,730 files, one PUT each) and into a pack (256-texel pages with the default
# border of 1: one multipart upload), JPEG Q85, each
# written to local disk and to moto's S3 server on 127.0.0.1, RUNS times alternating (default
# 3); medians of the wall time, our CPU time, the server's CPU time and our peak RSS. The local
# Deep Zoom runs write to a new ext4 each where root can (bench/lib.sh's new_ext4: on this
# machine's disk, creating files just after others were deleted measures that deletion too).
# moto keeps objects in memory and shares the two cores with us, so the S3 rows measure our
# uploading and that server's cost together; a real bucket is over a network instead.
# moto comes from VORTEX_MOTO (the bin/ of a venv with `moto[server]` and boto3, as .ci/run
# makes in target/moto), else it is installed into bench/work/moto the first time.
# Results go to docs/object-storage.md (or $DOC) between `<!-- s3:begin -->` and `<!-- s3:end -->`.
#     bench/s3.sh           # about 3 minutes on 2 quiet cores
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
S=$WORK/s3
mkdir -p "$S"
PORT=$(python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
"$MOTO/moto_server" -H 127.0.0.1 -p "$PORT" >"$S/moto.log" 2>&1 &
SERVER=$!
MNT=
! can_mount || MNT=$S/mnt
trap 'kill $SERVER 2>/dev/null || true; [ -z "$MNT" ] || drop_ext4 "$MNT"' EXIT
export AWS_ENDPOINT_URL=http://127.0.0.1:$PORT AWS_ACCESS_KEY_ID=bench AWS_SECRET_ACCESS_KEY=bench AWS_REGION=us-east-1 \
  AWS_ALLOW_HTTP=true
until python3 -c "import socket; socket.create_connection(('127.0.0.1', $PORT))" 2>/dev/null; do sleep 0.2; done
"$MOTO/python" -c 'import boto3; boto3.client("s3").create_bucket(Bucket="bench")'

SRC=$WORK/src16k.tif
cat "$SRC" >/dev/null # in the page cache: the runs measure writing
RAW=$S/runs.tsv # output to run wall_s cpu_s server_cpu_s rss_kib
: >"$RAW"
# server_cpu: the moto server's CPU seconds so far (user + system, from /proc).
server_cpu() { awk -v hz="$(getconf CLK_TCK)" '{ printf "%.2f", ($14 + $15) / hz }' "/proc/$SERVER/stat"; }

for run in $(seq "$RUNS"); do
  log "run $run"
  for output in dzi pack; do
    for to in local s3; do
      case $output-$to in
        dzi-local)
          dest=$S/local-$run
          [ -z "$MNT" ] || { new_ext4 "$MNT"; dest=$MNT/dz; }
          args=(--layout dzi -o "$dest" --tile-size 254 --overlap 1)
          ;;
        dzi-s3) args=(--layout dzi -o "s3://bench/dz-$run" --tile-size 254 --overlap 1) ;;
        pack-local) args=(--pack "$S/local-$run.vtpk" --tile-size 256) ;;
        pack-s3) args=(--pack "s3://bench/pack-$run.vtpk" --tile-size 256) ;;
      esac
      sync
      before=$(server_cpu)
      /usr/bin/time -f '%e %U %S %M' -o "$S/time.txt" "$WORK/bin/vortex-tiler" split "$SRC" "${args[@]}" --quality 85 -q
      read -r wall user sys rss <"$S/time.txt"
      printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$output" "$to" "$run" "$wall" "$(calc %.2f "$user + $sys")" \
        "$(calc %.2f "$(server_cpu) - $before")" "$rss" >>"$RAW"
      [ "$to" = s3 ] || { rm -rf "$S/local-$run" "$S/local-$run.vtpk"; [ -z "$MNT" ] || drop_ext4 "$MNT"; }
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
print(f"{datetime.date.today()}, {os.cpu_count()} cores, vortex-tiler {rev}, moto {moto} on 127.0.0.1;"
      " the 16384² strip BigTIFF, JPEG tiles (Q85): Deep Zoom's 254 texels with an overlap of 1, the pack's 256 with a border of 1;"
      " medians of the runs.")
print()
print("| output | to | wall | our CPU | the server's CPU | peak RSS | throughput vs local |")
print("|---|---|---:|---:|---:|---:|---:|")
for output, name in (("dzi", "Deep Zoom (5,730 files)"), ("pack", "pack")):
    for to in ("local", "s3"):
        key = (output, to)
        if key not in runs:
            continue
        vs = med((output, "local"), 0) / med(key, 0)
        print(f"| {name} | {'local disk' if to == 'local' else 'S3 (moto)'} | {med(key, 0):.2f} s | {med(key, 1):.2f} s "
              f"| {med(key, 2) if to == 's3' else 0:.2f} s | {med(key, 3) / 1024:.0f} MiB | {vs:.2f}x |")
PY
cat "$REPORT"
splice s3 "$REPORT" ""
