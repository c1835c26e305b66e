#!/usr/bin/env bash
# Builds the libFuzzer targets (fuzz/, docs/fuzzing.md) in build-fuzz with clang, ASan and UBSan, and runs each
# for SECONDS_PER_TARGET (default 30) from a corpus seeded from data/. Prints executions and coverage per target;
# exits non-zero on any crash, sanitizer report, timeout (> 10 s on one input) or memory blow-up (> 2 GB), with
# the input saved under build-fuzz/crashes/<target>/ (keep it in fuzz/regressions/<target>/ once fixed).
# With --unit-tests it first builds the unit tests of the same modules (core, io, datasets) in that build and
# runs them under ASan + UBSan; any report fails (CI's sanitizer stage, scripts/ci_sanitizers.sh).
# FUZZ_SEED=N fixes libFuzzer's mutation seed; FUZZ_RUNS=N runs exactly N inputs per target from a corpus seeded
# afresh (build-fuzz/corpus-fixed/) instead of fuzzing for a time: the same amount of work on any machine, and
# with the seed mostly the same inputs (CI does; otherwise each run explores anew and the corpus grows).
#   scripts/fuzz.sh [--unit-tests] [SECONDS_PER_TARGET] [TARGET...]
set -euo pipefail
cd "$(dirname "$0")/.."
UNIT_TESTS=0
if [ "${1:-}" = --unit-tests ]; then
  UNIT_TESTS=1
  shift
fi
SECONDS_PER_TARGET=${1:-30}
shift || true
BUILD=build-fuzz
JOBS=${JOBS:-$(nproc)}

# clang 16 (Debian 12's newest): clang 14 cannot compile lambdas that capture structured bindings (C++20).
CLANG=clang++-16
if ! command -v "$CLANG" >/dev/null || [ ! -e "$(dirname "$(readlink -f "$(command -v "$CLANG")")")/../lib/clang/16/lib/linux/libclang_rt.fuzzer-x86_64.a" ]; then
  if [ -r /etc/debian_version ] && command -v apt-get >/dev/null; then
    echo "fuzz: installing clang-16 and libclang-rt-16-dev (Debian)"
    SUDO=""
    [ "$(id -u)" -ne 0 ] && SUDO="sudo"
    export DEBIAN_FRONTEND=noninteractive
    $SUDO apt-get update -qq && $SUDO apt-get install -y -qq --no-install-recommends clang-16 libclang-rt-16-dev \
      >/dev/null || true
  fi
  if ! command -v "$CLANG" >/dev/null; then
    echo "fuzz: skipped: clang-16 with libFuzzer (Debian packages clang-16, libclang-rt-16-dev) is not installed and could not be"
    exit 0
  fi
fi

cmake -S . -B "$BUILD" -DCMAKE_CXX_COMPILER="$CLANG" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DSYNTHDRIVE_FUZZ=ON \
  -DSYNTHDRIVE_BUILD_TESTS=$([ $UNIT_TESTS = 1 ] && echo ON || echo OFF) >/dev/null
build_targets=(fuzz_targets)
[ $UNIT_TESTS = 1 ] && build_targets=(all)
if ! cmake --build "$BUILD" --target "${build_targets[@]}" -j "$JOBS" >"$BUILD/build.log" 2>&1; then
  grep -E 'error' "$BUILD/build.log" | head -20
  echo "fuzz: build failed (see $BUILD/build.log)" >&2
  exit 1
fi

if [ $UNIT_TESTS = 1 ]; then
  # Leak checking included; a UBSan report aborts (-fno-sanitize-recover), so it fails its test.
  if ! ASAN_OPTIONS=halt_on_error=1:detect_leaks=1 UBSAN_OPTIONS=halt_on_error=1:print_stacktrace=1 \
      ctest --test-dir "$BUILD" --output-on-failure -j "$JOBS" --timeout 900 >"$BUILD/unit-tests.log" 2>&1; then
    grep -E 'tests passed|\*\*\*|Failed|ERROR: (Address|Leak|Undefined)|runtime error' "$BUILD/unit-tests.log" | head -40
    echo "fuzz: unit tests under ASan + UBSan failed (see $BUILD/unit-tests.log)" >&2
    exit 1
  fi
  grep -E 'tests passed' "$BUILD/unit-tests.log"
