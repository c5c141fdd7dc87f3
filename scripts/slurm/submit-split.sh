#!/usr/bin/env bash
# Submits a sharded `vortex-tiler split` to Slurm (docs/scale-out.md): a job array of N tasks,
# each running scripts/slurm/split.sbatch (one shard pack into PARTS), and a merge job that
# starts when every task has succeeded (--dependency=afterok:ARRAY) and joins the shards into
# OUTPUT, byte-identical to `vortex-tiler split INPUT --pack OUTPUT` on one machine.
#
#   scripts/slurm/submit-split.sh INPUT OUTPUT.vtpk --shards N [--parts DIR] [--cpus N]
#                                 [--wait [--timeout S]] [-- SPLIT OPTION...]
#
# Prints the two job ids on standard output as one line, `ARRAYJOB MERGEJOB`, and what they do
# on standard error. Run `submit-split.sh --help` for the options.
#
# Environment: VORTEX_TILER (the binary; default: vortex-tiler on PATH), resolved here to an
# absolute path that every node must see; SLURM_CONF and sbatch's own input variables
# (SBATCH_PARTITION, SBATCH_ACCOUNT, SBATCH_TIMELIMIT, ...) reach both sbatch calls.
set -euo pipefail

PROG=submit-split.sh
HERE=$(cd "$(dirname "$0")" && pwd)
POLL=0.5 # seconds between two looks at the jobs with --wait

