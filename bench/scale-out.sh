#!/usr/bin/env bash
# bench/scale-out.sh: one image cut on N machines (`split --shard I/N` + `merge`) against one
# `split --pack` on one machine (issue 15).
#
# What it measures (results go to docs/scale-out.md, or $DOC, between the lines
# `<!-- scale-out:begin -->` and `<!-- scale-out:end -->`, which must already be there: the
# script stops before measuring anything if they are not). Every run cuts 256-texel JPEG tiles
# at the default quality (85) into packs, with no border:
#   1. Overhead of sharding, per image and per N in $NS: the user + system CPU time (from
#      /usr/bin/time -v) of all N shards, run one after another on this machine with the
#      default threads, plus the merge's, against one `split --pack` of the same image: ratio =
#      sharded / one machine; medians over RUNS rounds (each round: one machine, then every N).
#      Every merged pack is compared with the one-machine pack (`cmp`): the script stops if
#      they differ. Goal of the issue: at most 1.1x at N = 16. Images:
#        - 16384 x 16384 RGB 8-bit uncompressed BigTIFF (bench_setup's src16k.tif);
#        - 16384 x 131072 RGB 8-bit uncompressed BigTIFF (srcbig.tif, ~6.4 GB, written by
#          gen_image (crates/vortex-bench) like the first). Skipped with TALL=0, or with a note when the
#          disk lacks room (it needs about 10 GB free, 4 if the source is there).
#      Both have 64-row uncompressed strips: a shard reads only its rows, and of each row only
#      its columns (uncompressed 8-bit strips are read in part).
#   2. Merge: wall and CPU time, bytes read (copiedBytes + sumsBytes from `merge --json`), the
#      shards' total file size, the output pack's size, MB/s = bytes read / wall. The shards
#      were just written, so they are read from the page cache.
#   3. Per-shard wall time, per N: the slowest and the median shard; from them a projection
#      for a 262144 x 262144 image on M = 16, 64, 256 machines of this machine's kind:
#          critical path = t_slowest(N) x (P / M) / (p / N) + t_merge(N) x (P / p)
#      with p the measured image's pixels, P = 262144^2, N = M where measured (else the
#      largest measured N below M), the merge scaled by pack size (taken proportional to
#      pixels). A projection from these measurements, not a measurement.
#   4. Peak RSS of a 200000 x 2000 RGB PNG (bench/work/wide-200000x2000.png, made as
#      bench/wide-images.sh does if missing) cut into 16 shards against one machine: the
#      largest shard's peak RSS, and the CPU times as in 1; one round. Skipped with WIDE=0.
#
# Usage, from the repository root:
#     bench/scale-out.sh   # NS="2 4 16 64" RUNS=3 TALL=1 WIDE=1: 7-15 min on 2 shared cores
#     SIDE=4096 NS="2 4" TALL=0 WIDE=0 RUNS=1 bench/scale-out.sh    # a quick try, ~1 minute
# Environment: NS (shard counts, default "2 4 16 64"), RUNS (rounds, default 3), TALL=0 skips
# the 16384 x 131072 image, WIDE=0 skips case 4, KEEP=1 keeps the tall source (deleted
# otherwise; bench/split-vs-vips.sh uses the same file), SIDE (default 16384: the square
# image's side; the tall one is SIDE x 8 SIDE), DOC (the report's file), VORTEX=PATH (time that
# binary, see bench/lib.sh), REPORT_ONLY=1 (measure nothing: rebuild the report from the last
# run's files in bench/work/ and splice it again, e.g. once the doc has its markers). Works in
# bench/work/ (git-ignored): raw numbers in
# scale-out-runs.tsv (every process), scale-out-merge.tsv (merge --json) and
# scale-out-rounds.tsv (sums per round), the report in scale-out-report.md. Sources are read
# once before each image's runs to warm the page cache, so this measures decode + pyramid +
# encode + write, not the disk.
set -euo pipefail

