#!/usr/bin/env bash
# A real single-node Slurm cluster on this machine, from Debian's slurm-wlm and munge packages.
#
#   scripts/slurm/local-cluster.sh start    install what is missing, start munged, slurmctld, slurmd;
#                                           wait until the node is idle; print how to use it
#   scripts/slurm/local-cluster.sh stop     stop slurmd and slurmctld (and munged if start started it)
#   scripts/slurm/local-cluster.sh status   sinfo and squeue, or "not running" (exit 3)
#   scripts/slurm/local-cluster.sh env      print `export SLURM_CONF=...` (for eval)
#
# Everything Slurm writes (generated slurm.conf, state, spool, logs, pid files) lives under
# $VORTEX_SLURM_DIR (default /tmp/vortex-slurm); the daemons and clients are pointed at the
# generated config with SLURM_CONF, so a system /etc/slurm is never read nor written.
# Outside that directory, start may: apt-get install slurm-wlm and munge; create
# /etc/munge/munge.key (owner munge, mode 0400) when there is none; start munged.
# Meant for root on a machine without systemd (a container); daemons are started directly.
#
# Environment: VORTEX_SLURM_DIR, VORTEX_SLURM_TIMEOUT (seconds to wait for an idle node, 30),
# VORTEX_SLURMCTLD_PORT (6817), VORTEX_SLURMD_PORT (6818). Without those two, start tries Slurm's
# own ports 6817/6818, and when a daemon finds its port taken ("Address already in use") it
# stops what it started and tries another pair (up to PORT_ATTEMPTS); the ports chosen are in
# the generated slurm.conf, which clients read through SLURM_CONF. Ports given are used as given.
set -euo pipefail

PROG=local-cluster.sh
DIR=${VORTEX_SLURM_DIR:-/tmp/vortex-slurm}
TIMEOUT=${VORTEX_SLURM_TIMEOUT:-30}
CTLD_PORT=${VORTEX_SLURMCTLD_PORT:-6817}
D_PORT=${VORTEX_SLURMD_PORT:-6818}
PORTS_GIVEN=0
[ -z "${VORTEX_SLURMCTLD_PORT:-}${VORTEX_SLURMD_PORT:-}" ] || PORTS_GIVEN=1
PORT_ATTEMPTS=6
TAKEN=75 # what a daemon's start step returns when its port is taken
CONF=$DIR/etc/slurm.conf
LOG=$DIR/log
RUN=$DIR/run
MUNGE_KEY=/etc/munge/munge.key
MUNGE_PIDFILE=/run/munge/munged.pid
MUNGE_MARK=$RUN/munged.started-by-us # holds munged's pid when this script started it

say() { echo "$PROG: $*"; }
tail_logs() {
  local f
  for f in "$@"; do
    [ -s "$f" ] || continue
    echo "----- last lines of $f -----" >&2
    tail -n 25 "$f" >&2
  done
}
# die STEP MESSAGE [LOGFILE...]: a clear failure naming the step, with the tail of the logs.
die() {
  local step=$1 msg=$2
  shift 2
  echo "$PROG: FAILED at step '$step': $msg" >&2
  tail_logs "$@"
  [ "${CMD:-}" != start ] || echo "$PROG: whatever did start is still running; '$0 stop' stops it" >&2
  exit 1
}

pid_alive() { # pidfile [expected comm]
  local pid
  [ -s "$1" ] || return 1
  pid=$(cat "$1" 2>/dev/null) || return 1
  [[ $pid =~ ^[0-9]+$ ]] || return 1
  kill -0 "$pid" 2>/dev/null || return 1
  if [ -n "${2:-}" ]; then
    [ "$(cat "/proc/$pid/comm" 2>/dev/null)" = "$2" ] || return 1
  fi
}

# Stops the process in pidfile with SIGTERM, then SIGKILL after a bounded wait.
stop_pidfile() { # name pidfile
  local name=$1 pf=$2 pid i
  if ! pid_alive "$pf" "$name"; then
    rm -f "$pf"
    return 0
  fi
  pid=$(cat "$pf")
  kill -TERM "$pid" 2>/dev/null || true
  for ((i = 0; i < 100; i++)); do
    kill -0 "$pid" 2>/dev/null || break
    sleep 0.1
  done
  if kill -0 "$pid" 2>/dev/null; then
    say "$name (pid $pid) did not stop within 10 s; sending SIGKILL"
    kill -KILL "$pid" 2>/dev/null || true
    sleep 0.2
  fi
  rm -f "$pf"
  say "stopped $name (pid $pid)"
}

ctld_running() { pid_alive "$RUN/slurmctld.pid" slurmctld; }
slurmd_running() { pid_alive "$RUN/slurmd.pid" slurmd; }
munge_works() { munge -n 2>/dev/null | unmunge >/dev/null 2>&1; }

