#!/usr/bin/env bash
# bench/resume.sh: what `split --resume` costs (issue 47, docs/resume.md).
#
#   1. The journal's cost on a run that is not interrupted: `split SRC --pack` (and `-o DIR
#      --layout dzi`) with and without --resume, RUNS rounds alternating, medians of the wall and
#      of the user + system CPU time (/usr/bin/time), and the cost as the median over rounds of
#      each round's (--resume - plain) / plain (a round's two runs are seconds apart, so other
#      load on the machine moves them alike). Goal of the issue: under 2%.
#   2. A run SIGKILLed once its journal records half the tiles, then the same command with
#      --resume: the resumed run's tiles encoded and kept (from --json), its CPU time, and the
#      work done twice: (killed run's CPU + resumed run's CPU - an uninterrupted run's CPU) /
#      the uninterrupted run's CPU. The resumed output is compared with the uninterrupted
#      run's (`cmp`, `diff -r`): the script stops if they differ.
#
#   3. With CALLGRIND=1, the journal's cost where other load on the machine cannot move it:
#      the instructions (valgrind's callgrind, user space only; one encoder thread) of a
#      4096 x 4096 crop of the source cut with and without --resume, pack and Deep Zoom. The
#      kernel's part, one write(2) of a line per tile, is under a microsecond a tile.
#
# Source: a SIDE x SIDE RGB 8-bit uncompressed TIFF made by libvips (smooth bands plus noise,
# so that JPEG tiles are of a usual size), read once before the runs (page cache). Tiles: 256
# texels, no border, JPEG quality 85.
#
# Usage, from the repository root, after `cargo build --release` (any feature set with `cli`):
#     bench/resume.sh                 # SIDE=8192 RUNS=5, under a minute on 2 cores
#     SIDE=16384 RUNS=5 bench/resume.sh   # about 3 minutes
# VORTEX=PATH times another build. Works in bench/work/ (git-ignored): every process in
# resume-runs.tsv, the summary on standard output.
set -euo pipefail

cd "$(dirname "$0")/.."
source bench/lib.sh
SIDE=${SIDE:-8192}
RUNS=${RUNS:-5}
snapshot_release # VT, REV
cd "$WORK"

SRC=resume-src$SIDE.tif
if [ ! -s "$SRC" ]; then
  log "making $SRC with libvips"
  vips sines resume-s.v "$SIDE" "$SIDE" --hfreq 7 --vfreq 5
  vips linear resume-s.v resume-s8.v 90 128 --uchar
  vips gaussnoise resume-n.v "$SIDE" "$SIDE" --sigma 12 --mean 0
  vips add resume-s8.v resume-n.v resume-a.v
  vips cast resume-a.v resume-a8.v uchar
  vips bandjoin "resume-a8.v resume-s8.v resume-a8.v" resume-rgb.v
  vips tiffsave resume-rgb.v "part-$SRC" --compression none --bigtiff
  mv "part-$SRC" "$SRC"
  rm -f resume-*.v
fi
cat "$SRC" >/dev/null

RAW=$WORK/resume-runs.tsv # kind case round wall_s cpu_s encoded kept tiles
: >"$RAW"
OUT=$WORK/out-resume
rm -rf "$OUT"
mkdir -p "$OUT"
TILES=(--tile-size 256 --codec jpeg)

# dest KIND NAME: the output's path; flags KIND PATH: the output's flags.
dest() { if [ "$1" = pack ]; then echo "$OUT/$2.vtpk"; else echo "$OUT/$2"; fi; }
flags() { if [ "$1" = pack ]; then echo "--pack $2 --border 0"; else echo "-o $2 --layout dzi --overlap 0"; fi; }
jnum() { grep -o "\"$1\":[0-9.eE+-]*" "$2" | head -1 | cut -d: -f2; }
cpu_of() { awk '/User time/ { u = $NF } /System time/ { s = $NF } END { printf "%.3f", u + s }' "$1"; }
wall_of() {
  sed -n 's/^[[:space:]]*Elapsed (wall clock) time (h:mm:ss or m:ss): //p' "$1" |
    awk -F: '{ s = 0; for (i = 1; i <= NF; i++) s = s * 60 + $i; printf "%.3f", s }'
}

# run KIND CASE ROUND NAME [FLAGS...]: one timed run into NAME; appends a line to $RAW.
run() {
  local kind=$1 case=$2 round=$3 name=$4
  shift 4
  local path
  path=$(dest "$kind" "$name")
  rm -rf "$path"
  sync
  # shellcheck disable=SC2046
  /usr/bin/time -v -o time.txt "$VT" split "$SRC" $(flags "$kind" "$path") "${TILES[@]}" --json "$@" >run.json
  printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$kind" "$case" "$round" "$(wall_of time.txt)" "$(cpu_of time.txt)" \
    "$(jnum encoded run.json)" "$(jnum kept run.json)" "$(jnum tiles run.json)" >>"$RAW"
}