usage() {
  cat <<EOF
usage: $PROG INPUT OUTPUT.vtpk --shards N [--parts DIR] [--cpus N] [--wait [--timeout S]] [-- SPLIT OPTION...]

Cuts INPUT in N shards on a Slurm cluster and merges them into OUTPUT.vtpk: the same bytes as
\`vortex-tiler split INPUT --pack OUTPUT.vtpk [SPLIT OPTION...]\` on one machine.

  --shards N     the number of shards: a job array of N tasks (--array=0-\$((N-1))), each
                 \`vortex-tiler split INPUT --pack PARTS/shard-{shard}.vtpk --shard auto\`
  --parts DIR    where the shard packs and the jobs' logs (DIR/logs/) go
                 [default: OUTPUT without .vtpk, plus .parts: huge.vtpk -> huge.parts/]
  --cpus N       CPUs for each task and for the merge job (sbatch --cpus-per-task) [default:
                 the cluster's, usually 1]
  --wait         wait for the merge job; exit 0 when OUTPUT is written, 1 when a task or the
                 merge failed, after printing the failed jobs' logs
  --timeout S    with --wait: give up after S seconds (the jobs keep running) [default: none]
  -- OPTION...   options for every \`vortex-tiler split\` task (--tile-size 256 --border 4 ...)
  -h, --help     this text

INPUT, OUTPUT, DIR and the vortex-tiler binary (\$VORTEX_TILER or the one on PATH) must be at
the same path on every node: a shared filesystem. Pass other sbatch options through sbatch's
environment (SBATCH_PARTITION=gpu SBATCH_TIMELIMIT=30 $PROG ...).

Prints \`ARRAYJOB MERGEJOB\` on standard output. Example:
  $PROG huge.tif huge.vtpk --shards 16 --wait -- --tile-size 256 --border 4
EOF
}

# bad MESSAGE: a usage error (exit 2).
bad() {
  echo "$PROG: $*" >&2
  echo "run '$PROG --help' for the options" >&2
  exit 2
}
die() {
  echo "$PROG: $*" >&2
  exit 1
}
say() { echo "$PROG: $*" >&2; }
abs() { case $1 in /*) echo "$1" ;; *) echo "$PWD/$1" ;; esac }

positional=() shards="" parts="" cpus="" wait=0 timeout="" opts=()
while [ $# -gt 0 ]; do
  case $1 in
  -h | --help)
    usage
    exit 0
    ;;
  --shards | --parts | --cpus | --timeout)
    [ $# -ge 2 ] || bad "$1 needs a value"
    case $1 in
    --shards) shards=$2 ;;
    --parts) parts=$2 ;;
    --cpus) cpus=$2 ;;
    --timeout) timeout=$2 ;;
    esac
    shift 2
    ;;
  --shards=* | --parts=* | --cpus=* | --timeout=*)
    set -- "${1%%=*}" "${1#*=}" "${@:2}"
    ;;
  --wait)
    wait=1
    shift
    ;;
  --)
    shift
    opts=("$@")
    break
    ;;
  -*) bad "unknown option '$1' (options for vortex-tiler split go after --)" ;;
  *)
    positional+=("$1")
    shift
    ;;
  esac
done

[ ${#positional[@]} -ge 1 ] || bad "give INPUT and OUTPUT.vtpk"
[ ${#positional[@]} -ge 2 ] || bad "give OUTPUT.vtpk after INPUT: the pack the merge job writes"
[ ${#positional[@]} -le 2 ] || bad "one INPUT and one OUTPUT, not '${positional[*]}' (options for vortex-tiler split go after --)"
input=${positional[0]} output=${positional[1]}
[ -n "$shards" ] || bad "give --shards N: how many array tasks cut the image"
[[ $shards =~ ^[1-9][0-9]*$ ]] || bad "--shards '$shards' is not a whole number above 0"
[ -z "$cpus" ] || [[ $cpus =~ ^[1-9][0-9]*$ ]] || bad "--cpus '$cpus' is not a whole number above 0"
if [ -n "$timeout" ]; then
  [ "$wait" = 1 ] || bad "--timeout is for --wait"
  [[ $timeout =~ ^[1-9][0-9]*$ ]] || bad "--timeout '$timeout' is not a whole number of seconds above 0"
fi
[ -f "$input" ] || bad "$input: no such file (the image to split)"
case $output in
*/) bad "OUTPUT '$output' is a directory; give the pack file to write (e.g. huge.vtpk)" ;;
esac
[ ! -d "$output" ] || bad "OUTPUT '$output' is a directory; give the pack file to write (e.g. huge.vtpk)"
[ -d "$(dirname "$output")" ] || bad "$output: directory $(dirname "$output") does not exist"
[ -n "$parts" ] || parts=${output%.vtpk}.parts

tiler=${VORTEX_TILER:-$(command -v vortex-tiler || true)}
[ -n "$tiler" ] || bad "no vortex-tiler on PATH: set VORTEX_TILER to the binary (e.g. target/release/vortex-tiler)"
if [ ! -f "$tiler" ] || [ ! -x "$tiler" ]; then bad "VORTEX_TILER=$tiler is not an executable file"; fi
command -v sbatch >/dev/null 2>&1 ||
  die "no sbatch on PATH: run this on a Slurm login node (or: scripts/slurm/local-cluster.sh start; eval \"\$(scripts/slurm/local-cluster.sh env)\")"

input=$(abs "$input") output=$(abs "$output") parts=$(abs "$parts") tiler=$(abs "$tiler")
logs=$parts/logs
mkdir -p "$logs" || die "cannot create $logs"
export VORTEX_TILER=$tiler
unset SHARDS # split.sbatch's other mode; these tasks take --shard auto

common=(--parsable)
[ -z "$cpus" ] || common+=(--cpus-per-task="$cpus")

# parsable ID[;CLUSTER] -> ID
job_id() { echo "${1%%;*}"; }

array=$(sbatch "${common[@]}" --array="0-$((shards - 1))" --job-name=vortex-split \
  --output="$logs/split-%A_%a.log" "$HERE/split.sbatch" "$input" "$parts" -- "${opts[@]}") ||
  die "sbatch of the split array failed"
array=$(job_id "$array")

# The merge job: the N shard names as split.sbatch writes them ({shard} = I zero-padded to the
# width of N-1), not a glob, so that shards of an earlier run with another N are never taken.
merge_script() {
  local last=$((shards - 1))
  printf '#!/usr/bin/env bash\n# vortex-tiler merge of the %d shards of split job array %s (submit-split.sh)\n' "$shards" "$array"
  printf 'parts=%q output=%q tiler=%q count=%d width=%d\n' "$parts" "$output" "$tiler" "$shards" "${#last}"
  cat <<'EOF'
set -euo pipefail
shards=()
for ((i = 0; i < count; i++)); do
  printf -v name '%s/shard-%0*d.vtpk' "$parts" "$width" "$i"
  shards+=("$name")
done
echo "merge job ${SLURM_JOB_ID:-?} on $(hostname): $tiler merge ${shards[0]} .. ${shards[count - 1]} -o $output" >&2
exec "$tiler" merge "${shards[@]}" -o "$output"
EOF
}
merge=$(merge_script | sbatch "${common[@]}" --job-name=vortex-merge --dependency="afterok:$array" \
  --kill-on-invalid-dep=yes --output="$logs/merge-%j.log") || {
  scancel "$array" 2>/dev/null || true
  die "sbatch of the merge job failed; cancelled the split array $array"
}
merge=$(job_id "$merge")

say "split: job array $array, $shards tasks into $parts/shard-*.vtpk, logs $logs/split-${array}_I.log"
say "merge: job $merge (afterok:$array) into $output, log $logs/merge-$merge.log"
echo "$array $merge"
[ "$wait" = 1 ] || exit 0

# ---- --wait: poll slurmctld (sbatch --wait polls at growing intervals up to 10 s). ----

# records JOBID: one line per job (or per array task) from `scontrol show job -o`.
records() { scontrol show job -o "$1" 2>/dev/null || true; }
# field NAME LINE: the value of NAME= in a one-line record (values without spaces).
field() { if [[ " $2 " =~ \ $1=([^ ]*)\  ]]; then echo "${BASH_REMATCH[1]}"; fi; }
terminal() {
  case $1 in
  COMPLETED | FAILED | CANCELLED | TIMEOUT | NODE_FAIL | OUT_OF_MEMORY | PREEMPTED | BOOT_FAIL | DEADLINE) return 0 ;;
  esac
  return 1
}
show_log() { # title file
  echo "----- $1: ${2:-no log} -----" >&2
  if [ -n "$2" ] && [ -s "$2" ]; then tail -n 40 "$2" >&2; else echo "(empty or missing)" >&2; fi
}

started=$SECONDS
state="" reason=""
while :; do
  rec=$(records "$merge")
  [ -n "$rec" ] || die "slurmctld no longer knows merge job $merge; see $logs/"
  state=$(field JobState "$rec") reason=$(field Reason "$rec")
  terminal "$state" && break
  if [ "$state" = PENDING ] && [ "$reason" = DependencyNeverSatisfied ]; then
    scancel "$merge" 2>/dev/null || true
    state=CANCELLED
    break
  fi
  if [ -n "$timeout" ] && [ $((SECONDS - started)) -ge "$timeout" ]; then
    die "gave up after $timeout s: merge job $merge is $state${reason:+ ($reason)}; the jobs go on (scancel $array $merge stops them)"
  fi
  sleep "$POLL"
done

if [ "$state" = COMPLETED ]; then
  say "done in $((SECONDS - started)) s: $shards tasks of job array $array and merge job $merge completed; wrote $output"
  exit 0
fi

failed=0 going=""
while read -r line; do
  [ -n "$line" ] || continue
  s=$(field JobState "$line") task=$(field ArrayTaskId "$line")
  if ! terminal "$s"; then
    going+=" $task"
  elif [ "$s" != COMPLETED ]; then
    failed=$((failed + 1))
    show_log "task $task (job ${array}_$task) $s, exit code $(field ExitCode "$line")" "$logs/split-${array}_$task.log"
  fi
done < <(records "$array")
[ -z "$going" ] || say "tasks still pending or running:$going (scancel $array stops them)"
if [ "$failed" -gt 0 ]; then
  die "$failed of $shards split tasks of job array $array failed, so merge job $merge was $state: $output not written"
fi
show_log "merge job $merge $state, exit code $(field ExitCode "$rec")" "$logs/merge-$merge.log"
die "merge job $merge $state: $output not written"