fi

if [ $# -gt 0 ]; then
  targets=("$@")
else
  targets=()
  for f in fuzz/*_fuzzer.cpp; do targets+=("$(basename "$f" _fuzzer.cpp)"); done
fi

export ASAN_OPTIONS=halt_on_error=1:abort_on_error=1:detect_leaks=1
export ASAN_SYMBOLIZER_PATH=${ASAN_SYMBOLIZER_PATH:-$(command -v llvm-symbolizer-16 || command -v llvm-symbolizer || true)}
export UBSAN_OPTIONS=halt_on_error=1:print_stacktrace=1
failed=()
printf '%-16s %10s %8s %8s %7s %s\n' target executions exec/s cov ft result
for t in "${targets[@]}"; do
  bin="$BUILD/fuzz/${t}_fuzzer"
  corpus="$BUILD/corpus/$t"
  budget=(-max_total_time="$SECONDS_PER_TARGET")
  if [ -n "${FUZZ_RUNS:-}" ]; then
    # A time budget makes the inputs explored depend on the machine's speed; a count does not. The time cap
    # only guards against a hang-like slowdown (each input also has -timeout).
    corpus="$BUILD/corpus-fixed/$t"
    rm -rf "$corpus"
    budget=(-runs="$FUZZ_RUNS" -max_total_time=900)
  fi
  # Address-space randomisation changes which paths some targets take (pointer-keyed order), so a fixed run
  # turns it off where the kernel lets us.
  launcher=()
  [ -n "${FUZZ_RUNS:-}" ] && setarch "$(uname -m)" -R true 2>/dev/null && launcher=(setarch "$(uname -m)" -R)
  crashes="$BUILD/crashes/$t"
  log="$BUILD/logs/$t.log"
  mkdir -p "$corpus" "$crashes" "$(dirname "$log")"
  result=ok
  # Known crashers first: a regression fails before any new fuzzing.
  regressions=(fuzz/regressions/"$t"/*)
  if [ -e "${regressions[0]}" ] && ! "$bin" "${regressions[@]}" >"$log.replay" 2>&1; then
    result="regression fails (see $log.replay)"
  elif ! SYNTHDRIVE_FUZZ_SEEDS_OUT="$corpus" "${launcher[@]}" "$bin" "$corpus" "${budget[@]}" -timeout=10 \
      ${FUZZ_SEED:+-seed="$FUZZ_SEED"} \
      -rss_limit_mb=2048 -print_final_stats=1 -artifact_prefix="$crashes/" >"$log" 2>&1; then
    result="CRASH: $(ls -t "$crashes" | head -1 | sed "s|^|$crashes/|") (see $log)"
  fi
  runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" 2>/dev/null | tail -1)
  speed=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log" 2>/dev/null | tail -1)
  final=$(grep -E '^#[0-9]+.*(DONE|pulse|NEW|REDUCE|INITED).*cov:' "$log" 2>/dev/null | tail -1 || true)
  cov=$(sed -n 's/.* cov: \([0-9]*\).*/\1/p' <<<"$final")
  ft=$(sed -n 's/.* ft: \([0-9]*\).*/\1/p' <<<"$final")
  printf '%-16s %10s %8s %8s %7s %s\n' "$t" "${runs:--}" "${speed:--}" "${cov:--}" "${ft:--}" "$result"
  [ "$result" = ok ] || failed+=("$t")
done
if [ ${#failed[@]} -gt 0 ]; then
  echo "fuzz: failed: ${failed[*]}" >&2
  exit 1
fi
