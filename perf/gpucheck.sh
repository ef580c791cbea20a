#!/usr/bin/env bash
# The GPU check's measurement (docs/validation.md), for a machine with an
# NVIDIA GPU, CMake and the CUDA toolkit (nothing else of rtlab's):
#
#   perf/gpucheck.sh EXPORTS OUT
#
# EXPORTS: a directory of exports (rtlab gpucheck-export, one subdirectory per
# workload x ray type; scripts/gpucheck_exports.sh makes the documented set),
# or a .tar.xz of one. For each: the host twin and the CUDA program check every
# ray against the model (exit 1 on a difference), the CUDA program is timed
# (median of 20 launches), and Nsight Compute reads the cache and DRAM
# counters of the traversal kernel, and of the same kernel over an empty scene
# (the rays' and answers' own traffic, subtracted), from a cold start at base
# clocks; an ncu failure stops the script (exit 3). Writes OUT/<workload>.{run,io}.json, OUT/<workload>.{traverse,io}.csv,
# OUT/gpu.txt and, through perf/gpucheck_table.py, OUT/gpucheck.json and OUT/table.md.
set -euo pipefail
exports=${1:?usage: perf/gpucheck.sh EXPORTS OUT}
out=${2:?usage: perf/gpucheck.sh EXPORTS OUT}
here=$(cd "$(dirname "$0")/.." && pwd)
mkdir -p "$out"
source "$here/perf/gpucheck_common.sh"
exports=$(gpucheck_exports "$exports")

# Step: the GPU, driver and clocks; ncu must read counters here.
{ nvidia-smi --query-gpu=name,driver_version,clocks.sm,clocks.max.sm,clocks.mem,clocks.max.mem,power.limit --format=csv
  nvcc --version | tail -2; ncu --version | tail -1; } | tee "$out/gpu.txt"

# Step: build (CMake and the CUDA toolkit only).
gpucheck_build "$here"
bin="$here/build/gpucheck"

metrics=l1tex__t_sectors_pipe_lsu_mem_global_op_ld.sum,l1tex__t_sectors_pipe_lsu_mem_global_op_ld_lookup_hit.sum,\
l1tex__t_sectors_pipe_lsu_mem_global_op_ld_lookup_miss.sum,l1tex__t_requests_pipe_lsu_mem_global_op_ld.sum,\
l1tex__t_sector_hit_rate.pct,lts__t_sectors_srcunit_tex_op_read.sum,lts__t_sectors_srcunit_tex_op_read_lookup_hit.sum,\
lts__t_sectors_srcunit_tex_op_read_lookup_miss.sum,lts__t_sector_hit_rate.pct,dram__bytes_read.sum,dram__bytes_write.sum,\
gpu__time_duration.sum,launch__shared_mem_config_size,launch__registers_per_thread,launch__occupancy_limit_registers,\
launch__occupancy_limit_shared_mem,sm__warps_active.avg.per_cycle_active,sm__cycles_elapsed.avg.per_second,\
lts__t_sectors_srcunit_ltcfabric_op_read.sum,lts__t_sectors_srcunit_ltcfabric_op_read_lookup_hit.sum
ncu_run() {  # kernel csv args...: every metric or nothing (a missing one is an error, not a zero)
  local kernel=$1 csv=$2; shift 2
  ncu --cache-control all --clock-control base --kernel-name "$kernel" --launch-count 1 --csv --print-units base \
      --metrics "$metrics" "$@" >"$csv" 2>"$csv.log" || { cat "$csv.log" >&2; echo "ncu failed: $csv" >&2; exit 3; }
}

status=0
for d in "$exports"/*/; do
  name=$(basename "$d")
  [[ -f "$d/model.json" ]] || continue
  echo "== $name"
  "$bin/gpucheck-host" "$d" || status=1
  "$bin/gpucheck" "$d" --repeat 20 --json "$out/$name.run.json" || status=1
  "$bin/gpucheck" "$d" --repeat 0 --io-only --json "$out/$name.io.json" >/dev/null
  ncu_run traverse "$out/$name.traverse.csv" "$bin/gpucheck" "$d" --repeat 0
  ncu_run traverse "$out/$name.io.csv" "$bin/gpucheck" "$d" --repeat 0 --io-only
  # Optional counters, one ncu run each (a name this ncu lacks costs only itself):
  # GPUCHECK_EXTRA_METRICS="a,b,..." into OUT/<workload>.{traverse,io}.extra.csv.
  extra=${GPUCHECK_EXTRA_METRICS:-}
  for m in ${extra//,/ }; do
    for k in traverse io; do
      kernel=traverse; flags=(--repeat 0)
      [[ $k == io ]] && flags=(--repeat 0 --io-only)
      ncu --cache-control all --clock-control base --kernel-name $kernel --launch-count 1 --csv --print-units base \
          --metrics "$m" "$bin/gpucheck" "$d" "${flags[@]}" 2>>"$out/$name.extra.log" |
        grep "\"$m\"" >>"$out/$name.$k.extra.csv" || echo "ncu: no $m" >>"$out/$name.extra.log"
    done
  done
  cp "$d/model.json" "$out/$name.model.json"
done
python3 "$here/perf/gpucheck_table.py" "$out" | tee "$out/table.md"
exit $status
