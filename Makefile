# rtlab: two commands — `make demo` and `make test`. Both install missing Debian
# packages first (scripts/install-deps.sh), then configure + build Release.
.PHONY: deps configure build demo test bench converge workloads study gpu-study gpucheck-exports gpucheck doc-figures test-asan fuzz clean

deps:
	@bash scripts/install-deps.sh

configure: deps
	@cmake --preset release >/dev/null

build: configure
	@cmake --build --preset release

demo: build
	./build/release/apps/rtlab render --scene builtin:showcase --frames 3 --out out/demo
	@echo "demo: wrote out/demo/frame_0000.png .. frame_0002.png, EXR and stats.json"

test: build
	ctest --preset release

bench: build
	@mkdir -p out/bench
	@bash perf/run-benchmarks.sh build/release out/bench

# The workload table (docs/workloads.md): per suite workload and ray type,
# node and leaf visits, node-cache hit rates at 32 KiB and 1 MiB, rays per
# cycle on the RT-core model, from recorded and replayed rays (~10 minutes).
workloads: build
	@python3 perf/workloads.py build/release/apps/rtlab out/workloads docs/workloads.md

# Error against run time of the showcase's shadow, reflection, AO and GI
# denoisers at 480x270 and 320x180 (docs/denoise.md). References are cached
# in out/converge-cache: the first run renders them (tens of minutes), later
# runs take minutes.
converge: build
	@for e in shadows reflections ao gi; do \
	  ./build/release/apps/rtlab converge --scene builtin:showcase --effect $$e --out out/converge/showcase-$$e || exit $$?; \
	  ./build/release/apps/rtlab converge --scene builtin:showcase --effect $$e --width 320 --height 180 \
	    --out out/converge/showcase-$$e-320x180 || exit $$?; \
	done
	@python3 perf/converge_table.py out/converge

# The example study of docs/studies.md: node-cache size x scheduling policy on
# three workloads (27 points), then its report (out/study/report.html).
# Resumable: run it again after an interruption.
study: build
	./build/release/apps/rtlab sweep docs/studies/cache-policy.json --out out/study --jobs $$(nproc)
	./build/release/apps/rtlab report out/study

# The deterministic tables of README.md and docs/ (cycles, rays, hit rates),
# rewritten from the commands that produce them (scripts/check_doc_figures.py;
# `make test` checks them).
doc-figures: build
	@python3 scripts/check_doc_figures.py build/release/apps/rtlab --write

# The GPU study (docs/studies/gpu-study.md): four study files through rtlab
# sweep, their reports, and the page's tables rewritten (a few minutes).
gpu-study: build
	@python3 scripts/gpu_study.py build/release/apps/rtlab --jobs 2

# The GPU check (docs/validation.md). Here: the exports of its rows
# (out/gpucheck/exports and out/gpucheck/exports.tar.xz, about 10 minutes).
gpucheck-exports: build
	@scripts/gpucheck_exports.sh out/gpucheck/exports build/release/apps/rtlab

# On a machine with an NVIDIA GPU, CMake and the CUDA toolkit (no other
# dependency): the check and its measurement, GPUCHECK_EXPORTS (a directory
# or .tar.xz from gpucheck-exports) into GPUCHECK_OUT.
GPUCHECK_EXPORTS ?= out/gpucheck/exports.tar.xz
GPUCHECK_OUT ?= out/gpucheck/h100
gpucheck:
	@perf/gpucheck.sh $(GPUCHECK_EXPORTS) $(GPUCHECK_OUT)

# The sanitizer configuration (ASan + UBSan) over the whole suite.
test-asan: deps
	@cmake --preset asan >/dev/null
	@cmake --build --preset asan
	ctest --preset asan

# Coverage-guided fuzzing (docs/reliability.md): every libFuzzer target of
# fuzz/ (clang, ASan + UBSan; its own preset, build/fuzz) for FUZZ_SECONDS
# each, in parallel on the machine's cores; FUZZ_TARGETS=a,b for some only.
# Corpora grow in out/fuzz/corpus, findings land in out/fuzz/findings.
FUZZ_SECONDS ?= 60
FUZZ_TARGETS ?= all
fuzz: build
	@cmake --preset fuzz >/dev/null
	@cmake --build --preset fuzz
	@python3 scripts/fuzz.py --fuzz-build build/fuzz --rtlab build/release/apps/rtlab --seconds $(FUZZ_SECONDS) \
	  --jobs $$(nproc) --targets $(FUZZ_TARGETS)

clean:
	rm -rf build out
