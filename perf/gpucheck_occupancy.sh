#!/usr/bin/env bash
# The GPU check at fewer resident blocks per SM, the L1 unchanged
# (docs/validation.md, "Rays in flight"): for each named workload of EXPORTS
# and each B, the CUDA check with --blocks-per-sm B under Nsight Compute
# (traversal and empty-scene baseline, as perf/gpucheck.sh), into
# OUT/<workload>-b<B>.*; perf/gpucheck_table.py OUT --models DIR then compares
# with predictions made for the same residency (DIR/<workload>-b<B>/model.json).
#   perf/gpucheck_occupancy.sh EXPORTS OUT "2 4 8" WORKLOAD...
set -euo pipefail
exports=${1:?usage: perf/gpucheck_occupancy.sh EXPORTS OUT "B..." WORKLOAD...}
out=${2:?}; counts=${3:?}; shift 3
here=$(cd "$(dirname "$0")/.." && pwd)
mkdir -p "$out"
source "$here/perf/gpucheck_common.sh"
exports=$(gpucheck_exports "$exports")
gpucheck_build "$here"
bin="$here/build/gpucheck/gpucheck"
metrics=l1tex__t_sectors_pipe_lsu_mem_global_op_ld.sum,l1tex__t_sectors_pipe_lsu_mem_global_op_ld_lookup_hit.sum,\
l1tex__t_sectors_pipe_lsu_mem_global_op_ld_lookup_miss.sum,lts__t_sectors_srcunit_tex_op_read.sum,\
lts__t_sectors_srcunit_tex_op_read_lookup_hit.sum,dram__bytes_read.sum,launch__shared_mem_config_size,\
sm__warps_active.avg.per_cycle_active,lts__t_sectors_srcunit_ltcfabric_op_read.sum,\
lts__t_sectors_srcunit_ltcfabric_op_read_lookup_hit.sum,gpu__time_duration.sum
for w in "$@"; do
  for b in $counts; do
    name="$w-b$b"
    echo "== $name"
    "$bin" "$exports/$w" --blocks-per-sm "$b" --repeat 5 --json "$out/$name.run.json"
    for k in traverse io; do
      flags=(--repeat 0 --blocks-per-sm "$b"); [[ $k == io ]] && flags+=(--io-only)
      ncu --cache-control all --clock-control base --kernel-name traverse --launch-count 1 --csv --print-units base \
          --metrics "$metrics" "$bin" "$exports/$w" "${flags[@]}" >"$out/$name.$k.csv" 2>"$out/$name.$k.log" ||
        { cat "$out/$name.$k.log" >&2; exit 3; }
    done
  done
done
