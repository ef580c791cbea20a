#!/usr/bin/env bash
# The exports of docs/validation.md's rows: each workload recorded on the
# model at 320x180, one frame, and exported per ray type with the h100-like
# preset set up as the CUDA kernel runs (docs/validation.md, "The model's
# side"). Usage: scripts/gpucheck_exports.sh OUT [RTLAB] [--rtcore-set k=v ...]
#   OUT/<workload>-<rays>/   one export each (rtlab gpucheck-export)
#   OUT.tar.xz               all of them, for the device machine
set -euo pipefail
out=${1:?usage: scripts/gpucheck_exports.sh OUT [RTLAB] [--rtcore-set k=v ...]}
rtlab=${2:-build/release/apps/rtlab}
shift $(( $# >= 2 ? 2 : 1 ))
engine=/usr/share/assimp/models/glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb
size=(--width 320 --height 180 --frames 1 --denoise none --backend rtcore)
# h100-like (its memory parameters calibrated by this check) set up as the kernel runs, as ncu
# reports it (docs/validation.md): the L1 the carve-out leaves (92 KB = 32 sets x 23 ways of 128-byte
# lines), 16 resident warps of one ray per thread.
model=(--rtcore-config h100-like --rtcore-set cache.sizeBytes=94208 --rtcore-set cache.ways=23
       --rtcore-set gpu.residentWarps=16 --rtcore-set core.raySlots=512 "$@")
rows=(
  "terrain|builtin:terrain?triangles=200000|gbuffer|primary"
  "terrain|builtin:terrain?triangles=200000|ao|ao"
  "forest|builtin:forest?instances=500|gbuffer|primary"
  "forest|builtin:forest?instances=500|pathtrace|pathBounce"
  "slivers|builtin:slivers?triangles=200000|gbuffer|primary"
  "slivers|builtin:slivers?triangles=200000|shadows|shadow"
  "engine|$engine|gbuffer|primary"
  "engine|$engine|pathtrace|pathBounce"
)
mkdir -p "$out/recordings"
for row in "${rows[@]}"; do
  IFS='|' read -r name scene effects types <<<"$row"
  rec="$out/recordings/$name-$effects"
  if [[ ! -f "$rec/frame_0000.rays" ]]; then
    echo "recording $name ($effects)" >&2
    "$rtlab" render --scene "$scene" "${size[@]}" --effects "$effects" --record-rays "$rec" --out "$rec.render" >/dev/null
  fi
  echo "exporting $name-$types" >&2
  "$rtlab" gpucheck-export --scene "$scene" --rays "$rec/frame_0000.rays" --ray-types "$types" \
    --label "$name-$types" --out "$out/$name-$types" "${model[@]}"
done
[[ -n "${GPUCHECK_NO_TAR:-}" ]] && exit 0  # predictions made again with other parameters (perf/gpucheck_table.py --models)
tar -cJf "$out.tar.xz" -C "$(dirname "$out")" --exclude recordings --exclude '*.render' "$(basename "$out")"
ls -l "$out.tar.xz" >&2
