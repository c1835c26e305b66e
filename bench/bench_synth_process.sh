#!/usr/bin/env bash
# One frame as a new user makes it: the whole `synthdrive synth` process (start-up, reading the log, placing,
# rendering, writing the derivative dataset) on the repo's nuScenes keyframe with 5 cones, against the floor of
# one thread decoding and re-encoding that frame's six camera JPEGs (BM_JpegRoundTripFloor of
# bench_synth_keyframe). Also the start-up alone (`synthdrive categories`).
# Usage: bench/bench_synth_process.sh [build dir (default build)] [runs (default 5)]
# Prints each run and the medians; the asset import is set-up and not timed.
set -euo pipefail
repo=$(cd "$(dirname "$0")/.." && pwd)
build=${1:-$repo/build}
runs=${2:-5}
bin=$build/bin/synthdrive
[[ -x $bin ]] || { echo "bench_synth_process: no $bin (build first)" >&2; exit 1; }
t=$(mktemp -d)
trap 'rm -rf "$t"' EXIT
info=$repo/data/driving/nuscenes-scene0061-kf0/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json
"$bin" -q asset import --mesh "$repo/data/assets/metadrive_traffic_cone/scene.gltf" --up +y --height 0.7 \
  --category traffic_cone --out "$t/cone"
cat > "$t/five_cones.json" <<'J'
{"seed": 7, "location": {"latitude_deg": 1.2966, "longitude_deg": 103.7871, "name": "singapore-onenorth"},
 "objects": [{"category": "traffic_cone", "count": 5, "distance_m": [7, 20], "lateral_m": [-4, 4], "yaw": "random"}]}
J
median() { sort -g | awk '{v[NR] = $1} END {print v[int((NR + 1) / 2)]}'; }
seconds() { local s e; s=$(date +%s.%N); "$@" > /dev/null; e=$(date +%s.%N); awk -v s="$s" -v e="$e" 'BEGIN {printf "%.3f\n", e - s}'; }

echo "start-up (synthdrive categories):"
for i in $(seq "$runs"); do seconds "$bin" categories; done | tee "$t/startup" | sed 's/^/  /'
echo "synth, one keyframe, 5 cones:"
for i in $(seq "$runs"); do seconds "$bin" -q synth --log "$info" --asset "$t/cone" --scenario "$t/five_cones.json" --out "$t/out$i"; done |
  tee "$t/synth" | sed 's/^/  /'
floor_ms=$("$build/bin/bench_synth_keyframe" --benchmark_filter=BM_JpegRoundTripFloor --benchmark_repetitions="$runs" \
  --benchmark_report_aggregates_only=true 2>/dev/null | awk '/_median/ {print $2}')
startup=$(median < "$t/startup")
synth=$(median < "$t/synth")
awk -v a="$startup" -v s="$synth" -v f="$floor_ms" 'BEGIN {
  printf "median start-up %.3f s; median synth process %.3f s; JPEG floor (6 decodes + encodes, 1 thread) %.0f ms; ratio %.1f\n", a, s, f, s * 1000 / f }'
