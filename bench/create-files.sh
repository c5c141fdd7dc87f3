#!/usr/bin/env bash
# bench/create-files.sh: what creating a tile file costs, and why a Deep Zoom run here paid up to
# 0.7 ms of system time per file (issue 45).
#
# 1. crates/vortex-bench's `create_files`: 4096 files of 20 KB in one directory (a Deep Zoom
#    level's names), by 1 or 2 threads, opened as our tile directories open theirs (O_EXCL) or
#    as libvips does (O_TRUNC); a round into the fresh directory, then one after deleting those
#    files. On three file systems: ext4 with a journal and ext4 without one, each a new 3 GB
#    image made by mkfs.ext4 before every run and mounted through a loop device (as root; left
#    out with a note otherwise), and bench/work's own file system as it is.
# 2. The tools: `split --layout dzi` and libvips 8.18's dzsave (pyvips-binary, direct mode) of
#    the JPEG-tiled BigTIFF of bench/split-matrix.sh (256-texel tiles, no overlap, Q85, the
#    finest level's tiles copied by us) into each new loop file system, then again once that
#    output is deleted, as the benchmarks did between runs: wall, system CPU and system CPU per
#    tile file; and the system calls per tile file (strace -c, one extra run).
# RUNS runs per cell (default 3), alternating; medians. Results go to docs/benchmarks.md (or
# $DOC) between `<!-- create-files:begin -->` and `<!-- create-files:end -->`.
#     bench/create-files.sh            # about 3 minutes on 2 quiet cores
set -euo pipefail
cd "$(dirname "$0")/.."
source bench/lib.sh
RUNS=${RUNS:-3}
splice_check create-files
bench_setup
cargo build --release --quiet -p vortex-bench --bin create_files
cp target/release/create_files "$WORK/bin/"
pyvips_setup
SRC=$(jpeg_tiled_source)
find "$SRC" -type f -exec cat {} + >/dev/null # in the page cache: the runs measure writing

C=$WORK/create-files
RAW=$C/runs.tsv # fs what run wall_s sys_s files printed
mkdir -p "$C"
: >"$RAW"
LOOPS=
if can_mount; then
  LOOPS="journal nojournal"
else
  echo "note: not root or no mkfs.ext4: the loop-mounted ext4 rows are left out" >&2
fi
trap 'for fs in $LOOPS; do drop_ext4 "$C/mnt-$fs"; done' EXIT

# fresh_fs FS: a new, empty ext4 at $C/mnt-FS (FS: journal or nojournal); prints its path.
fresh_fs() {
  new_ext4 "$C/mnt-$1" "$1"
  echo "$C/mnt-$1"
}

# timed FS WHAT RUN OUT COMMAND...: one run under /usr/bin/time, appended to $RAW with the number
# of files under OUT after it (0 where OUT is -) and what it printed (create_files' JSON).
timed() {
  local fs=$1 what=$2 run=$3 out=$4 files=0
  shift 4
  sync
  /usr/bin/time -f '%e %S' -o "$C/time.txt" "$@" >"$C/out.txt" 2>"$C/err.txt" || { cat "$C/err.txt" >&2; exit 1; }
  [ "$out" = - ] || files=$(find "$out" -type f | wc -l)
  printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$fs" "$what" "$run" "$(cut -d' ' -f1 "$C/time.txt")" \
    "$(cut -d' ' -f2 "$C/time.txt")" "$files" "$(tr -d '\n' <"$C/out.txt")" >>"$RAW"
}

for run in $(seq "$RUNS"); do
  log "run $run"
  for fs in $LOOPS work; do
    for threads in 1 2; do
      for open in create_new truncate; do
        if [ "$fs" = work ]; then dir=$C/files; else dir=$(fresh_fs "$fs")/files; fi
        timed "$fs" "files $threads $open" "$run" - "$WORK/bin/create_files" "$dir" --threads "$threads" \
          $([ "$open" = truncate ] && echo --truncate)
      done
    done
  done
  for fs in $LOOPS; do
    for tool in ours peer; do
      [ "$tool" = ours ] || [ -n "$PY" ] || continue
      mnt=$(fresh_fs "$fs")
      for when in fresh again; do
        if [ "$tool" = ours ]; then
          timed "$fs" "dzi $tool $when" "$run" "$mnt" "$WORK/bin/vortex-tiler" split "$SRC" --layout dzi -o "$mnt/dz" \
            --tile-size 256 --overlap 0 -q
        else
          timed "$fs" "dzi $tool $when" "$run" "$mnt" "$PY" -c "$PEER_DZSAVE" "$SRC" "$mnt/dz" 256 0
        fi
        # As the benchmarks did between runs: the output deleted (ext4's deletion times are whole seconds).
        rm -rf "$mnt"/dz*
        sync
        sleep 2
      done
    done
  done
