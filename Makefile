# phos: the two set-up commands of the README, and a few more.
#   make demo   install what is missing (apt), build in Release, run the main job
#   make test   install what is missing, build under ASan+UBSan, run every test (ctest)
# Other targets: build (Release only), bench (benchmarks, Release), study
# (regenerate the integrator error, Glassner and nc trade studies in docs/), clean.

JOBS ?= $(shell nproc)

.PHONY: all bootstrap build demo test bench study clean

all: build

bootstrap:
	@bash scripts/bootstrap.sh

build: bootstrap
	@cmake --preset release >/dev/null
	@cmake --build --preset release -j $(JOBS)

demo: build
	@bash scripts/demo.sh

test: bootstrap
	@cmake --preset asan >/dev/null
	@cmake --build --preset asan -j $(JOBS)
	@ctest --preset asan -j $(JOBS)

bench: build
	@bash scripts/bench.sh

study: build
	@build/bin/phos-integrator-study --out docs
	@build/bin/phos-glassner-study --out docs
	@build/bin/phos-nc-study --out docs
	@build/bin/phos-dss-study --out docs
	@build/bin/phos-appearance-study --out docs

clean:
	rm -rf build build-asan results
