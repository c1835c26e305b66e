#!/usr/bin/env bash
# The GPU test run (docs/gpu.md), on a machine with an NVIDIA GPU, CUDA, CMake, a C++ compiler and PyTorch:
#  1. the raster tests on the GPU (SYNTHDRIVE_DEVICE=cuda: every gradient test) and the CPU/GPU agreement test;
#  2. the model runtime built here against PyTorch's CUDA LibTorch, its tests on the GPU, and bench_models;
#  3. bench_refine and bench_generate (oracle views) on the GPU and on this machine's CPUs, with the peak GPU
#     memory sampled by nvidia-smi;
#  4. CLIP ViT-B/32 on its real architecture (random weights) through the runtime and tokenizer against the
#     Python model, and its throughput (tools/gpu/clip_check.py; needs the vocabulary pack.sh copies).
# Usage: tools/gpu/run_gpu.sh <packed-dir from pack.sh> <results-dir> [objects]
# PHASES (default "tests refine generate clip") picks the parts, so a run can be split to fit a time limit;
# REPEATS (default 3) is bench_refine's repeats per object.
set -uo pipefail
phases=" ${PHASES:-tests refine generate clip} "
repeats=${REPEATS:-3}
pack=$(realpath "${1:?usage: run_gpu.sh <packed-dir> <results-dir> [objects]}")
results=${2:?usage: run_gpu.sh <packed-dir> <results-dir> [objects]}
objects=${3:-}
repo=$(cd "$(dirname "$0")/../.." && pwd)
mkdir -p "$results"
export LD_LIBRARY_PATH="$pack/lib:$pack/deps/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
export SYNTHDRIVE_SOURCE_DIR="$repo" PYTHONUNBUFFERED=1
status=0
step() { echo "== $*" | tee -a "$results/summary.txt"; }

nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader | tee "$results/gpu.txt"
# GPU memory in use, every 100 ms, for the peak of each benchmark.
# Appending (>>), so the MARK lines written beside it are not overwritten.
nvidia-smi --query-gpu=timestamp,memory.used --format=csv,noheader,nounits -lms 100 >> "$results/gpu_memory.csv" &
sampler=$!
mark() { echo "$(date '+%Y/%m/%d %H:%M:%S.%3N'), MARK $*" >> "$results/gpu_memory.csv"; }

# The model runtime, its tests and benchmarks, built against the machine's CUDA LibTorch (once per run).
build_models() {
  [[ -x /tmp/build-gpu/bin/bench_clip ]] && return 0
  step "model runtime against CUDA LibTorch"
  local prefix
  prefix=$(python3 -c 'import torch; print(torch.utils.cmake_prefix_path)')
  (cmake -S "$repo/tools/gpu" -B /tmp/build-gpu -DSYNTHDRIVE_GPU_DEPS="$pack/deps" -DCMAKE_PREFIX_PATH="$prefix" \
     -DCMAKE_BUILD_TYPE=Release > "$results/models_build.txt" 2>&1 &&
   cmake --build /tmp/build-gpu -j "$(nproc)" >> "$results/models_build.txt" 2>&1) || { status=1; tail -n 30 "$results/models_build.txt"; }
}

if [[ $phases == *" tests "* ]]; then
step "raster tests on cuda"
# Runs a test binary with its own log; on failure the end of the log goes to the summary.
run_test() {  # log name, command...
  local log="$results/$1.log"; shift
  "$@" > "$log" 2>&1
  local rc=$?
  if [[ $rc -eq 0 ]]; then
    echo "passed: $(basename "$log" .log) ($(grep -c '^\[       OK \]' "$log") ok, $(grep -c '^\[  SKIPPED \]' "$log") skipped)" | tee -a "$results/summary.txt"
  else
    status=1
    { echo "FAILED: $(basename "$log" .log) (exit $rc)"; grep -E '^\[ RUN|FAILED|Failure|error' "$log" | tail -n 12; tail -n 15 "$log"; } | tee -a "$results/summary.txt"
    if [[ $rc -ge 128 ]] && command -v cuda-gdb > /dev/null; then  # a crash: where
      cuda-gdb -q -batch -ex run -ex bt -ex 'x/8a $sp' --args "$@" 2>&1 | grep -E '^#|signal|SIG|^0x' | head -n 30 | tee -a "$results/summary.txt"
    fi
  fi
}
for t in "$pack"/bin/raster_*; do
  SYNTHDRIVE_DEVICE=cuda run_test "$(basename "$t")_cuda" "$t"