done
# The system calls per tile file, counted (strace's own times are its overhead's, not kept).
STRACE=
if command -v strace >/dev/null && [ -n "$LOOPS" ]; then
  mnt=$(fresh_fs journal)
  strace -f -c -o "$C/strace-ours.txt" "$WORK/bin/vortex-tiler" split "$SRC" --layout dzi -o "$mnt/ours" --tile-size 256 \
    --overlap 0 -q
  [ -z "$PY" ] || strace -f -c -o "$C/strace-peer.txt" "$PY" -c "$PEER_DZSAVE" "$SRC" "$mnt/peer" 256 0
  STRACE=$C
fi

REPORT=$C/report.md
python3 - "$RAW" "$REV" "${PYVIPS_VERSION:-}" "$STRACE" >"$REPORT" <<'PY'
import json, statistics, sys, datetime, os
raw, rev, peer, strace = sys.argv[1:5]
runs = {}
for line in open(raw):
    fs, what, run, wall, sys_s, files, out = line.rstrip("\n").split("\t")
    runs.setdefault((fs, what), []).append((float(wall), float(sys_s), int(files), json.loads(out) if out else None))
fs_name = {"journal": "ext4 with a journal (new)", "nojournal": "ext4 without a journal (new)", "work": "bench/work's file system, as it is"}
med = lambda xs: statistics.median(xs)
print(f"{datetime.date.today()}, {os.cpu_count()} cores, vortex-tiler {rev}; medians of the runs per cell.")
print()
print("| file system | threads | open | µs of system time per file: fresh directory | after deleting its files | wall: fresh | after deleting |")
print("|---|---:|---|---:|---:|---:|---:|")
for (fs, what), rs in runs.items():
    if not what.startswith("files"):
        continue
    _, threads, open_ = what.split()
    f = [r[3]["fresh"] for r in rs]
    a = [r[3]["afterDeleting"] for r in rs]
    print(f"| {fs_name[fs]} | {threads} | {'O_EXCL (ours)' if open_ == 'create_new' else 'O_TRUNC (libvips)'} "
          f"| {med([x['sysMicrosPerFile'] for x in f]):.0f} | {med([x['sysMicrosPerFile'] for x in a]):.0f} "
          f"| {med([x['wallSeconds'] for x in f]):.3f} s | {med([x['wallSeconds'] for x in a]):.3f} s |")
print()
print(f"The tools, into a new file system each run: Deep Zoom of the 16384² JPEG-tiled BigTIFF, 256-texel tiles, no overlap, Q85"
      + (f" (the peer: {peer}, direct mode)" if peer else "") + ".")
print()
print("| file system | tool | into | wall | system CPU | µs of system CPU per tile file |")
print("|---|---|---|---:|---:|---:|")
for (fs, what), rs in runs.items():
    if not what.startswith("dzi"):
        continue
    _, tool, when = what.split()
    sys_s = med([r[1] for r in rs])
    print(f"| {fs_name[fs]} | {'vortex-tiler' if tool == 'ours' else 'libvips dzsave'} "
          f"| {'the new file system' if when == 'fresh' else 'it again, its output deleted'} "
          f"| {med([r[0] for r in rs]):.2f} s | {sys_s:.2f} s | {sys_s / rs[0][2] * 1e6:.0f} |")
if strace:
    print()
    files = next(rs[0][2] for (fs, what), rs in runs.items() if what == "dzi ours fresh")
    print(f"System calls per tile file (`strace -f -c`, ext4 with a journal; {files:,} files):")
    print()
    print("| tool | openat | mkdir | stat, newfstatat, statx | write | close |")
    print("|---|---:|---:|---:|---:|---:|")
    for tool, name in (("ours", "vortex-tiler"), ("peer", "libvips dzsave")):
        path = os.path.join(strace, f"strace-{tool}.txt")
        if not os.path.exists(path):
            continue
        calls = {}
        for line in open(path):
            f = line.split()
            if len(f) >= 5 and f[0][0].isdigit() and f[-1].isidentifier():
                calls[f[-1]] = int(f[3])
        per = lambda *names: f"{sum(calls.get(n, 0) for n in names) / files:.1f}"
        print(f"| {name} | {per('openat')} | {per('mkdir')} | {per('stat', 'newfstatat', 'statx')} | {per('write')} | {per('close')} |")
PY
cat "$REPORT"
splice create-files "$REPORT" ""
