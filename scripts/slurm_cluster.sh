#!/usr/bin/env bash
# A single-node SLURM cluster on this machine, without systemd (tests, benchmarks, demos).
#
#   bash scripts/slurm_cluster.sh start   # prints: export SLURM_CONF=...
#   bash scripts/slurm_cluster.sh status
#   bash scripts/slurm_cluster.sh stop
#
# Installs Debian's slurm-wlm (22.05) and munge when missing (root: apt-get), starts munged as
# user munge with a generated key, then slurmctld and slurmd as root with a slurm.conf written
# to $PARSOLVE_SLURM_DIR (default /tmp/parsolve-slurm): no accounting, no cgroups
# (proctrack/linuxproc, task/none), one partition "debug" holding this node. Idempotent: start
# on a running cluster only prints the export line. Exit status 0 when the node is idle.
set -euo pipefail
DIR=${PARSOLVE_SLURM_DIR:-/tmp/parsolve-slurm}
CONF=$DIR/slurm.conf
HOST=$(hostname -s)
SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"

say() { echo "slurm_cluster: $*" >&2; }

alive() { [ -f "$1" ] && kill -0 "$(cat "$1")" 2>/dev/null; }

install() {
  local missing=""
  for p in slurm-wlm munge; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing="$missing $p"
  done
  if [ -n "$missing" ]; then
    say "installing$missing"
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq $missing >/dev/null
  fi
}

start_munge() {
  if munge -n 2>/dev/null | unmunge >/dev/null 2>&1; then return; fi
  if [ ! -s /etc/munge/munge.key ]; then
    say "generating /etc/munge/munge.key"
    $SUDO mkdir -p /etc/munge
    $SUDO dd if=/dev/urandom of=/etc/munge/munge.key bs=1 count=1024 status=none
  fi
  $SUDO mkdir -p /run/munge /var/log/munge /var/lib/munge
  $SUDO chown munge:munge /etc/munge/munge.key /run/munge /var/log/munge /var/lib/munge
  $SUDO chmod 400 /etc/munge/munge.key
  $SUDO chmod 755 /run/munge
  $SUDO runuser -u munge -- /usr/sbin/munged --force
  touch "$DIR/munged.ours"  # stop ends munged only when this script started it
  for _ in $(seq 50); do
    munge -n 2>/dev/null | unmunge >/dev/null 2>&1 && return
    sleep 0.1
  done
  say "munged does not answer"; exit 1
}

write_conf() {
  local cpus mem
  cpus=$(nproc)
  mem=$(free -m | awk '/^Mem:/ {print int($2 * 0.9)}')
  mkdir -p "$DIR/state" "$DIR/spool"
  cat > "$CONF" <<CONF
ClusterName=parsolve
SlurmctldHost=$HOST
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
SlurmctldPort=${PARSOLVE_SLURM_PORT:-6817}
SlurmdPort=$(( ${PARSOLVE_SLURM_PORT:-6817} + 1 ))
StateSaveLocation=$DIR/state
SlurmdSpoolDir=$DIR/spool
SlurmctldPidFile=$DIR/slurmctld.pid
SlurmdPidFile=$DIR/slurmd.pid
SlurmctldLogFile=$DIR/slurmctld.log
SlurmdLogFile=$DIR/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SwitchType=switch/none
MpiDefault=none
ReturnToService=2
SchedulerType=sched/backfill
# schedule pending tasks every second (default 60 s): short runs are the common case here
SchedulerParameters=sched_interval=1,sched_min_interval=100000,batch_sched_delay=0
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
AccountingStorageType=accounting_storage/none
JobAcctGatherType=jobacct_gather/none
JobCompType=jobcomp/none
SlurmctldTimeout=30
SlurmdTimeout=30
InactiveLimit=0
MinJobAge=60
KillWait=10
Waittime=0
MaxArraySize=10001
NodeName=$HOST CPUs=$cpus RealMemory=$mem State=UNKNOWN
PartitionName=debug Nodes=$HOST Default=YES MaxTime=INFINITE State=UP
CONF
}

start() {
  install
  mkdir -p "$DIR"
  export SLURM_CONF=$CONF
  if alive "$DIR/slurmctld.pid" && alive "$DIR/slurmd.pid"; then
    say "already running"
  else
    start_munge
    write_conf
    alive "$DIR/slurmctld.pid" || $SUDO /usr/sbin/slurmctld -f "$CONF" -i
    alive "$DIR/slurmd.pid" || $SUDO /usr/sbin/slurmd -f "$CONF"
  fi
  for _ in $(seq 150); do
    state=$(sinfo -h -n "$HOST" -o %T 2>/dev/null | head -n 1 || true)
    if [ "$state" = idle ] || [ "$state" = mixed ] || [ "$state" = allocated ]; then
      say "node $HOST $state"
      echo "export SLURM_CONF=$CONF"
      return 0
    fi
    sleep 0.2
  done
  say "node not idle after 30 s (state: ${state:-none}); logs: $DIR/slurmctld.log $DIR/slurmd.log"
  exit 1
}

stop() {
  for d in slurmd slurmctld; do
    if alive "$DIR/$d.pid"; then
      pid=$(cat "$DIR/$d.pid")
      $SUDO kill "$pid"
      for _ in $(seq 100); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
      kill -0 "$pid" 2>/dev/null && $SUDO kill -9 "$pid"
    fi
  done
  if [ -f "$DIR/munged.ours" ]; then
    pid=$(cat /run/munge/munged.pid 2>/dev/null || true)
    [ -n "$pid" ] && $SUDO kill "$pid" 2>/dev/null || true
    rm -f "$DIR/munged.ours"
  fi
  say "stopped"
}

status() {
  export SLURM_CONF=$CONF
  alive "$DIR/slurmctld.pid" && alive "$DIR/slurmd.pid" || { say "not running"; exit 1; }
  sinfo
  echo "export SLURM_CONF=$CONF"
}

case "${1:-}" in
  start) start ;;
  stop) stop ;;
  status) status ;;
  *) echo "usage: $0 start|stop|status" >&2; exit 2 ;;
esac
