#!/usr/bin/env bash
# Compiles the GPU check's CUDA program (gpucheck/src/gpucheck.cu) for sm_90
# with the flags of gpucheck/CMakeLists.txt, without running it (no GPU
# needed), and checks ptxas' report: the traversal kernel keeps its arrays in
# registers (0 bytes of stack frame, no spills), so no local memory goes
# through the L1 whose counters the check compares. ctest runs it where nvcc
# exists. Usage: scripts/check_gpucheck_cuda.sh NVCC SOURCE_DIR
set -euo pipefail
nvcc=$1 src=$2
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
"$nvcc" -std=c++17 -arch=sm_90 --fmad=false -prec-div=true -prec-sqrt=true -O3 -I"$src/gpucheck/include" \
  -Xptxas -v -c "$src/gpucheck/src/gpucheck.cu" -o "$out/gpucheck.o" 2>"$out/ptxas.txt"
report=$(grep -A2 "Compiling entry function.*traverse" "$out/ptxas.txt")
echo "$report"
grep -q "0 bytes stack frame, 0 bytes spill stores, 0 bytes spill loads" <<<"$report" ||
  { echo "check_gpucheck_cuda: the traversal kernel uses local memory" >&2; exit 1; }