done

if [[ -x "$(command -v python3)" ]] && python3 -c 'import torch' 2>/dev/null; then
  build_models
  models=/tmp/test_models
  for g in make_test_models make_stage_test_models make_diffusion_test_models make_segmentation_test_models; do
    python3 "$repo/tools/testing/$g.py" "$models/$g" >> "$results/models_fixtures.txt" 2>&1 || echo "fixture $g failed" | tee -a "$results/summary.txt"
  done
  run_model_test() {  # test, fixture dir
    SYNTHDRIVE_DEVICE=cuda SYNTHDRIVE_TEST_MODELS="$models/$2" run_test "models_$1_cuda" /tmp/build-gpu/bin/models_$1
  }
  run_model_test runtime_test make_test_models
  run_model_test super_resolution_test make_test_models
  run_model_test multiview_diffusion_test make_diffusion_test_models
  run_model_test segmentation_test make_segmentation_test_models
  for t in clip_test normal_estimation_test lrm_test harmonization_test; do run_model_test $t make_stage_test_models; done
  if [[ -f "$pack/models/esrgan-slim-x2.pt" ]]; then
    step "bench_models"
    mark bench_models
    /tmp/build-gpu/bin/bench_models --model "$pack/models/esrgan-slim-x2.pt" --repeats 5 | tee "$results/bench_models.txt"
    /tmp/build-gpu/bin/bench_models --model "$pack/models/esrgan-slim-x2.pt" --repeats 5 --tile 320 | tee -a "$results/bench_models.txt"
  fi
fi
fi

only=()
[[ -n $objects ]] && only=(--objects "$objects")
[[ $phases == *" refine "* ]] && for device in cuda cpu; do
  step "bench_refine on $device"
  mark "bench_refine $device"
  "$pack/bin/bench_refine" --device $device --conditions clean --repeats "$repeats" "${only[@]}" \
    --json "$results/refine_$device.json" --html "$results/refine_$device.html" > "$results/bench_refine_$device.txt" 2>&1 || status=1
  grep -E "device|MEAN" "$results/bench_refine_$device.txt"
done
[[ $phases == *" generate "* ]] && for device in cuda cpu; do
  step "bench_generate on $device"
  mark "bench_generate $device"
  SYNTHDRIVE_MODELS="$pack/models" "$pack/bin/bench_generate" --device $device "${only[@]}" \
    > "$results/bench_generate_$device.txt" 2>&1 || status=1
  tail -n 12 "$results/bench_generate_$device.txt"
done
if [[ $phases == *" clip "* ]]; then
  if [[ -f $pack/clip/bpe_simple_vocab_16e6.txt.gz ]]; then
    build_models
    step "CLIP ViT-B/32 through the runtime against the Python model"
    mark clip
    photos=("$repo"/data/images/roadanomaly-cones/frames/*.jpg "$repo"/data/driving/nuscenes-scene0061-kf0/samples/CAM_*/*.jpg
            "$repo"/data/driving/kitti-object/training/image_2/*.png)
    python3 "$repo/tools/gpu/clip_check.py" --bench /tmp/build-gpu/bin/bench_clip \
      --vocab "$pack/clip/bpe_simple_vocab_16e6.txt.gz" --reference "$pack/clip/reference_tokens.json" \
      --out "$results/clip" "${photos[@]}" > "$results/clip_check.txt" 2>&1 || { status=1; tail -n 30 "$results/clip_check.txt"; }
    tail -n 80 "$results/clip_check.txt"
  else
    step "clip: skipped, the pack has no CLIP vocabulary (pack.sh copies it from ../shared/data/models/clip)"
  fi
fi
mark end
kill $sampler 2>/dev/null
exit $status
