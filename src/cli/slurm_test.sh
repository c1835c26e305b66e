#!/usr/bin/env bash
# `synthdrive slurm submit|status` on a real Slurm cluster (scripts/ci_slurm.sh starts a one-node one): a
# 4-shard `mine index` and a 4-shard `synth` + `--merge` run as job arrays must give exactly what one local
# process gives; resubmitting the job script must change nothing; a failing task must show as FAILED with a
# non-zero `slurm status`. Skips (exit 77) when there is no Slurm client or no idle node.
# usage: slurm_test.sh <synthdrive binary> <repo data dir>
set -u
BIN=$(realpath "$1")
DATA=$(realpath "$2")
SKIP=77

if ! command -v sbatch >/dev/null 2>&1 || ! command -v sinfo >/dev/null 2>&1; then
  echo "SKIP: no Slurm client (sbatch/sinfo) on PATH; scripts/ci_slurm.sh installs and starts a one-node cluster"
  exit $SKIP
fi
if ! timeout 10 sinfo -h -o '%T' 2>/dev/null | grep -qE '^(idle|mixed|allocated|completing)'; then
  echo "SKIP: Slurm cluster not up (sinfo shows no usable node); scripts/ci_slurm.sh starts one"
  exit $SKIP
fi

# Job arrays run on the cluster's nodes: the work folder must be one they see (here: the same host).
T=$(mktemp -d "${SLURM_TEST_DIR:-/tmp}/slurm_test.XXXXXX")
trap 'rm -rf "$T"' EXIT
cd "$T" || exit 1
pass=0
fail=0
ok() { pass=$((pass + 1)); }
bad() { fail=$((fail + 1)); echo "FAIL: $*"; }

# wait_job <jobid> <seconds>: polls `slurm status` until no task is pending or running; leaves the last
# status in $T/status.<jobid> and returns its exit code (124 on timeout).
wait_job() {
  local job=$1 limit=$2 start=$SECONDS rc
  while :; do
    "$BIN" slurm status "$job" >"$T/status.$job" 2>&1
    rc=$?
    if grep -qE "^job $job: .* 0 running, 0 pending" "$T/status.$job"; then return $rc; fi
    if [ $((SECONDS - start)) -ge "$limit" ]; then
      echo "job $job still not finished after $limit s:" && cat "$T/status.$job"
      return 124
    fi
    sleep 0.5
  done
}

# check_all_completed <name> <jobid> <tasks>
check_all_completed() {
  local name=$1 job=$2 n=$3
  if ! grep -q "^job $job: $n tasks: $n completed, 0 running, 0 pending, 0 failed$" "$T/status.$job"; then
    bad "$name: not all $n tasks completed: $(cat "$T/status.$job")"
    for f in "$T"/logs/*-"$job"_*.out; do [ -e "$f" ] && { echo "--- $f"; tail -n 5 "$f"; }; done
    return 1
  fi
  [ "$(grep -c "^${job}_[0-9]* COMPLETED$" "$T/status.$job")" -eq "$n" ] || { bad "$name: per-task lines: $(cat "$T/status.$job")"; return 1; }
  ok
}

# same_index <a> <b>: the same chunk folders holding identical items, vectors, crops and masks; chunk.json
# differs only in its timings.
same_index() {
  local a=$1 b=$2
  [ -n "$(ls "$a/shards")" ] || { echo "$a: no chunks"; return 1; }
  diff <(ls "$a/shards") <(ls "$b/shards") || return 1
  diff -r -x chunk.json -x logs "$a" "$b" || return 1   # logs/: one run log per shard process
  for c in "$a"/shards/*/chunk.json; do
    diff <(grep -v '_seconds' "$c") <(grep -v '_seconds' "$b/shards/$(basename "$(dirname "$c")")/chunk.json") || return 1
  done
}

# --- mine index: 4 shards (one chunk each) as a job array against one local process.
MINE=(mine index --log "$DATA/driving/kitti-object"
  --log "$DATA/driving/nuscenes-scene0061-kf0/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json" --clip none --chunk-size 1)
"$BIN" -q "${MINE[@]}" --out "$T/local_index" || bad "local mine index"
[ "$(ls "$T/local_index/shards" | wc -l)" -ge 4 ] || bad "local index has fewer chunks than shards"

JOB=$("$BIN" -q slurm submit --shards 4 --log-dir "$T/logs" --job-name mine -- "${MINE[@]}" --out "$T/slurm_index")
if ! [[ "$JOB" =~ ^[0-9]+$ ]]; then
  bad "slurm submit printed '$JOB', not a job id"