cd "$(dirname "$0")/.."
DOC=${DOC:-$PWD/docs/scale-out.md}

source bench/lib.sh
splice_check scale-out # the report's place, before anything is measured
NS=${NS:-2 4 16 64}
RUNS=${RUNS:-3}
TALL=${TALL:-1}
WIDE=${WIDE:-1}
KEEP=${KEEP:-0}
SIDE=${SIDE:-16384}
TALL_H=$((SIDE * 8))
TARGET=262144 # side of the projected image
MACHINES=(16 64 256)
WIDE_N=16
WIDE_SRC=wide-200000x2000.png
TILES=(--tile-size 256 --border 0 --codec jpeg)

REPORT_ONLY=${REPORT_ONLY:-0}
RAW=$WORK/scale-out-runs.tsv     # image kind n run index wall_s rss_kib user_s sys_s load1 minor_faults
MERGES=$WORK/scale-out-merge.tsv # image n run cutLevel madeAboveCut copiedBytes sumsBytes shardFileBytes fileBytes tiles
META=$WORK/scale-out-meta.sh     # the settings of the run that wrote them, for REPORT_ONLY=1
declare -A SRC W H
W[square]=$SIDE H[square]=$SIDE W[tall]=$SIDE H[tall]=$TALL_H W[wide]=200000 H[wide]=2000

if [ "$REPORT_ONLY" = 1 ]; then
  if ! { [ -s "$META" ] && [ -s "$RAW" ] && [ -s "$MERGES" ]; }; then
    echo "error: REPORT_ONLY=1 needs a finished run's $RAW, $MERGES and $META" >&2
    exit 1
  fi
  # shellcheck source=/dev/null
  source "$META" # REV RUN_DATE NS RUNS SIDE TALL_H TALL_NOTE WIDE IMAGES of that run
  W[square]=$SIDE H[square]=$SIDE W[tall]=$SIDE H[tall]=$TALL_H
  cd "$WORK"
  log "rebuilding the report of the run of $RUN_DATE from $RAW"
else
# ---------------------------------------------------------------------------------------------
# 1. Build, binaries, images
bench_setup # time, bin/{vortex-tiler,gen_image}, src16k.tif, REV
VT=$WORK/bin/vortex-tiler
cd "$WORK"

# gen_into FILE W H: writes the gen_image picture unless FILE is there (via a partial name).
gen_into() {
  [ -s "$1" ] && return
  log "generating $1 ($2 x $3)"
  bin/gen_image "$2" "$3" "part-$1"
  mv "part-$1" "$1"
}

IMAGES=(square)
if [ "$SIDE" = 16384 ]; then
  SRC[square]=src16k.tif
else
  SRC[square]=src$SIDE.tif
  gen_into "${SRC[square]}" "$SIDE" "$SIDE"
fi

TALL_NOTE=
if [ "$TALL" = 1 ]; then
  if [ "$SIDE" = 16384 ]; then SRC[tall]=srcbig.tif; else SRC[tall]=src${SIDE}x$TALL_H.tif; fi
  # The source (3 bytes a texel, if not there yet) and about 1.3 bytes a texel of packs at
  # once: the one-machine pack, a round's shards and their merge.
  need_gb=$(awk -v p="$((SIDE * TALL_H))" -v have="$([ -s "${SRC[tall]}" ] && echo 1 || echo 0)" 'BEGIN { printf "%.0f", (p * (have ? 0 : 3) + p * 1.3) / 1e9 + 1 }')
  free_gb=$(df -BG --output=avail "$WORK" | tail -1 | tr -dc 0-9)
  if [ "$free_gb" -lt "$need_gb" ]; then
    TALL_NOTE="skipped: only $free_gb GB free in bench/work, it needs about $need_gb GB"
    echo "note: tall image $TALL_NOTE" >&2
  else
    gen_into "${SRC[tall]}" "$SIDE" "$TALL_H"
    IMAGES+=(tall)
  fi