node_name() { hostname -s; }
node_state() { sinfo -h -N -n "$(node_name)" -o '%T' 2>/dev/null | head -n 1; }

step_packages() {
  local need=()
  for c in slurmctld slurmd sinfo sbatch; do
    command -v "$c" >/dev/null 2>&1 || need=(slurm-wlm)
  done
  command -v munged >/dev/null 2>&1 || need+=(munge)
  [ ${#need[@]} -eq 0 ] && return 0
  [ "$(id -u)" -eq 0 ] || die packages "need root to apt-get install ${need[*]}"
  say "installing ${need[*]} with apt-get"
  export DEBIAN_FRONTEND=noninteractive
  mkdir -p "$LOG"
  # The packages' postinst would start the daemons from /etc (init scripts): a policy-rc.d that
  # says no (exit 101), as container images have, keeps them off; put one only for this install.
  local policy=/usr/sbin/policy-rc.d ours=0 rc=0
  if [ ! -e "$policy" ]; then
    printf '#!/bin/sh\n# temporary, from vortex scripts/slurm/local-cluster.sh\nexit 101\n' >"$policy"
    chmod 0755 "$policy"
    ours=1
  fi
  { apt-get update -qq && apt-get install -y -qq --no-install-recommends "${need[@]}"; } \
    >"$LOG/apt.log" 2>&1 || rc=$?
  [ "$ours" = 0 ] || rm -f "$policy"
  [ "$rc" = 0 ] || die packages "apt-get install ${need[*]} failed (exit $rc)" "$LOG/apt.log"
  for c in slurmctld slurmd sinfo sbatch munged munge unmunge; do
    command -v "$c" >/dev/null 2>&1 || die packages "$c is still missing after apt-get install" "$LOG/apt.log"
  done
}

step_munge_key() {
  getent passwd munge >/dev/null || die munge-key "no 'munge' user (the munge package creates it)"
  install -d -o munge -g munge -m 0700 /etc/munge
  if [ ! -s "$MUNGE_KEY" ]; then
    say "creating $MUNGE_KEY"
    if command -v mungekey >/dev/null 2>&1; then
      mungekey --create --keyfile="$MUNGE_KEY" --force ||
        die munge-key "mungekey --create failed"
    else
      dd if=/dev/urandom of="$MUNGE_KEY" bs=1024 count=1 status=none ||
        die munge-key "writing random bytes to $MUNGE_KEY failed"
    fi
  fi
  if ! { chown munge:munge "$MUNGE_KEY" && chmod 0400 "$MUNGE_KEY"; }; then
    die munge-key "cannot set owner munge and mode 0400 on $MUNGE_KEY"
  fi
}

step_munged() {
  if munge_works; then
    return 0
  fi
  # The directories systemd's tmpfiles would make; munged refuses loose permissions.
  install -d -o munge -g munge -m 0755 /run/munge
  install -d -o munge -g munge -m 0700 /var/lib/munge /var/log/munge
  rm -f /run/munge/munge.socket.2 /run/munge/munge.socket.2.lock "$MUNGE_PIDFILE"
  say "starting munged"
  # As the munge user, like munge.service; munged daemonizes and writes its pid file.
  if ! runuser -u munge -- /usr/sbin/munged >"$LOG/munged.start.log" 2>&1 9>&-; then
    die munged "munged did not start" "$LOG/munged.start.log" /var/log/munge/munged.log
  fi
  local i
  for ((i = 0; i < 50; i++)); do
    munge_works && break
    sleep 0.2
  done
  munge_works || die munged "munged started but 'munge -n | unmunge' fails" \
    "$LOG/munged.start.log" /var/log/munge/munged.log
  cat "$MUNGE_PIDFILE" >"$MUNGE_MARK"
}

# The node's CPUs, sockets, cores, threads and RealMemory as slurmd itself sees them.
node_hw() {
  local hw
  hw=$(env -u SLURM_CONF slurmd -C 2>"$LOG/slurmd-C.log" | grep -m1 '^NodeName=') ||
    die config "'slurmd -C' printed no NodeName line" "$LOG/slurmd-C.log"
  # Drop NodeName=...; keep CPUs=.. Boards=.. SocketsPerBoard=.. CoresPerSocket=.. ThreadsPerCore=.. RealMemory=..
  echo "${hw#NodeName=* }"
}

step_config() {
  local host hw
  host=$(node_name)
  [ -n "$host" ] || die config "'hostname -s' is empty"
  hw=$(node_hw)
  mkdir -p "$DIR/etc" "$DIR/state" "$DIR/spool/slurmd" "$LOG" "$RUN"
  cat >"$CONF.tmp" <<EOF
# Generated by scripts/slurm/local-cluster.sh: a single-node cluster on $host.
# Rewritten at every start while the cluster is stopped; use with SLURM_CONF=$CONF
ClusterName=vortex
SlurmctldHost=$host(127.0.0.1)
SlurmUser=root
SlurmdUser=root
SlurmctldPort=$CTLD_PORT
SlurmdPort=$D_PORT
AuthType=auth/munge
CredType=cred/munge
StateSaveLocation=$DIR/state
SlurmdSpoolDir=$DIR/spool/slurmd
SlurmctldPidFile=$RUN/slurmctld.pid
SlurmdPidFile=$RUN/slurmd.pid
SlurmctldLogFile=$LOG/slurmctld.log
SlurmdLogFile=$LOG/slurmd.log
SlurmctldDebug=info
SlurmdDebug=info
# No systemd and no cgroups here: track processes through /proc, no task confinement.
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
MpiDefault=none
SwitchType=switch/none
SchedulerType=sched/backfill
# Schedule batch jobs at once (the default batch_sched_delay=3 starts at most one pass every 3 s).
SchedulerParameters=batch_sched_delay=0
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
MailProg=/bin/true
SlurmdTimeout=60
InactiveLimit=0
KillWait=5
MinJobAge=300
MaxArraySize=10001
NodeName=$host NodeAddr=127.0.0.1 $hw State=UNKNOWN
PartitionName=debug Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF
  # Some plugins read cgroup.conf beside slurm.conf; say plainly that no cgroup is mounted here.
  cat >"$DIR/etc/cgroup.conf.tmp" <<EOF
# Generated by scripts/slurm/local-cluster.sh: cgroups are not used (proctrack/linuxproc, task/none).
CgroupAutomount=no
EOF
  mv "$CONF.tmp" "$CONF"
  mv "$DIR/etc/cgroup.conf.tmp" "$DIR/etc/cgroup.conf"
}

# Keeps the previous run's log as NAME.log.prev, so the tail printed on failure is this run's.
fresh_log() { [ ! -e "$LOG/$1.log" ] || mv -f "$LOG/$1.log" "$LOG/$1.log.prev"; }

# Whether NAME's logs of this start say that its port was taken.
port_taken() { grep -qs 'Address already in use' "$LOG/$1.start.log" "$LOG/$1.log"; }

# wait_daemon NAME SECONDS CHECK...: until CHECK succeeds; fails at once when NAME has died,
# returning $TAKEN instead when it died because its port was taken.
wait_daemon() {
  local name=$1 secs=$2 i
  shift 2
  for ((i = 0; i < secs * 5; i++)); do
    if pid_alive "$RUN/$name.pid" "$name"; then
      "$@" && return 0
    elif port_taken "$name"; then
      return "$TAKEN"
    elif [ "$i" -ge 10 ]; then # no live pid 2 s after start: it has exited
      die "$name" "$name exited after starting (see its log)" "$LOG/$name.start.log" "$LOG/$name.log"
    fi
    sleep 0.2
  done
  die "$name" "$name did not get ready within $secs s ($*)" "$LOG/$name.start.log" "$LOG/$name.log"
}
ctld_pings() { scontrol ping 2>/dev/null | grep -q 'is UP'; }

step_slurmctld() {
  ctld_running && return 0
  say "starting slurmctld"
  fresh_log slurmctld
  # -c: start with a clean job state; this cluster is for tests, jobs do not survive a restart.
  if ! slurmctld -c >"$LOG/slurmctld.start.log" 2>&1 9>&-; then
    port_taken slurmctld && return "$TAKEN"
    die slurmctld "slurmctld exited non-zero" "$LOG/slurmctld.start.log" "$LOG/slurmctld.log"
  fi
  wait_daemon slurmctld 20 ctld_pings
}

step_slurmd() {
  slurmd_running && return 0
  say "starting slurmd"
  fresh_log slurmd
  if ! slurmd -N "$(node_name)" >"$LOG/slurmd.start.log" 2>&1 9>&-; then
    port_taken slurmd && return "$TAKEN"
    die slurmd "slurmd exited non-zero" "$LOG/slurmd.start.log" "$LOG/slurmd.log"
  fi
  wait_daemon slurmd 10 true
}

# A fresh config and both daemons, on other ports while one is taken (see the header). A port is
# never found free and then released: the daemon binds it or says it could not.
step_daemons_on_free_ports() {
  local attempt rc
  for ((attempt = 1; ; attempt++)); do
    step_config
    rc=0
    step_slurmctld || rc=$?
    [ "$rc" != 0 ] || step_slurmd || rc=$?
    [ "$rc" != 0 ] || return 0
    stop_pidfile slurmd "$RUN/slurmd.pid" >/dev/null
    stop_pidfile slurmctld "$RUN/slurmctld.pid" >/dev/null
    if [ "$PORTS_GIVEN" = 1 ] || [ "$attempt" -ge "$PORT_ATTEMPTS" ]; then
      die ports "port $CTLD_PORT or $D_PORT is taken (after $attempt attempt(s)); set VORTEX_SLURMCTLD_PORT and VORTEX_SLURMD_PORT to free ones" \
        "$LOG/slurmctld.log" "$LOG/slurmd.log"
    fi
    say "port $CTLD_PORT or $D_PORT is taken; trying another pair"
    # A pair in the range Linux does not hand out on its own (below 32768).
    CTLD_PORT=$((20000 + (RANDOM % 6000) * 2))
    D_PORT=$((CTLD_PORT + 1))
  done
}

step_wait_idle() {
  local i state=""
  for ((i = 0; i < TIMEOUT * 2; i++)); do
    state=$(node_state)
    case $state in
    idle | mixed | allocated | completing) return 0 ;;
    esac
    # A node that comes up drained or down never becomes idle by itself: resume it once.
    case $state in
    drain* | down) scontrol update NodeName="$(node_name)" State=RESUME >/dev/null 2>&1 || true ;;
    esac
    sleep 0.5
  done
  local reason
  reason=$(sinfo -h -R -n "$(node_name)" -o '%E' 2>/dev/null || true)
  die wait-idle "node $(node_name) is '${state:-unknown}' after ${TIMEOUT} s, not idle${reason:+ (reason: $reason)}" \
    "$LOG/slurmctld.log" "$LOG/slurmd.log"
}

