#!/usr/bin/env bash
# bench_batch: synthesis as a batch — frames per minute with 1 worker and with 2 workers (two `--shard` processes
# of one thread each, then `--merge`), on the 5 KITTI frames of ../shared/data (or the repo's 3 without it).
# The Slurm path's overhead per task is measured by src/cli/slurm_test.sh's cluster (docs/scale.md); this script
# measures the work itself. Median of --repeat runs (default 3). Usage: bench/bench_batch.sh [build dir] [repeat]
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/.." && pwd)
BIN=${1:-$ROOT/build/bin}/synthdrive
REPEAT=${2:-3}
LOG=$ROOT/../shared/data/driving/kitti-object-openpcdet
[ -d "$LOG" ] || LOG=$ROOT/data/driving/kitti-object
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
"$BIN" -q asset import --mesh "$ROOT/data/assets/metadrive_traffic_cone/scene.gltf" --up +y --height 0.7 \
  --category traffic_cone --out "$T/cone"
"$BIN" -q asset import --mesh "$ROOT/data/assets/metadrive_road_barrier/scene.gltf" --up +y --front +z --scale 1 \
  --category barrier --out "$T/barrier"
cat > "$T/scenario.json" <<'J'
{"seed": 5, "objects": [
  {"category": "traffic_cone", "count": 3, "distance_m": [6, 20], "lateral_m": [-4, 4], "yaw": "random"},
  {"category": "barrier", "count": 1, "distance_m": [8, 25], "lateral_m": [-5, 5], "yaw": "aligned"}]}
J
FRAMES=$(ls "$LOG"/training/image_2 2>/dev/null | wc -l)
ARGS=(--log "$LOG" --asset "$T/cone" --asset "$T/barrier" --scenario "$T/scenario.json")
median() { sort -n | awk '{a[NR]=$1} END {print (NR % 2) ? a[(NR + 1) / 2] : (a[NR / 2] + a[NR / 2 + 1]) / 2}'; }
one=() two=()
for r in $(seq "$REPEAT"); do
  rm -rf "$T"/out1* "$T"/out2*
  s=$(date +%s.%N)
  "$BIN" -q --threads 2 synth "${ARGS[@]}" --out "$T/out1"
  one+=("$(awk -v a="$(date +%s.%N)" -v b="$s" 'BEGIN {printf "%.2f", a - b}')")
  s=$(date +%s.%N)
  "$BIN" -q --threads 1 synth "${ARGS[@]}" --out "$T/out2" --shard 0/2 &
  "$BIN" -q --threads 1 synth "${ARGS[@]}" --out "$T/out2" --shard 1/2
  wait
  "$BIN" -q synth "${ARGS[@]}" --out "$T/out2" --merge
  two+=("$(awk -v a="$(date +%s.%N)" -v b="$s" 'BEGIN {printf "%.2f", a - b}')")
  diff -r "$T/out1" "$T/out2" >/dev/null || { echo "bench_batch: 2-worker result differs from 1 worker" >&2; exit 1; }
done
m1=$(printf '%s\n' "${one[@]}" | median)
m2=$(printf '%s\n' "${two[@]}" | median)
printf 'log %s: %d frames, 4 objects each\n' "$LOG" "$FRAMES"
printf '1 worker  (--threads 2):              %6.1f s  %6.1f frames/min  runs: %s\n' "$m1" "$(awk -v f="$FRAMES" -v t="$m1" 'BEGIN {print 60 * f / t}')" "${one[*]}"
printf '2 workers (2 shards x --threads 1 + merge): %6.1f s  %6.1f frames/min  runs: %s\n' "$m2" "$(awk -v f="$FRAMES" -v t="$m2" 'BEGIN {print 60 * f / t}')" "${two[*]}"