else
  TALL_NOTE="not measured (TALL=0)"
fi

[ "$WIDE" = 1 ] && gen_into "$WIDE_SRC" 200000 2000

OUT=$WORK/out-scale
rm -rf "$OUT"
mkdir -p "$OUT"

# ---------------------------------------------------------------------------------------------
# 2. Timing
: >"$RAW"
: >"$MERGES"

to_seconds() { awk -F: '{ s = 0; for (i = 1; i <= NF; i++) s = s * 60 + $i; printf "%.2f", s }' <<<"$1"; }
field() { sed -n "s/^[[:space:]]*$1: //p" "$2"; }
# jnum KEY FILE: the number KEY holds in FILE's JSON (one flat member of the object).
jnum() { grep -o "\"$1\":[0-9.eE+-]*" "$2" | head -1 | cut -d: -f2; }

# timed IMAGE KIND N RUN INDEX COMMAND...: runs COMMAND under /usr/bin/time -v, its output in
# $OUT/last.log; appends a line to $RAW.
timed() {
  local image=$1 kind=$2 n=$3 run=$4 index=$5
  shift 5
  sync # the previous run's writeback must not land in this one
  local load
  load=$(cut -d' ' -f1 /proc/loadavg)
  if ! /usr/bin/time -v -o "$OUT/time.txt" "$@" >"$OUT/last.log" 2>&1; then
    echo "error: $image $kind n=$n run $run index $index failed: $*" >&2
    cat "$OUT/last.log" "$OUT/time.txt" >&2
    exit 1
  fi
  printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$image" "$kind" "$n" "$run" "$index" \
    "$(to_seconds "$(field 'Elapsed (wall clock) time (h:mm:ss or m:ss)' "$OUT/time.txt")")" \
    "$(field 'Maximum resident set size (kbytes)' "$OUT/time.txt")" \
    "$(field 'User time (seconds)' "$OUT/time.txt")" "$(field 'System time (seconds)' "$OUT/time.txt")" "$load" \
    "$(field 'Minor (reclaiming a frame) page faults' "$OUT/time.txt")" >>"$RAW"
}

# one_machine IMAGE RUN SRC: one split --pack into $OUT/IMAGE-one.vtpk (run 1) or
# $OUT/IMAGE-again.vtpk, which must equal run 1's.
one_machine() {
  local dest=$OUT/$1-one.vtpk
  [ "$2" = 1 ] || dest=$OUT/$1-again.vtpk
  timed "$1" one 1 "$2" 0 "$VT" split "$3" --pack "$dest" "${TILES[@]}" --quiet
  if [ "$2" != 1 ]; then
    cmp -s "$dest" "$OUT/$1-one.vtpk" || { echo "error: $1: one-machine run $2 differs from run 1" >&2; exit 1; }
    rm -f "$dest"
  fi
  log "$1 one machine, run $2: $(tail -1 "$RAW" | cut -f6) s wall, $(tail -1 "$RAW" | awk -F'\t' '{ print $8 + $9 }') s CPU"
}