usage_hint() {
  cat <<EOF
$PROG: Slurm is up: node $(node_name), partition debug. To use it:
  export SLURM_CONF=$CONF
  sinfo; sbatch --wrap 'hostname'; squeue
Logs: $LOG   Stop: $0 stop
EOF
}

cmd_start() {
  [ "$(id -u)" -eq 0 ] || die start "run as root (daemons run as root, packages may be installed)"
  mkdir -p "$LOG" "$RUN"
  step_packages
  export SLURM_CONF=$CONF
  step_munge_key
  step_munged
  # Rewrite the config only when nothing reads it: a running cluster keeps its own.
  if ! ctld_running && ! slurmd_running; then
    step_daemons_on_free_ports
  elif [ ! -s "$CONF" ]; then
    die config "daemons are running from $DIR but $CONF is missing; run '$0 stop' first"
  else
    step_slurmctld || die slurmctld "its port is taken; '$0 stop' and start again" "$LOG/slurmctld.log"
    step_slurmd || die slurmd "its port is taken; '$0 stop' and start again" "$LOG/slurmd.log"
  fi
  step_wait_idle
  usage_hint
}

cmd_stop() {
  export SLURM_CONF=$CONF
  if ctld_running && [ -s "$CONF" ]; then
    # Cancel what is left so no slurmstepd outlives the daemons.
    scancel --user="$(id -un)" >/dev/null 2>&1 || true
  fi
  stop_pidfile slurmd "$RUN/slurmd.pid"
  stop_pidfile slurmctld "$RUN/slurmctld.pid"
  if [ -s "$MUNGE_MARK" ]; then
    if pid_alive "$MUNGE_PIDFILE" munged && [ "$(cat "$MUNGE_PIDFILE")" = "$(cat "$MUNGE_MARK")" ]; then
      stop_pidfile munged "$MUNGE_PIDFILE"
    fi
    rm -f "$MUNGE_MARK"
  fi
  say "stopped (state and logs kept in $DIR)"
}

cmd_status() {
  export SLURM_CONF=$CONF
  if ! ctld_running; then
    echo "not running"
    if slurmd_running; then echo "(but slurmd is running: pid $(cat "$RUN/slurmd.pid"))"; fi
    return 3
  fi
  echo "SLURM_CONF=$CONF"
  sinfo || true
  squeue || true
  slurmd_running || {
    echo "slurmd is not running"
    return 3
  }
}

# One start or stop at a time (parallel test runs may call start together).
lock() {
  mkdir -p "$DIR"
  exec 9>"$DIR/.lock"
  flock -w 120 9 || die lock "another start or stop holds $DIR/.lock"
}

CMD=${1:-}
case $CMD in
start) lock && cmd_start ;;
stop) lock && cmd_stop ;;
status) cmd_status ;;
env) echo "export SLURM_CONF=$CONF" ;;
*)
  echo "usage: $0 start|stop|status|env" >&2
  exit 2
  ;;
esac
