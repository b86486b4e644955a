# phos: the two set-up commands of the README, and a few more.
#   make demo   install what the build needs (apt), build phos in Release (the
#               target phos_demo: not the tests or benchmarks), run the main job
#   make test   install what is missing, build under ASan+UBSan, run every test (ctest),
#               then every fuzz harness for FUZZ_CI_SECONDS (4 s) each
#   make install PREFIX=DIR   phos and its data into DIR/bin and DIR/share/phos (default /usr/local)
# Other targets: phos (what demo and install build), build (Release: everything), bench (benchmarks, Release), study
# (regenerate the integrator error, Glassner, nc, dss, appearance and path
# tracer convergence studies in docs/),
# fuzz (the libFuzzer harnesses for FUZZ_SECONDS each, docs/fuzzing.md), format
# (clang-format, .clang-format, on every tracked C++ file), clean.

JOBS ?= $(shell nproc)
PREFIX ?= /usr/local
FUZZ_SECONDS ?= 60
FUZZ_CI_SECONDS ?= 4
FUZZ_JOBS ?= 1

.PHONY: all bootstrap bootstrap-demo phos build demo install test bench study fuzz fuzz-build format clean

all: build

bootstrap:
	@bash scripts/bootstrap.sh

build: bootstrap
	@cmake --preset release >/dev/null
	@cmake --build --preset release -j $(JOBS)

# The packages the Release build needs, not the test suite's browser, Slurm
# and clang (scripts/bootstrap.sh demo); then only what demo.sh runs.
bootstrap-demo:
	@bash scripts/bootstrap.sh demo

phos: bootstrap-demo
	@cmake --preset release >/dev/null
	@cmake --build --preset release -j $(JOBS) --target phos_demo

demo: phos
	@bash scripts/demo.sh

# phos, its commands and the data they read (presets, example scenes) into
# PREFIX/bin and PREFIX/share/phos (cmake --install; docs/install.md).
install: phos
	@cmake --install build --prefix $(PREFIX)

test: bootstrap
	@cmake --preset asan >/dev/null
	@cmake --build --preset asan -j $(JOBS)
	@ctest --preset asan -j $(JOBS)
	@$(MAKE) --no-print-directory fuzz FUZZ_SECONDS=$(FUZZ_CI_SECONDS) FUZZ_JOBS=$(JOBS)

bench: build
	@bash scripts/bench.sh

study: build
	@build/bin/phos-integrator-study --out docs
	@build/bin/phos-glassner-study --out docs
	@build/bin/phos-nc-study --out docs
	@build/bin/phos-dss-study --out docs --quality-table render/data/transport-quality.json
	@build/bin/phos-appearance-study --out docs
	@build/bin/phos-path-study --out docs
	@build/bin/phos-two-state-map-study --out docs
	@build/bin/phos-state-trade-study --out docs

# The harnesses (fuzz/, its own CMake project: clang, libFuzzer, ASan + UBSan,
# only the loaders' sources), each run for FUZZ_SECONDS, FUZZ_JOBS at a time (1; make test: all cores).
fuzz-build: bootstrap
	@cd fuzz && cmake --preset fuzz >/dev/null
	@cmake --build build-fuzz -j $(JOBS)

fuzz: fuzz-build
	@FUZZ_SECONDS=$(FUZZ_SECONDS) FUZZ_JOBS=$(FUZZ_JOBS) bash fuzz/run.sh

clean:
	rm -rf build build-asan build-fuzz results

format:
	@git ls-files '*.cpp' '*.h' | xargs clang-format -i