# sharded IMAGE N RUN SRC: the N shards one after another, the merge, and the check.
sharded() {
  local image=$1 n=$2 run=$3 src=$4 i
  rm -rf "$OUT/shards" "$OUT/merged.vtpk"
  mkdir -p "$OUT/shards"
  for ((i = 0; i < n; i++)); do
    timed "$image" shard "$n" "$run" "$i" "$VT" split "$src" --pack "$OUT/shards/{shard}.vtpk" --shard "$i/$n" "${TILES[@]}" --quiet
  done
  local shards=("$OUT"/shards/*.vtpk)
  [ "${#shards[@]}" = "$n" ] || { echo "error: $image: $n shards wrote ${#shards[@]} files" >&2; exit 1; }
  local shard_bytes
  shard_bytes=$(stat -c %s "${shards[@]}" | awk '{ s += $1 } END { printf "%.0f", s }')
  timed "$image" merge "$n" "$run" 0 "$VT" merge "${shards[@]}" -o "$OUT/merged.vtpk" --json
  local j=$OUT/last.log
  [ "$(jnum shards "$j")" = "$n" ] || { echo "error: $image: merge --json does not say $n shards:" >&2; cat "$j" >&2; exit 1; }
  if ! cmp "$OUT/merged.vtpk" "$OUT/$image-one.vtpk"; then
    echo "error: $image: the merge of $n shards (run $run) differs from the one-machine pack" >&2
    exit 1
  fi
  printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$image" "$n" "$run" "$(jnum cutLevel "$j")" "$(jnum madeAboveCut "$j")" \
    "$(jnum copiedBytes "$j")" "$(jnum sumsBytes "$j")" "$shard_bytes" "$(jnum fileBytes "$j")" "$(jnum tiles "$j")" >>"$MERGES"
  log "$image N=$n, run $run: shards $(awk -F'\t' -v im="$image" -v n="$n" -v r="$run" '$1 == im && $2 == "shard" && $3 == n && $4 == r { c += $8 + $9; if ($6 > m) m = $6 } END { printf "%.2f s CPU, slowest %.2f s wall", c, m }' "$RAW"), merge $(tail -1 "$RAW" | awk -F'\t' '{ printf "%.2f s wall", $6 }'), identical"
  rm -rf "$OUT/shards" "$OUT/merged.vtpk"
}

for run in $(seq 1 "$RUNS"); do
  for image in "${IMAGES[@]}"; do
    cat "${SRC[$image]}" >/dev/null # warm the page cache (the other image's runs may have evicted it)
    one_machine "$image" "$run" "${SRC[$image]}"
    for n in $NS; do sharded "$image" "$n" "$run" "${SRC[$image]}"; done
  done
done

if [ "$WIDE" = 1 ]; then
  cat "$WIDE_SRC" >/dev/null
  one_machine wide 1 "$WIDE_SRC"
  sharded wide $WIDE_N 1 "$WIDE_SRC"
fi

if [ -n "${SRC[tall]:-}" ] && [ "$KEEP" != 1 ]; then rm -f "${SRC[tall]}"; fi
rm -rf "$OUT"
RUN_DATE=$(date -u '+%Y-%m-%d %H:%M UTC')
declare -p REV RUN_DATE NS RUNS SIDE TALL_H TALL_NOTE WIDE IMAGES | sed 's/^declare -/declare -g/; s/^declare -g- /declare -g /' >"$META"
fi # REPORT_ONLY

# ---------------------------------------------------------------------------------------------
# 3. Aggregates: per image, N and round, then medians over the rounds
AGG=$WORK/scale-out-rounds.tsv
# Columns: 1 image:n, 2 round, 3 shards' CPU s, 4 merge CPU s, 5 one machine CPU s, 6 slowest
# shard wall s, 7 median shard wall s, 8 merge wall s, 9 one machine wall s, 10 largest shard
# peak RSS KiB, 11 one machine peak RSS KiB, 12 sharded / one CPU, 13 index of the shard of 10,
# 14 merge peak RSS KiB, 15 minor page faults of the shards and the merge, 16 of one machine,
# 17 user s of the shards and the merge, 18 their system s, 19 one machine's user s, 20 its system s.
awk -F'\t' '
  $2 == "one" { o = $1 SUBSEP $4; oc[o] = $8 + $9; ow[o] = $6; orss[o] = $7; of[o] = $11; ou[o] = $8; os[o] = $9 }
  $2 == "merge" { k = $1 SUBSEP $3 SUBSEP $4; mc[k] = $8 + $9; mw[k] = $6; mr[k] = $7; sf[k] += $11; su[k] += $8; ss[k] += $9 }
  $2 == "shard" { k = $1 SUBSEP $3 SUBSEP $4; sc[k] += $8 + $9; sf[k] += $11; su[k] += $8; ss[k] += $9; walls[k] = walls[k] " " $6
    if (!(k in sr) || $7 > sr[k]) { sr[k] = $7; si[k] = $5 }
    if (!(k in sw) || $6 > sw[k]) sw[k] = $6 }
  END {
    for (k in sc) {
      split(k, p, SUBSEP); o = p[1] SUBSEP p[3]
      n = split(substr(walls[k], 2), v, " ")
      for (i = 1; i <= n; i++) for (j = i + 1; j <= n; j++) if (v[j] + 0 < v[i] + 0) { t = v[i]; v[i] = v[j]; v[j] = t }
      med = n % 2 ? v[(n + 1) / 2] : (v[n / 2] + v[n / 2 + 1]) / 2
      printf "%s:%s\t%s\t%.2f\t%.2f\t%.2f\t%.2f\t%.3f\t%.2f\t%.2f\t%d\t%d\t%.4f\t%d\t%d\t%d\t%d\t%.2f\t%.2f\t%.2f\t%.2f\n", p[1], p[2], p[3],
        sc[k], mc[k], oc[o], sw[k], med, mw[k], ow[o], sr[k], orss[o], (sc[k] + mc[k]) / oc[o], si[k], mr[k], sf[k], of[o],
        su[k], ss[k], ou[o], os[o]
    }
  }' "$RAW" | sort -t$'\t' -k1,1V -k2,2n >"$AGG"

mr() { median "$AGG" "$1:$2" "$3"; }       # mr IMAGE N COLUMN: the median over rounds
m() { calc %.2f "$(mr "$1" "$2" "$3")"; } # the same, rounded for the report
mg() { awk -F'\t' -v im="$1" -v n="$2" -v c="$3" '$1 == im && $2 == n { print $c; exit }' "$MERGES"; } # mg IMAGE N COLUMN (first round)
# ratio_range IMAGE N: the per-round ratios' median and range.
ratio_range() {
  awk -F'\t' -v k="$1:$2" '$1 == k { print $12 }' "$AGG" | sort -g |
    awk '{ v[NR] = $1 } END { med = NR % 2 ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2
      if (NR > 1) printf "%.3fx (%.3f-%.3f)", med, v[1], v[NR]; else printf "%.3fx", med }'
}

# ---------------------------------------------------------------------------------------------
# 4. Report
CPU_MODEL=$(sed -n 's/^model name[[:space:]]*: //p' /proc/cpuinfo | head -1)
MEM_GIB=$(awk '/^MemTotal/ { printf "%.0f", $2 / 1048576 }' /proc/meminfo)
LOADS=$(cut -f10 "$RAW" | sort -g | awk 'NR == 1 { lo = $1 } { hi = $1 } END { print lo "-" hi }')
declare -A LABEL=([square]="${SIDE} x ${SIDE}" [tall]="${SIDE} x ${TALL_H}" [wide]="200000 x 2000")
mpx() { calc %.1f "${W[$1]} * ${H[$1]} / 1e6"; }
mb() { calc %.1f "$1 / 1e6"; }
REPORT=$WORK/scale-out-report.md
{
  echo "Run $RUN_DATE, vortex-tiler at $REV, $RUNS round$([ "$RUNS" = 1 ] || echo s) (medians over rounds); machine: $(nproc) cores ($CPU_MODEL), $MEM_GIB GiB RAM, $(. /etc/os-release && echo "$PRETTY_NAME"), 1-minute load average $LOADS before the runs (other work on the machine shows in wall times more than in CPU times)."
  echo
  echo "Every run cuts 256-texel JPEG tiles at quality 85, no border, into a pack; shards run one after another on this machine, each with the default threads (one per core), under \`/usr/bin/time -v\`:"
  echo
  echo '```sh'
  echo "vortex-tiler split SRC --pack one.vtpk --tile-size 256 --border 0 --codec jpeg --quiet            # one machine"
  echo "for i in \$(seq 0 \$((N - 1))); do"
  echo "  vortex-tiler split SRC --pack 'shards/{shard}.vtpk' --shard \$i/\$N --tile-size 256 --border 0 --codec jpeg --quiet"
  echo "done"
  echo "vortex-tiler merge shards/*.vtpk -o merged.vtpk --json"
  echo "cmp merged.vtpk one.vtpk                                                                        # every merge: identical"
  echo '```'
  echo
  echo "Sources: RGB 8-bit uncompressed BigTIFFs from \`gen_image\` (crates/vortex-bench; 64-row strips: a shard seeks to the strips of its rows and, the strips being uncompressed, reads only its columns of each row), read once before each image's runs so that they come from the page cache. Tall image: ${TALL_NOTE:-measured}."
  echo
  echo "### Overhead of sharding (CPU time)"
  echo
  echo "Goal (issue 15): **at most 1.1x at N = 16** (all shards' CPU time plus the merge's, over one machine's)."
  echo
  echo "| image | N | cut level | shards' CPU s (sum) | merge CPU s | sharded CPU s | one machine CPU s | sharded / one (range) | extra CPU s per shard | largest shard's peak RSS MiB | one machine's peak RSS MiB |"
  echo "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
  for image in "${IMAGES[@]}"; do
    for n in $NS; do
      sc=$(mr "$image" "$n" 3) mc=$(mr "$image" "$n" 4) oc=$(mr "$image" "$n" 5)
      echo "| ${LABEL[$image]} ($(mpx "$image") Mpx) | $n | $(mg "$image" "$n" 4) | $(calc %.2f "$sc") | $(calc %.2f "$mc") | $(calc %.2f "$sc + $mc") | $(calc %.2f "$oc") | $(ratio_range "$image" "$n") | $(calc %.3f "($sc + $mc - $oc) / $n") | $(calc %.0f "$(mr "$image" "$n" 10) / 1024") | $(calc %.0f "$(mr "$image" "$n" 11) / 1024") |"
    done
  done
  echo
  if grep -q "^[a-z]*:16	" "$AGG"; then
    for image in "${IMAGES[@]}"; do
      r=$(median "$AGG" "$image:16" 12)
      echo "- ${LABEL[$image]} at N = 16: $(calc %.3f "$r")x, goal $(awk -v r="$r" 'BEGIN { print (r <= 1.1 ? "met" : "**not met**") }')."
    done
  else
    echo "- N = 16 was not measured (NS=\"$NS\")."
  fi
  echo
  echo "CPU = user + system seconds; sums and ratios are per round, then the median over rounds (ratio range over rounds in brackets). Extra CPU per shard = (sharded − one machine) / N. Every merged pack was byte-identical to the one-machine pack (\`cmp\`), and every one-machine run to the first."
  echo
  echo "User and system time apart (shards + merge against one machine, medians over rounds), and minor page faults (from \`/usr/bin/time -v\`: 4 KiB pages the processes took fresh from the kernel, each zeroed in system time):"
  echo
  echo "| image | N | user s, sharded | user s, one machine | user ratio | system s, sharded | system s, one machine | minor faults (millions), sharded | one machine |"
  echo "|---|---:|---:|---:|---:|---:|---:|---:|---:|"
  for image in "${IMAGES[@]}"; do
    for n in $NS; do
      su=$(mr "$image" "$n" 17) ou=$(mr "$image" "$n" 19)
      echo "| ${LABEL[$image]} | $n | $(calc %.2f "$su") | $(calc %.2f "$ou") | $(calc %.3fx "$su / $ou") | $(m "$image" "$n" 18) | $(m "$image" "$n" 20) | $(calc %.2f "$(mr "$image" "$n" 15) / 1e6") | $(calc %.2f "$(mr "$image" "$n" 16) / 1e6") |"
    done
  done
  echo
  echo "### Merge"
  echo
  echo "| image | N | cut level | pages made above the cut | wall s | CPU s (user + sys) | peak RSS MiB | bytes read MB (copied + sums) | shards' files MB | output pack MB | MB/s read |"
  echo "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
  for image in "${IMAGES[@]}"; do
    for n in $NS; do
      mw=$(mr "$image" "$n" 8)
      read_b=$(calc %.0f "$(mg "$image" "$n" 6) + $(mg "$image" "$n" 7)")
      echo "| ${LABEL[$image]} | $n | $(mg "$image" "$n" 4) | $(mg "$image" "$n" 5) | $(calc %.2f "$mw") | $(m "$image" "$n" 4) | $(calc %.0f "$(mr "$image" "$n" 14) / 1024") | $(mb "$read_b") ($(mb "$(mg "$image" "$n" 6)") + $(mb "$(mg "$image" "$n" 7)")) | $(mb "$(mg "$image" "$n" 8)") | $(mb "$(mg "$image" "$n" 9)") | $(awk -v b="$read_b" -v w="$mw" 'BEGIN { if (w > 0) printf "%.0f", b / 1e6 / w; else print "-" }') |"
    done
  done
  echo
  echo "Bytes read = the shards' tile payloads copied as they are plus the compressed exact sums of the cut level's pages; the rest of a shard file is its index and metadata. The shards were written just before, so the merge read them from the page cache; MB/s = bytes read / wall (1 MB = 10^6 bytes). The merge maps the shard packs into memory (vortex-pack's reader uses mmap), so its peak RSS counts the shards' file pages it has touched, which the kernel can drop, not memory it allocated."
  echo
  echo "### Per-shard wall time"
  echo
  echo "| image | N | Mpx per shard (mean) | slowest shard s | median shard s | slowest / median | one machine wall s | merge wall s |"
  echo "|---|---:|---:|---:|---:|---:|---:|---:|"
  for image in "${IMAGES[@]}"; do
    for n in $NS; do
      slow=$(mr "$image" "$n" 6) med=$(mr "$image" "$n" 7)
      echo "| ${LABEL[$image]} | $n | $(calc %.1f "${W[$image]} * ${H[$image]} / $n / 1e6") | $(calc %.2f "$slow") | $(calc %.2f "$med") | $(calc %.2f "$slow / $med") | $(m "$image" "$n" 9) | $(m "$image" "$n" 8) |"
    done
  done
  echo
  echo "### Projection: ${TARGET} x ${TARGET} on M machines"
  echo
  echo "**A projection from the measurements above, not a measurement.** For M machines of this kind ($(nproc) cores each) and a measured image of p pixels cut into N shards:"
  echo
  echo '```'
  echo "critical path(M) = t_slowest(N) x (P / M) / (p / N)  +  t_merge(N) x (P / p)"
  echo "one machine      = t_one x (P / p)"
  echo '```'
  echo
  echo "with P = ${TARGET}² = $(calc %.0f "$TARGET * $TARGET / 1e6") Mpx, t_slowest the slowest shard's wall time scaled by pixels per shard, t_merge the merge's wall time scaled by pack size (taken proportional to pixels: same content, same codec), N = M where measured, else the largest measured N below M (the smallest measured N if none is). It assumes time linear in pixels, a source each machine reads at page-cache speed, and nothing for moving the shard packs to the merging machine."
  echo
  echo "| from | M | N used | slowest shard s | merge s | critical path s | one machine s | speed-up |"
  echo "|---|---:|---:|---:|---:|---:|---:|---:|"
  for image in "${IMAGES[@]}"; do
    p=$((${W[$image]} * ${H[$image]}))
    scale=$(calc %.6f "$TARGET * $TARGET / $p")
    t_one=$(mr "$image" "${NS%% *}" 9)
    for mach in "${MACHINES[@]}"; do
      use=
      for n in $NS; do [ "$n" -le "$mach" ] && { [ -z "$use" ] || [ "$n" -gt "$use" ]; } && use=$n; done
      [ -n "$use" ] || use=$(tr ' ' '\n' <<<"$NS" | grep . | sort -n | head -1)
      ts=$(calc %.1f "$(mr "$image" "$use" 6) * ($TARGET * $TARGET / $mach) / ($p / $use)")
      tm=$(calc %.1f "$(mr "$image" "$use" 8) * $scale")
      one=$(calc %.0f "$t_one * $scale")
      echo "| ${LABEL[$image]} | $mach | $use | $ts | $tm | $(calc %.1f "$ts + $tm") | $one | $(calc %.1fx "$one / ($ts + $tm)") |"
    done
  done
  echo
  if [ "$WIDE" = 1 ]; then
    echo "### Memory: a 200000 x 2000 image in $WIDE_N shards"
    echo
    echo "\`bench/work/$WIDE_SRC\` (RGB 8-bit PNG, 400 Mpx, from \`gen_image\` (crates/vortex-bench) as in bench/wide-images.sh), the same commands with N = $WIDE_N, default \`--max-memory\` (1G), one round:"
    echo
    k=wide:$WIDE_N
    row() { awk -F'\t' -v k="$k" -v c="$1" '$1 == k { print $c }' "$AGG"; }
    wide_rss=$(awk -F'\t' '$1 == "wide" && $2 == "shard" { print $7 }' "$RAW" | sort -g | awk '{ v[NR] = $1 } END { print NR % 2 ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2 }')
    echo "| run | peak RSS MiB | wall s | CPU s |"
    echo "|---|---:|---:|---:|"
    echo "| one machine | $(calc %.0f "$(row 11) / 1024") | $(row 9) | $(row 5) |"
    echo "| largest shard (shard $(row 13) of $WIDE_N) | $(calc %.0f "$(row 10) / 1024") | $(awk -F'\t' -v i="$(row 13)" '$1 == "wide" && $2 == "shard" && $5 == i { print $6 }' "$RAW") | $(awk -F'\t' -v i="$(row 13)" '$1 == "wide" && $2 == "shard" && $5 == i { print $8 + $9 }' "$RAW") |"
    wide_cpu=$(awk -F'\t' '$1 == "wide" && $2 == "shard" { print $8 + $9 }' "$RAW" | sort -g | awk '{ v[NR] = $1 } END { print NR % 2 ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2 }')
    echo "| median shard (each column's median) | $(calc %.0f "$wide_rss / 1024") | $(calc %.2f "$(row 7)") | $(calc %.2f "$wide_cpu") |"
    echo "| merge | $(calc %.0f "$(row 14) / 1024") | $(row 8) | $(row 4) |"
    echo "| all $WIDE_N shards + merge | | | $(calc %.2f "$(row 3) + $(row 4)") ($(calc %.2f "$(row 12)")x one machine) |"
    echo
    echo "Cut level $(mg wide $WIDE_N 4); merged pack identical to the one-machine pack. A PNG can neither seek nor read part of a row: every shard decodes the whole width of every row from the top down to the end of its region (the rows above it are decoded and dropped), which is where the CPU ratio comes from."
    echo
  fi
  echo "Raw numbers: \`bench/work/scale-out-runs.tsv\` (every process: image, kind, N, round, shard index, wall s, peak RSS KiB, user s, system s, load, minor page faults), \`scale-out-merge.tsv\` (merge --json per N and round), \`scale-out-rounds.tsv\` (per round sums). Reproduce with \`bench/scale-out.sh\` (see its header)."
} >"$REPORT"

splice scale-out "$REPORT" "" # no INTRO: fails if the doc lost its markers while this ran
cat "$REPORT"
log "wrote $DOC"