else
  ok
  [ -f "$T/logs/mine-$JOB.sbatch" ] && grep -q '^#SBATCH --array=0-3$' "$T/logs/mine-$JOB.sbatch" && ok ||
    bad "job script $T/logs/mine-$JOB.sbatch missing or without --array=0-3"
  wait_job "$JOB" 300
  check_all_completed "mine index" "$JOB" 4
  same_index "$T/local_index" "$T/slurm_index" && ok || bad "mine index: job array index differs from the local one"

  # Resubmitting the same script (how failed tasks are rerun) finds every chunk done and changes nothing.
  cp -r "$T/slurm_index" "$T/index_before"
  JOB2=$(sbatch --parsable "$T/logs/mine-$JOB.sbatch" | cut -d';' -f1)
  wait_job "$JOB2" 300
  check_all_completed "mine index rerun" "$JOB2" 4
  # The index is untouched; only its run logs (logs/, appended per run) record the rerun, one "skipped" line
  # per chunk.
  diff -r -x logs "$T/index_before" "$T/slurm_index" >/dev/null && ok || bad "mine index rerun changed the index"
  [ "$(cat "$T"/slurm_index/logs/*.jsonl | grep -c '"status":"skipped"')" -eq "$(ls "$T/slurm_index/shards" | wc -l)" ] &&
    ok || bad "mine index rerun: the run logs do not record every chunk as skipped"
  [ "$(grep -l "0 new chunks" "$T"/logs/mine-"$JOB2"_*.out | wc -l)" -eq 4 ] && ok ||
    bad "mine index rerun: not every task skipped its chunks"
fi

# --- sbatch refusing the job: one line naming the script, exit 2, no log folder or script left behind.
"$BIN" -q slurm submit --shards 2 --partition no_such_partition --log-dir "$T/refused" -- mine index --log x \
  --out "$T/refused_index" >"$T/stdout" 2>"$T/stderr"
rc=$?
if [ $rc -eq 2 ] && [ "$(grep -c . "$T/stderr")" -eq 1 ] && grep -q "sbatch failed" "$T/stderr" && [ ! -e "$T/refused" ] &&
  [ ! -s "$T/stdout" ]; then ok; else
  bad "refused submission: exit $rc, stderr $(cat "$T/stderr"), $(ls "$T/refused" 2>&1)"
fi

# --- A failing task: FAILED per task and a non-zero `slurm status`.
JOBF=$("$BIN" -q slurm submit --shards 2 --log-dir "$T/logs" --job-name broken -- mine index --log "$T/no_such_log.json" \
  --clip none --out "$T/broken_index")
if [[ "$JOBF" =~ ^[0-9]+$ ]]; then
  wait_job "$JOBF" 120
  rc=$?
  if [ $rc -eq 1 ] && grep -q "^job $JOBF: 2 tasks: 0 completed, 0 running, 0 pending, 2 failed$" "$T/status.$JOBF" &&
    grep -q "no_such_log.json" "$T/logs/broken-${JOBF}_1.out"; then ok; else
    bad "failing job: status exit $rc, $(cat "$T/status.$JOBF")"
  fi
else
  bad "slurm submit (failing job) printed '$JOBF'"
fi

# --- synth: 4 shards as a job array, then --merge, against one local process.
"$BIN" -q asset import --mesh "$DATA/assets/metadrive_traffic_cone/scene.gltf" --up +y --height 0.7 \
  --category traffic_cone --out "$T/cone" || bad "asset import"
cat >"$T/cones.json" <<'J'
{"seed": 3, "objects": [{"category": "traffic_cone", "count": 2, "distance_m": [6, 15], "lateral_m": [-3, 3]}]}
J
if "$BIN" synth --help | grep -q -- '--merge'; then
  SYNTH=(synth --log "$DATA/driving/kitti-object" --asset "$T/cone" --scenario "$T/cones.json")
  "$BIN" -q "${SYNTH[@]}" --out "$T/local_synth" || bad "local synth"
  JOBS=$("$BIN" -q slurm submit --shards 4 --log-dir "$T/logs" --job-name synth -- "${SYNTH[@]}" --out "$T/slurm_synth")
  if [[ "$JOBS" =~ ^[0-9]+$ ]]; then
    wait_job "$JOBS" 600
    check_all_completed "synth" "$JOBS" 4
    "$BIN" -q "${SYNTH[@]}" --out "$T/slurm_synth" --merge || bad "synth --merge"
    diff -r "$T/local_synth" "$T/slurm_synth" >/dev/null && ok || bad "synth: merged job array output differs from the local one"
  else
    bad "slurm submit (synth) printed '$JOBS'"
  fi
else
  echo "NOTE: this synthdrive has no synth --shard/--merge: synth job array not checked"
fi

echo "slurm_test: $pass passed, $fail failed"
[ $fail -eq 0 ]
