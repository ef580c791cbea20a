#!/usr/bin/env bash
# Installs exactly the Debian packages rtlab needs to build, test and benchmark,
# but only those that are missing. Idempotent: a second run does nothing.
set -euo pipefail

packages=(
  build-essential cmake ninja-build ccache pkg-config
  libembree-dev libtbb-dev
  libopenvdb-dev libboost-dev libboost-iostreams-dev libimath-dev libblosc-dev zlib1g-dev
  libglm-dev libtinygltf-dev nlohmann-json3-dev libstb-dev libtinyobjloader-dev libassimp-dev
  libopenexr-dev libcli11-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  libdraco-dev libmeshoptimizer-dev
  libopenmpi-dev openmpi-bin
  python3 python3-matplotlib chromium librsvg2-bin poppler-utils fonts-dejavu-core
  assimp-testmodels assimp-utils
  clang llvm
)

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#packages[@]} packages present"
  exit 0
fi

apt_line="apt-get install -y --no-install-recommends ${missing[*]}"
if [ "$(id -u)" -ne 0 ]; then
  echo "install-deps: missing packages: ${missing[*]}" >&2
  echo "install-deps: not root; run as root:  apt-get update && $apt_line" >&2
  exit 1
fi

echo "install-deps: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq
# shellcheck disable=SC2086
apt-get install -y -qq --no-install-recommends "${missing[@]}"
echo "install-deps: done"
