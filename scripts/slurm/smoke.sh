#!/usr/bin/env bash
# Smoke check of the local Slurm cluster (scripts/slurm/local-cluster.sh): starts it, runs a
# plain job, a 4-task job array, a job that depends on the array (afterok), a failing job and
# one that depends on it, checks every output, then stops the cluster again if this script
# (or another smoke.sh running beside it) started it, once the last of them is done;
# VORTEX_SLURM_KEEP=1 leaves it running.
# Exits non-zero on the first failure.
#
#   scripts/slurm/smoke.sh
#
# Environment: as local-cluster.sh (VORTEX_SLURM_DIR, ...); VORTEX_SLURM_KEEP=1.
set -euo pipefail

HERE=$(cd "$(dirname "$0")" && pwd)
LC=$HERE/local-cluster.sh
JOB_TIMEOUT=120 # seconds any one `sbatch --wait` may take
DIR=${VORTEX_SLURM_DIR:-/tmp/vortex-slurm}
MARK=""
passed=0
W=""

fail() {
  echo "smoke: FAILED: $*" >&2
  if [ -n "${SLURM_CONF:-}" ]; then
    squeue >&2 || true
    local d
    d=$(dirname "$(dirname "$SLURM_CONF")")/log
    for f in "$d/slurmctld.log" "$d/slurmd.log"; do
      [ -s "$f" ] && {
        echo "----- last lines of $f -----" >&2
        tail -n 15 "$f" >&2
      }
    done
  fi
  exit 1
}
ok() {
  passed=$((passed + 1))
  echo "ok $passed - $*"
}
cleanup() {
  local rc=$?
  exec 8>&- # drop this run's shared hold on users.lock
  # The last smoke.sh out stops the cluster if a smoke.sh started it (parallel test runs share
  # it): exclusive users.lock means no other user is on it, and holding it while stopping
  # keeps a newcomer from starting to use it meanwhile (exit 75: the lock is taken).
  if [ -e "$MARK" ] && [ "${VORTEX_SLURM_KEEP:-0}" != 1 ]; then
    local stopped=0
    flock -n -x -o -E 75 "$DIR/users.lock" "$LC" stop || stopped=$?
    case $stopped in
      0) rm -f "$MARK" ;;
      75) echo "smoke: another user is on the cluster; the last one out stops it" ;;
      *) rc=1 ;;
    esac
  fi
  [ -n "$W" ] && rm -rf "$W"
  exit "$rc"
}
trap cleanup EXIT

# expect_file FILE CONTENT
expect_file() {
  [ -f "$1" ] || fail "$1 was not written"
  local got
  got=$(cat "$1")
  [ "$got" = "$2" ] || fail "$1 holds '$got', expected '$2'"
}

# job_state JOBID: the job's JobState as slurmctld reports it (jobs stay listed for MinJobAge).
job_state() { scontrol show job "$1" 2>/dev/null | grep -o 'JobState=[A-Z_]*' | head -n 1 | cut -d= -f2; }

# A shared lock held while this script uses the cluster; the daemons must not inherit it (8>&-).
mkdir -p "$DIR"
exec 8>>"$DIR/users.lock"
flock -s 8
MARK=$DIR/started-by-smoke # present while a smoke.sh started the cluster
if ! "$LC" status >/dev/null 2>&1 8>&-; then
  touch "$MARK"
fi
"$LC" start 8>&- || fail "local-cluster.sh start"
eval "$("$LC" env 8>&-)"
export SLURM_CONF

W=$(mktemp -d /tmp/vortex-slurm-smoke.XXXXXX)
cd "$W"
host=$(hostname)

# Everything is submitted first and checked after: `sbatch --wait` polls every 2 s, then 8 s,
# so waiting for each job in turn would take about 10 s a job.
wait_bg() { # pid: the exit status of a background `sbatch --wait`
  local rc=0
  wait "$1" || rc=$?
  [ "$rc" -ne 124 ] || fail "an sbatch --wait ran past ${JOB_TIMEOUT} s"
  return "$rc"
}

# 1. A plain job; --wait returns its exit code.
timeout "$JOB_TIMEOUT" sbatch --quiet --wait --time=2 -o "$W/hostname.out" --wrap 'hostname' &
p_host=$!
# shellcheck disable=SC2016 # $SLURM_ARRAY_TASK_* expand in the job, not here.
# 2. A 4-task job array, each task writing its index and the task count to its own file.
timeout "$JOB_TIMEOUT" sbatch --quiet --wait --time=2 --array=0-3 -o "$W/array_%a.out" \
  --wrap 'echo $SLURM_ARRAY_TASK_ID $SLURM_ARRAY_TASK_COUNT' &
p_array=$!
# shellcheck disable=SC2016
# 3. A job that depends on a whole array (afterok) runs after every task, like a merge of shards.
array=$(sbatch --parsable --time=2 --array=0-3 -o "$W/shard_%a.out" \
  --wrap 'sleep 1; echo shard $SLURM_ARRAY_TASK_ID') || fail "sbatch shard array"
array=${array%%;*}
timeout "$JOB_TIMEOUT" sbatch --quiet --wait --time=2 --dependency="afterok:$array" -o "$W/merge.out" \
  --wrap "cat $W/shard_0.out $W/shard_1.out $W/shard_2.out $W/shard_3.out" &
p_merge=$!
# 4. A failing job: sbatch --wait exits non-zero.
timeout "$JOB_TIMEOUT" sbatch --quiet --wait --time=2 -o /dev/null --wrap 'exit 3' &
p_fail=$!
# 5. A job that depends (afterok) on a failing one never runs (--kill-on-invalid-dep cancels it).
bad=$(sbatch --parsable --time=2 -o /dev/null --wrap 'sleep 1; exit 3') || fail "sbatch failing job"
dep=$(sbatch --parsable --time=2 --dependency="afterok:$bad" --kill-on-invalid-dep=yes \
  -o /dev/null --wrap "touch $W/must-not-run") || fail "sbatch dependent of failing job"

wait_bg $p_host || fail "sbatch --wait --wrap hostname exited $?"
expect_file "$W/hostname.out" "$host"
ok "sbatch --wait --wrap hostname printed '$host'"

wait_bg $p_array || fail "sbatch --array=0-3 --wait exited $?"
for i in 0 1 2 3; do expect_file "$W/array_$i.out" "$i 4"; done
ok "job array 0-3: each task wrote 'INDEX 4'"

wait_bg $p_merge || fail "sbatch --dependency=afterok:$array --wait exited $?"
expect_file "$W/merge.out" "$(printf 'shard %s\n' 0 1 2 3)"
ok "job with --dependency=afterok:$array ran after all 4 array tasks"

rc=0
wait_bg $p_fail || rc=$?
[ "$rc" -ne 0 ] || fail "sbatch --wait of a job that exits 3 returned 0"
ok "sbatch --wait of a failing job exits $rc"

state=""
for ((i = 0; i < 60; i++)); do
  state=$(job_state "$dep")
  case $state in CANCELLED | COMPLETED | FAILED) break ;; esac
  sleep 0.5
done
[ "$state" = CANCELLED ] || fail "job $dep (afterok:$bad, which failed) is '$state', expected CANCELLED"
[ ! -e "$W/must-not-run" ] || fail "job $dep ran although job $bad failed"
ok "job with afterok on a failing job was cancelled, not run"

echo "smoke: all $passed Slurm checks passed"
