# The two set-up commands of the README:
#   make demo   installs what is missing, builds Release, runs `synthdrive demo` on data/
#   make test   the same set-up, builds and runs the test suite through CTest
.PHONY: setup build demo test bench clean

JOBS ?= $(shell nproc)
PRESET ?= release

setup:
	@scripts/setup.sh

build: setup
	cmake --preset $(PRESET) >/dev/null
	cmake --build --preset $(PRESET) -j $(JOBS)

demo: build
	build/bin/synthdrive demo --out out/demo --overwrite

test: build
	ctest --test-dir build --output-on-failure -j $(JOBS)

bench: build
	build/bin/bench_synth_keyframe --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
	bench/bench_synth_process.sh build 5

clean:
	rm -rf build build-debug build-asan build-fuzz out
