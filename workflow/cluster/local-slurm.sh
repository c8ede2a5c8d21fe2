#!/usr/bin/env bash
# A one-node SLURM cluster on this machine, on localhost only, for testing the workflow's
# SLURM profile with the real executor. Run as root:
#   workflow/cluster/local-slurm.sh up       start it (writes the configs on first use)
#   workflow/cluster/local-slurm.sh down     stop every daemon it started
#   workflow/cluster/local-slurm.sh status   say what runs; exit 0 when the cluster takes jobs
# `up` and `down` are idempotent: a daemon that already runs is left alone, one that is not
# running is not stopped twice. The Debian packages come from `make slurm-up` (see Makefile).
#
# What runs, and why:
#   munged       credentials for every SLURM message (Unix socket only, no network)
#   mariadbd     the accounting database, --skip-networking: reachable only by its Unix socket
#   slurmdbd     accounting: the snakemake slurm executor (1.9.2) asks `sacct` for job states,
#                and sacct needs slurmdbd; it listens on 127.0.0.1:6819 (DbdAddr=localhost)
#   slurmctld    the controller, 127.0.0.1:6817
#   slurmd       the one compute node "localhost", 127.0.0.1:6818, with this host's cores and
#                memory (from `slurmd -C`)
# CommunicationParameters=NoInAddrAny,NoCtldInAddrAny make the SLURM daemons bind to the address
# their name resolves to (localhost: 127.0.0.1) instead of every interface; srun's own ports are
# bound the same way. No cgroups (proctrack/linuxproc, task/none): the cluster does not depend on
# how a container exposes them.
#
# Files: /etc/slurm/{slurm,slurmdbd}.conf (only if absent or written by this script
# before: a site's own slurm.conf is never overwritten), state in /var/lib/slurm/local,
# logs in /var/log/slurm/local, the database in /var/lib/slurm/local/mysql.
set -euo pipefail

MARK="# written by workflow/cluster/local-slurm.sh"
ETC=/etc/slurm
STATE=/var/lib/slurm/local
LOGS=/var/log/slurm/local
RUN=/run/slurm-local
DB_DIR=$STATE/mysql
DB_RUN=$RUN/mysql
DB_SOCKET=$DB_RUN/mysqld.sock
CLUSTER=local
PARTITION=local

die() { echo "local-slurm: $*" >&2; exit 1; }
say() { echo "local-slurm: $*"; }

need_root() { [ "$(id -u)" = 0 ] || die "run as root (it starts system daemons)"; }