for kind in pack dzi; do
  for round in $(seq 1 "$RUNS"); do
    log "$kind round $round: plain, then --resume"
    run "$kind" plain "$round" plain
    run "$kind" journal "$round" journal --resume
    if [ "$kind" = pack ]; then cmp "$(dest pack plain)" "$(dest pack journal)"; else diff -r "$(dest dzi plain)" "$(dest dzi journal)" >/dev/null; fi
  done
  # Killed half-way, then resumed.
  total=$(awk -F'\t' -v k="$kind" '$1 == k && $2 == "plain" { print $8; exit }' "$RAW")
  path=$(dest "$kind" killed)
  rm -rf "$path"
  name=$(basename "$path")
  # shellcheck disable=SC2046
  /usr/bin/time -v -o time-killed.txt "$VT" split "$SRC" $(flags "$kind" "$path") "${TILES[@]}" -q --resume &
  timer=$!
  child=
  while [ -z "$child" ]; do child=$(pgrep -P "$timer" || true); [ -n "$child" ] || sleep 0.001; done
  journal=
  while :; do
    journal=$(find "$OUT" -maxdepth 1 -name ".$name.resume-*" | head -1)
    if [ -n "$journal" ] && [ $(($(wc -l <"$journal") - 2)) -ge $((total / 2)) ]; then break; fi
    sleep 0.005
  done
  kill -KILL "$child"
  wait "$timer" || true
  at_kill=$(($(wc -l <"$journal") - 2))
  printf '%s\t%s\t%s\t%s\t%s\t\t%s\t%s\n' "$kind" killed 1 "$(wall_of time-killed.txt)" "$(cpu_of time-killed.txt)" "$at_kill" "$total" >>"$RAW"
  run "$kind" resumed 1 killed --resume
  if [ "$kind" = pack ]; then cmp "$path" "$(dest pack plain)"; else diff -r "$path" "$(dest dzi plain)" >/dev/null; fi
done

if [ "${CALLGRIND:-0}" = 1 ]; then
  [ -s resume-src4096.tif ] || vips crop "$SRC" resume-src4096.tif 0 0 4096 4096
  # instructions FLAGS...: callgrind's count of the run's user-space instructions.
  instructions() {
    valgrind --tool=callgrind --callgrind-out-file="$WORK/callgrind.out" "$VT" split resume-src4096.tif "$@" \
      --tile-size 256 --codec jpeg -q --threads 1 2>&1 | sed -n 's/.*Collected : //p'
  }
  for kind in pack dzi; do
    rm -rf "$OUT"/cg-*  "$OUT"/.cg-*
    # shellcheck disable=SC2046
    plain=$(instructions $(flags "$kind" "$(dest "$kind" cg-plain)"))
    # shellcheck disable=SC2046
    journal=$(instructions $(flags "$kind" "$(dest "$kind" cg-journal)") --resume)
    printf '%s\tcallgrind\t1\t%s\t%s\n' "$kind" "$plain" "$journal" >>"$RAW"
  done
fi

median_of() { awk -F'\t' -v k="$1" -v c="$2" -v f="$3" '$1 == k && $2 == c { print $f }' "$RAW" | sort -g |
  awk '{ v[NR] = $1 } END { if (NR % 2) print v[(NR + 1) / 2]; else print (v[NR / 2] + v[NR / 2 + 1]) / 2 }'; }
one() { awk -F'\t' -v k="$1" -v c="$2" -v f="$3" '$1 == k && $2 == c { print $f; exit }' "$RAW"; }

echo
echo "vortex-tiler $REV, $(date -u '+%Y-%m-%d %H:%M UTC'), $SIDE x $SIDE RGB, 256-texel JPEG tiles, $RUNS rounds (medians); $(nproc) cores, load $(cut -d' ' -f1 /proc/loadavg)"
echo
# paired KIND COLUMN: the median over rounds of (--resume - plain) / plain, in %.
paired() {
  awk -F'\t' -v k="$1" -v c="$2" '$1 == k && $2 == "plain" { p[$3] = $c } $1 == k && $2 == "journal" { j[$3] = $c }
    END { for (r in p) if (r in j) printf "%.2f\n", 100 * (j[r] - p[r]) / p[r] }' "$RAW" | sort -g |
    awk '{ v[NR] = $1 } END { if (NR % 2) print v[(NR + 1) / 2]; else print (v[NR / 2] + v[NR / 2 + 1]) / 2 }'
}
echo "| output | wall s plain | wall s --resume | wall cost (median of rounds) | CPU s plain | CPU s --resume | CPU cost (median of rounds) |"
echo "|---|---:|---:|---:|---:|---:|---:|"
for kind in pack dzi; do
  wp=$(median_of "$kind" plain 4) wj=$(median_of "$kind" journal 4) cp=$(median_of "$kind" plain 5) cj=$(median_of "$kind" journal 5)
  echo "| $kind | $wp | $wj | $(paired "$kind" 4)% | $cp | $cj | $(paired "$kind" 5)% |"
done
if [ "${CALLGRIND:-0}" = 1 ]; then
  echo
  echo "| output (4096 x 4096, one thread) | instructions plain | instructions --resume | cost |"
  echo "|---|---:|---:|---:|"
  for kind in pack dzi; do
    p=$(one "$kind" callgrind 4) j=$(one "$kind" callgrind 5)
    echo "| $kind | $p | $j | $(calc '%+.2f%%' "100 * ($j - $p) / $p") |"
  done
fi
echo
echo "| output | tiles | journaled at the kill | resumed: kept | resumed: encoded | encoded uninterrupted | killed CPU s | resumed CPU s | done twice (CPU) |"
echo "|---|---:|---:|---:|---:|---:|---:|---:|---:|"
for kind in pack dzi; do
  cp=$(median_of "$kind" plain 5)
  ck=$(one "$kind" killed 5) cr=$(one "$kind" resumed 5)
  echo "| $kind | $(one "$kind" plain 8) | $(one "$kind" killed 7) | $(one "$kind" resumed 7) | $(one "$kind" resumed 6) | $(one "$kind" plain 6) | $ck | $cr | $(calc '%.1f%%' "100 * ($ck + $cr - $cp) / $cp") |"
done
