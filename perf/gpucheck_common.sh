# Sourced by perf/gpucheck.sh and perf/gpucheck_occupancy.sh: the exports
# (a directory, or a .tar.xz of one, unpacked) and the standalone build.
# gpucheck_exports PATH: prints the directory of the exports' subdirectories.
gpucheck_exports() {
  local exports=$1
  if [[ -f "$exports" ]]; then
    local dir
    dir=$(mktemp -d)
    tar -xJf "$exports" -C "$dir"
    exports=$(find "$dir" -name model.json -printf '%h\n' | xargs -n1 dirname | sort -u | head -1)
  fi
  echo "$exports"
}
# gpucheck_build ROOT: builds gpucheck/ (CMake and the CUDA toolkit only) into ROOT/build/gpucheck.
gpucheck_build() {
  cmake -S "$1/gpucheck" -B "$1/build/gpucheck" -G Ninja -DCMAKE_BUILD_TYPE=Release >/dev/null
  cmake --build "$1/build/gpucheck" >/dev/null
}