need_packages() {
    local missing=()
    for binary in munged slurmctld slurmd slurmdbd sbatch sacct mariadbd mariadb-install-db; do
        command -v "$binary" >/dev/null 2>&1 || [ -x "/usr/sbin/$binary" ] || missing+=("$binary")
    done
    [ ${#missing[@]} = 0 ] || die "missing ${missing[*]}: install the Debian packages with \`make slurm-up\`"
}

# running PIDFILE: true when the process of a pid file is alive (a zombie is not: where PID 1
# does not reap, a stopped daemon stays one)
running() {
    [ -s "$1" ] || return 1
    local state
    state=$(ps -o stat= -p "$(cat "$1")" 2>/dev/null) || return 1
    [ -n "$state" ] && [ "${state#Z}" = "$state" ]
}

wait_for() {  # wait_for SECONDS DESCRIPTION COMMAND...
    local seconds=$1 what=$2; shift 2
    for _ in $(seq 1 $((seconds * 4))); do
        "$@" >/dev/null 2>&1 && return 0
        sleep 0.25
    done
    die "$what did not come up within ${seconds}s (logs: $LOGS)"
}

ours() { [ ! -e "$1" ] || grep -qF "$MARK" "$1"; }

write_configs() {
    for file in slurm.conf slurmdbd.conf; do
        ours "$ETC/$file" || die "$ETC/$file exists and was not written by this script; not touching it"
    done
    mkdir -p "$ETC" "$STATE/ctld" "$STATE/d" "$LOGS" "$RUN"
    chown slurm:slurm "$STATE/ctld" "$LOGS"
    # the node as slurmd itself measures it: CPUs, sockets/cores/threads, RealMemory (MB)
    local node
    node=$(slurmd -C | head -1 | sed -e 's/^NodeName=[^ ]*//' -e 's/ *UpTime=.*//')
    [ -n "$node" ] || die "slurmd -C did not describe this host"
    cat >"$ETC/slurm.conf.new" <<EOF
$MARK
# A one-node cluster on localhost for testing; see the script for what each daemon does.
ClusterName=$CLUSTER
SlurmctldHost=localhost(127.0.0.1)
CommunicationParameters=NoInAddrAny,NoCtldInAddrAny
SlurmUser=slurm
AuthType=auth/munge
CredType=cred/munge
StateSaveLocation=$STATE/ctld
SlurmdSpoolDir=$STATE/d
SlurmctldPidFile=$RUN/slurmctld.pid
SlurmdPidFile=$RUN/slurmd.pid
SlurmctldLogFile=$LOGS/slurmctld.log
SlurmdLogFile=$LOGS/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
# srun hands its tasks a PMIx server: Open MPI (Debian's has no PMI-1/2) needs it even for a
# serial mpi4py process that srun starts, as the executor starts every non-MPI job
MpiDefault=pmix
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
ReturnToService=2
AccountingStorageType=accounting_storage/slurmdbd
AccountingStorageHost=localhost
JobAcctGatherType=jobacct_gather/none
JobCompType=jobcomp/none
# keep finished jobs visible to the controller for 10 minutes (scontrol show job)
MinJobAge=600
NodeName=localhost NodeAddr=127.0.0.1 NodeHostname=localhost $node State=UNKNOWN
PartitionName=$PARTITION Nodes=localhost Default=YES MaxTime=INFINITE State=UP
EOF
    if cmp -s "$ETC/slurm.conf.new" "$ETC/slurm.conf"; then
        rm "$ETC/slurm.conf.new"
    else
        mv "$ETC/slurm.conf.new" "$ETC/slurm.conf"
        CONFIG_CHANGED=1
    fi
    # StorageHost=localhost: the MariaDB client library then takes the Unix socket (StoragePort
    # is unused); the database user is authenticated by that socket's peer uid (unix_socket).
    umask 077
    cat >"$ETC/slurmdbd.conf" <<EOF
$MARK
AuthType=auth/munge
DbdAddr=localhost
CommunicationParameters=NoInAddrAny
DbdHost=localhost
SlurmUser=slurm
PidFile=$RUN/slurmdbd.pid
LogFile=$LOGS/slurmdbd.log
StorageType=accounting_storage/mysql
StorageHost=localhost
StorageLoc=slurm_acct_db_local
StorageUser=slurm
EOF
    umask 022
    # slurmdbd accepts only a config that its user alone can read
    chown slurm:slurm "$ETC/slurmdbd.conf"
    chmod 600 "$ETC/slurmdbd.conf"
}

start_munge() {
    if running /run/munge/munged.pid; then return; fi
    if [ ! -s /etc/munge/munge.key ]; then
        mkdir -p /etc/munge
        dd if=/dev/urandom of=/etc/munge/munge.key bs=1024 count=1 status=none
    fi
    chown -R munge:munge /etc/munge
    chmod 700 /etc/munge
    chmod 400 /etc/munge/munge.key
    mkdir -p /run/munge /var/log/munge /var/lib/munge
    chown munge:munge /run/munge /var/log/munge /var/lib/munge
    runuser -u munge -- /usr/sbin/munged
    touch "$RUN/munged.ours"
    wait_for 10 munged munge -n
}

start_database() {
    if running "$DB_RUN/mysqld.pid"; then return; fi
    mkdir -p "$DB_DIR" "$DB_RUN" "$LOGS/mariadb"
    chown mysql:mysql "$DB_DIR" "$DB_RUN" "$LOGS/mariadb"
    if [ ! -d "$DB_DIR/mysql" ]; then
        mariadb-install-db --user=mysql --datadir="$DB_DIR" --skip-test-db >"$LOGS/mariadb-install.log" 2>&1 \
            || die "mariadb-install-db failed (see $LOGS/mariadb-install.log)"
    fi
    # --no-defaults: nothing from /etc/mysql (no TCP port, no other data directory)
    setsid /usr/sbin/mariadbd --no-defaults --user=mysql --datadir="$DB_DIR" --skip-networking \
        --socket="$DB_SOCKET" --pid-file="$DB_RUN/mysqld.pid" --log-error="$LOGS/mariadb/mariadb.log" \
        --innodb-buffer-pool-size=64M --innodb-lock-wait-timeout=900 </dev/null >/dev/null 2>&1 &
    wait_for 60 mariadbd mariadb --no-defaults --socket="$DB_SOCKET" -e "select 1"
    mariadb --no-defaults --socket="$DB_SOCKET" <<EOF
CREATE DATABASE IF NOT EXISTS slurm_acct_db_local;
CREATE USER IF NOT EXISTS 'slurm'@'localhost' IDENTIFIED VIA unix_socket;
GRANT ALL ON slurm_acct_db_local.* TO 'slurm'@'localhost';
EOF
}

start_slurmdbd() {
    if running "$RUN/slurmdbd.pid"; then return; fi
    # the client library finds the socket through MYSQL_UNIX_PORT
    MYSQL_UNIX_PORT=$DB_SOCKET /usr/sbin/slurmdbd
    wait_for 60 slurmdbd sacctmgr -i -n list cluster
}

register_cluster() {
    # slurmctld registers with slurmdbd only as a cluster the database knows
    sacctmgr -i -n list cluster format=cluster | grep -qw "$CLUSTER" || sacctmgr -i add cluster "$CLUSTER" >/dev/null
}

start_slurmctld() {
    if running "$RUN/slurmctld.pid"; then
        if [ "${CONFIG_CHANGED:-0}" = 1 ]; then scontrol reconfigure && say "slurm.conf changed: reconfigured"; fi
        return
    fi
    /usr/sbin/slurmctld
    wait_for 60 slurmctld scontrol ping
}

start_slurmd() {
    if running "$RUN/slurmd.pid"; then return; fi
    /usr/sbin/slurmd -N localhost
    wait_for 60 "the node" sh -c "sinfo -h -N -o %T | grep -Eq '^(idle|mixed|allocated)'"
}

up() {
    need_root
    need_packages
    write_configs
    start_munge
    start_database
    start_slurmdbd
    register_cluster
    start_slurmctld
    start_slurmd
    say "up: partition '$PARTITION' on node localhost ($(sinfo -h -N -o '%c CPUs, %m MB'))"
}

stop_pidfile() {  # stop_pidfile NAME PIDFILE
    if running "$2"; then
        kill "$(cat "$2")"
        for _ in $(seq 1 120); do running "$2" || break; sleep 0.25; done
        running "$2" && die "$1 did not stop"
        say "stopped $1"
    fi
    rm -f "$2"
}

down() {
    need_root
    stop_pidfile slurmd "$RUN/slurmd.pid"
    stop_pidfile slurmctld "$RUN/slurmctld.pid"
    stop_pidfile slurmdbd "$RUN/slurmdbd.pid"
    stop_pidfile mariadbd "$DB_RUN/mysqld.pid"
    # munged only if this script started it (a system munged may serve other things)
    if [ -e "$RUN/munged.ours" ]; then
        stop_pidfile munged /run/munge/munged.pid
        rm -f "$RUN/munged.ours"
    fi
    say "down"
}

status() {
    local ok=0
    for pidfile in "$RUN/slurmd.pid" "$RUN/slurmctld.pid" "$RUN/slurmdbd.pid" "$DB_RUN/mysqld.pid"; do
        daemon=$(basename "$pidfile" .pid)
        if running "$pidfile"; then echo "$daemon: running (pid $(cat "$pidfile"))"
        else echo "$daemon: stopped"; ok=1; fi
    done
    if running /run/munge/munged.pid; then echo "munged: running"; else echo "munged: stopped"; ok=1; fi
    [ $ok = 0 ] && sinfo
    return $ok
}

case "${1:-}" in
    up) up ;;
    down) down ;;
    status) status ;;
    *) echo "usage: $0 up|down|status" >&2; exit 2 ;;
esac
