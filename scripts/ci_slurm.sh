#!/usr/bin/env bash
# A real single-node Slurm cluster for the test suite (src/cli/slurm_test.sh), started without systemd:
# installs slurm-wlm + munge from Debian when missing, writes a one-node slurm.conf for this host, creates a
# munge key when there is none, starts munged, slurmctld and slurmd, and waits until the node is idle.
# Idempotent (a cluster that already answers costs one `sinfo`), and it never fails the caller: when Slurm
# cannot be installed or started it prints one line and exits 0, and the Slurm test skips.
# usage: scripts/ci_slurm.sh
set -u

CONF=/etc/slurm/slurm.conf
MARK="# Written by synthdrive scripts/ci_slurm.sh"
NODE=$(hostname -s 2>/dev/null || hostname)

skip() {
  echo "ci_slurm: no Slurm cluster ($*); the Slurm test will skip"
  exit 0
}

node_ready() {
  local state
  state=$(timeout 10 sinfo -h -N -n "$NODE" -o '%T' 2>/dev/null | head -n 1)
  case "$state" in idle | mixed | allocated | completing) return 0 ;; *) return 1 ;; esac
}

# A daemon is running when its pid file names a live process (not a zombie; /proc works for any user).
running() { [ -s "$1" ] && grep -qs '^State:[[:space:]]*[^Z[:space:]]' "/proc/$(cat "$1")/status"; }
ours() { [ -e "$CONF" ] && head -n 1 "$CONF" | grep -qF "$MARK"; }

# slurmctld keeps calling a node idle for SlurmdTimeout after its slurmd died: with our own configuration the
# local daemons must be running too.
if command -v sinfo >/dev/null 2>&1 && node_ready &&
  { ! ours || { running /run/slurmctld.pid && running /run/slurmd.pid; }; }; then
  echo "ci_slurm: node $NODE already up"
  exit 0
fi

if [ "$(id -u)" -ne 0 ]; then
  SUDO=sudo
  command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null || skip "not root and no passwordless sudo"
else
  SUDO=
fi

if ! command -v sbatch >/dev/null 2>&1 || [ ! -x /usr/sbin/slurmctld ] || [ ! -x /usr/sbin/slurmd ] || [ ! -x /usr/sbin/munged ]; then
  { $SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y slurm-wlm munge >/tmp/ci_slurm_apt.log 2>&1 ||
    { $SUDO apt-get update >>/tmp/ci_slurm_apt.log 2>&1 &&
      $SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y slurm-wlm munge >>/tmp/ci_slurm_apt.log 2>&1; }; } ||
    skip "apt-get install slurm-wlm munge failed, see /tmp/ci_slurm_apt.log"
fi

# Only ever (re)write a slurm.conf this script wrote: a site's own configuration is left alone.
if [ -e "$CONF" ] && ! ours; then
  skip "$CONF exists and was not written by this script"
fi
CPUS=$(nproc)
MEM_MB=$(awk '/^MemTotal:/ {print int($2 / 1024 * 0.9)}' /proc/meminfo)
TMP_CONF=$(mktemp)
cat >"$TMP_CONF" <<EOF
$MARK: one node, no cgroups, no accounting database.
ClusterName=synthdrive-ci
SlurmctldHost=$NODE(127.0.0.1)
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
MpiDefault=none
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
SchedulerType=sched/backfill
ReturnToService=2
# Finished jobs stay visible to squeue for an hour: without accounting that is what \`slurm status\` reads.
MinJobAge=3600
StateSaveLocation=/var/spool/slurmctld
SlurmdSpoolDir=/var/spool/slurmd
SlurmctldPidFile=/run/slurmctld.pid
SlurmdPidFile=/run/slurmd.pid
SlurmctldLogFile=/var/log/slurm/slurmctld.log
SlurmdLogFile=/var/log/slurm/slurmd.log
NodeName=$NODE NodeAddr=127.0.0.1 CPUs=$CPUS RealMemory=$MEM_MB State=UNKNOWN
PartitionName=debug Nodes=$NODE Default=YES MaxTime=INFINITE State=UP
EOF
if ! cmp -s "$TMP_CONF" "$CONF"; then
  $SUDO mkdir -p /etc/slurm && $SUDO install -m 0644 "$TMP_CONF" "$CONF" || { rm -f "$TMP_CONF"; skip "cannot write $CONF"; }
  CHANGED=1
else
  CHANGED=0
fi
rm -f "$TMP_CONF"
$SUDO mkdir -p /var/spool/slurmctld /var/spool/slurmd /var/log/slurm /run/munge /var/log/munge /var/lib/munge

# munge: a key (Debian's package makes one; a bare image may not), then the daemon as the munge user.
if [ ! -s /etc/munge/munge.key ]; then
  $SUDO mkdir -p /etc/munge
  $SUDO dd if=/dev/urandom of=/etc/munge/munge.key bs=1 count=1024 status=none || skip "cannot create a munge key"
fi
$SUDO chown -R munge:munge /etc/munge /run/munge /var/log/munge /var/lib/munge 2>/dev/null
$SUDO chmod 0700 /etc/munge && $SUDO chmod 0400 /etc/munge/munge.key
if ! munge -n 2>/dev/null | unmunge >/dev/null 2>&1; then
  $SUDO runuser -u munge -- /usr/sbin/munged >/tmp/ci_slurm_munged.log 2>&1 ||
    $SUDO /usr/sbin/munged --force >>/tmp/ci_slurm_munged.log 2>&1 || skip "munged does not start, see /tmp/ci_slurm_munged.log"
  for _ in $(seq 50); do munge -n 2>/dev/null | unmunge >/dev/null 2>&1 && break; sleep 0.1; done
  munge -n 2>/dev/null | unmunge >/dev/null 2>&1 || skip "munge does not answer"
fi

# A daemon left from another configuration is restarted; a running one with this configuration is kept.
if [ "$CHANGED" = 1 ]; then
  for pid_file in /run/slurmd.pid /run/slurmctld.pid; do
    running "$pid_file" && $SUDO kill "$(cat "$pid_file")" && sleep 1
  done
fi
if ! running /run/slurmctld.pid; then
  # -c: a clean start; a CI cluster has no jobs worth keeping across configurations.
  $SUDO /usr/sbin/slurmctld -c -f "$CONF" >/tmp/ci_slurm_ctld.log 2>&1 || skip "slurmctld does not start, see /var/log/slurm/slurmctld.log"
fi
if ! running /run/slurmd.pid; then
  $SUDO /usr/sbin/slurmd -f "$CONF" >/tmp/ci_slurm_d.log 2>&1 || skip "slurmd does not start, see /var/log/slurm/slurmd.log"
fi
for _ in $(seq 60); do
  if node_ready; then
    echo "ci_slurm: node $NODE idle ($CPUS CPUs, ${MEM_MB} MB), partition debug"
    exit 0
  fi
  # A node marked down by an earlier unclean stop comes back when told to.
  $SUDO scontrol update nodename="$NODE" state=resume >/dev/null 2>&1
  sleep 0.5
done
skip "node $NODE not idle after 30 s ($(sinfo -h -N -o '%T %E' 2>&1 | head -n 1)), see /var/log/slurm/"
