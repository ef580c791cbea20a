#!/usr/bin/env bash
# Runs every benchmark executable built from perf/*.cpp and writes one JSON
# file per benchmark into OUT_DIR. Usage: perf/run-benchmarks.sh BUILD_DIR OUT_DIR
set -euo pipefail
build=${1:-build/release}
out=${2:-out/bench}
mkdir -p "$out"
shopt -s nullglob
ran=0
for src in perf/*.cpp; do
  name=$(basename "$src" .cpp)
  exe="$build/perf/$name"
  [ -x "$exe" ] || { echo "run-benchmarks: $exe not built" >&2; exit 1; }
  echo "== $name"
  extra=()
  # The tracer's, the replay's and the launch model's ratios compare benchmarks that run
  # seconds apart: repetitions in random interleaved order, the fastest of each counts
  # (perf/summarize.py), so that a noisy neighbour does not decide a ratio.
  case "$name" in
    tracer_overhead|replay_speed) extra=(--benchmark_repetitions=5 --benchmark_enable_random_interleaving=true) ;;
    rtcore_speed) extra=(--benchmark_repetitions=3 --benchmark_enable_random_interleaving=true) ;;
  esac
  "$exe" --benchmark_out="$out/$name.json" --benchmark_out_format=json "${extra[@]}"
  ran=$((ran + 1))
done
echo "run-benchmarks: $ran benchmark programs, JSON in $out/"
python3 perf/summarize.py "$out"
