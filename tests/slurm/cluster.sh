#!/usr/bin/env bash
# A single-node Slurm cluster on this machine, for the Slurm tests (engine/cli/tests/slurm.rs)
# and for trying `--submit slurm` by hand. Needs root and Debian's `slurm-wlm` and `munge`.
#
#   tests/slurm/cluster.sh start DIR   # configure and start munged, slurmctld, slurmd in DIR;
#                                      # returns once `sinfo` shows the node idle
#   tests/slurm/cluster.sh stop DIR    # stop the three daemons by their process ids
#   tests/slurm/cluster.sh env DIR     # print `export SLURM_CONF=...` for the client commands
#
# Everything (configuration, munge key and socket, state, spool, logs, pid files) lives in
# DIR; nothing is written to /etc. The client commands (sbatch, squeue, sinfo, scancel)
# find the cluster through SLURM_CONF=DIR/slurm.conf. `start` is idempotent: daemons whose
# pid file names a live process are left running. Ports: SPH_SLURM_PORT (slurmctld,
# default 16817) and the next one (slurmd).
set -euo pipefail

die() {
    echo "cluster.sh: $*" >&2
    exit 1
}

cmd=${1:-}
dir=${2:-}
[[ -n $cmd && -n $dir ]] || die "usage: cluster.sh start|stop|env DIR"
mkdir -p "$dir"
dir=$(cd "$dir" && pwd)
conf=$dir/slurm.conf

# The process whose id is in pid file $1, if it is alive.
alive() {
    local pid
    [[ -s $1 ]] || return 1
    pid=$(cat "$1")
    [[ $pid =~ ^[0-9]+$ ]] && kill -0 "$pid" 2>/dev/null
}

# Waits up to $1 seconds for command $4... to succeed, while the daemon of pid file $3
# (if given) lives; fails with the tail of log $2.
wait_for() {
    local limit=$1 log=$2 pidfile=$3
    shift 3
    local t=0
    until "$@" >/dev/null 2>&1; do
        if ((t >= limit * 10)) || { [[ -n $pidfile ]] && ((t >= 20)) && ! alive "$pidfile"; }; then
            if ((t >= limit * 10)); then
                echo "cluster.sh: gave up after ${limit} s waiting for: $*" >&2
            else
                echo "cluster.sh: the daemon of $pidfile exited while waiting for: $*" >&2
            fi
            [[ -f $log ]] && { echo "--- last lines of $log:" >&2; tail -n 20 "$log" >&2; }
            return 1
        fi
        sleep 0.1
        t=$((t + 1))
    done
}

node_idle() {
    [[ $(SLURM_CONF=$conf sinfo -h -N -o '%T' 2>/dev/null) == idle ]]
}

start() {
    for exe in munged slurmctld slurmd sinfo sbatch; do
        command -v "$exe" >/dev/null || die "$exe not found: install Debian's slurm-wlm and munge (apt-get install slurm-wlm munge)"
    done
    [[ $(id -u) == 0 ]] || die "run as root (slurmd starts jobs as their user)"
    local host port cpus
    host=$(hostname -s)
    port=${SPH_SLURM_PORT:-16817}
    cpus=$(nproc)
    mkdir -p "$dir"/{munge,state,spool,log}
    chmod 0700 "$dir/munge"
    if [[ ! -s $dir/munge/munge.key ]]; then
        head -c 1024 /dev/urandom >"$dir/munge/munge.key"
        chmod 0400 "$dir/munge/munge.key"
    fi
    cat >"$conf" <<CONF
# Written by tests/slurm/cluster.sh: a single-node cluster for tests.
ClusterName=sphtest
SlurmctldHost=$host(127.0.0.1)
SlurmUser=root
SlurmdUser=root
SlurmctldPort=$port
SlurmdPort=$((port + 1))
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$dir/munge/munge.socket
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
SchedulerType=sched/backfill
MpiDefault=none
JobRequeue=1
ReturnToService=2
KillWait=30
MinJobAge=600
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool
SlurmctldPidFile=$dir/slurmctld.pid
SlurmdPidFile=$dir/slurmd.pid
SlurmctldLogFile=$dir/log/slurmctld.log
SlurmdLogFile=$dir/log/slurmd.log
AccountingStorageType=accounting_storage/none
JobAcctGatherType=jobacct_gather/none
JobCompType=jobcomp/none
NodeName=$host NodeAddr=127.0.0.1 CPUs=$cpus State=UNKNOWN
PartitionName=test Nodes=$host Default=YES MaxTime=INFINITE State=UP
CONF
    export SLURM_CONF=$conf
    if ! alive "$dir/slurmctld.pid"; then
        for p in "$port" $((port + 1)); do
            if (exec 3<>"/dev/tcp/127.0.0.1/$p") 2>/dev/null; then
                die "port $p is in use (another Slurm?): choose free ports with SPH_SLURM_PORT=N (N and N+1)"
            fi
        done
    fi
    if ! alive "$dir/munged.pid"; then
        munged --force --key-file="$dir/munge/munge.key" --socket="$dir/munge/munge.socket" \
            --pid-file="$dir/munged.pid" --log-file="$dir/log/munged.log" \
            --seed-file="$dir/munge/munged.seed" ||
            die "munged did not start (log: $dir/log/munged.log)"
        wait_for 10 "$dir/log/munged.log" "" alive "$dir/munged.pid" ||
            die "munged did not start"
    fi
    if ! alive "$dir/slurmctld.pid"; then
        slurmctld -i || die "slurmctld did not start (log: $dir/log/slurmctld.log)"
        wait_for 30 "$dir/log/slurmctld.log" "$dir/slurmctld.pid" scontrol ping ||
            die "slurmctld does not answer"
    fi
    if ! alive "$dir/slurmd.pid"; then
        slurmd || die "slurmd did not start (log: $dir/log/slurmd.log)"
    fi
    wait_for 60 "$dir/log/slurmd.log" "$dir/slurmd.pid" node_idle ||
        die "the node $host did not become idle: $(sinfo -h -N -o '%T %E' 2>&1)"
    echo "cluster.sh: Slurm is up in $dir (node $host idle, $cpus CPUs); export SLURM_CONF=$conf"
}

# Stops a daemon by the id in its pid file: SIGTERM, then SIGKILL after 15 s.
stop_one() {
    local name=$1 file=$dir/$1.pid pid t=0
    alive "$file" || { rm -f "$file"; return 0; }
    pid=$(cat "$file")
    kill -TERM "$pid" 2>/dev/null || true
    while kill -0 "$pid" 2>/dev/null; do
        if ((t >= 150)); then
            echo "cluster.sh: $name ($pid) ignored SIGTERM for 15 s: SIGKILL" >&2
            kill -KILL "$pid" 2>/dev/null || true
            break
        fi
        sleep 0.1
        t=$((t + 1))
    done
    rm -f "$file"
}

case $cmd in
start) start ;;
stop)
    # Jobs still running end with the cluster (bounded: 15 s).
    if alive "$dir/slurmctld.pid"; then
        SLURM_CONF=$conf scancel --full --user="$(id -un)" 2>/dev/null || true
        for _ in $(seq 150); do
            [[ -z $(SLURM_CONF=$conf squeue -h -t R,CG 2>/dev/null) ]] && break
            sleep 0.1
        done
    fi
    stop_one slurmd
    stop_one slurmctld
    stop_one munged
    echo "cluster.sh: stopped the daemons of $dir"
    ;;
env) echo "export SLURM_CONF=$conf" ;;
*) die "unknown command $cmd: use start, stop or env" ;;
esac
