#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# One-command setup for a fresh Debian 12 machine: installs the Debian packages translume
# needs (idempotent), configures and builds in ./build, then optionally runs the demo or tests.
#
#   bash tools/setup.sh            # install + build
#   bash tools/setup.sh --demo     # install + build + run the main job on the embedded default
#   bash tools/setup.sh --test     # install + build + run the whole test suite (ctest)
set -euo pipefail

usage() { echo "usage: bash tools/setup.sh [--demo|--test] [--build-dir DIR]" >&2; exit 2; }

mode=build
build_dir=""
while [ $# -gt 0 ]; do
  case "$1" in
    --demo) mode=demo ;;
    --test) mode=test ;;
    --build-dir) shift; [ $# -gt 0 ] || usage; build_dir=$1 ;;
    -h|--help) usage ;;
    *) echo "setup.sh: unknown argument '$1'" >&2; usage ;;
  esac
  shift
done

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
build_dir=${build_dir:-$root/build}

packages=(
  build-essential cmake ninja-build pkg-config git
  libeigen3-dev libceres-dev
  libopencv-dev libopencv-contrib-dev
  libopenimageio-dev openimageio-tools libopenexr-dev
  libopenvdb-dev libboost-iostreams-dev libtbb-dev
  libegl-dev libgl-dev libosmesa6-dev libegl-mesa0 libgl1-mesa-dri
  libcli11-dev nlohmann-json3-dev libspdlog-dev libfmt-dev
  libgtest-dev libgmock-dev libbenchmark-dev
)

sudo=""
if [ "$(id -u)" -ne 0 ]; then
  command -v sudo >/dev/null || { echo "setup.sh: run as root or install sudo" >&2; exit 1; }
  sudo=sudo
fi

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "setup.sh: installing ${#missing[@]} Debian packages: ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  $sudo apt-get update -qq || { echo "setup.sh: apt-get update failed" >&2; exit 1; }
  if ! $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/tmp/translume-apt.log 2>&1; then
    for p in "${missing[@]}"; do
      if ! $sudo apt-get install -y -qq --no-install-recommends "$p" >>/tmp/translume-apt.log 2>&1; then
        echo "setup.sh: could not install Debian package '$p' (log: /tmp/translume-apt.log)" >&2
        exit 1
      fi
    done
  fi
else
  echo "setup.sh: all ${#packages[@]} Debian packages already installed"
fi

jobs=$(nproc)
cmake -S "$root" -B "$build_dir" -G Ninja -DCMAKE_BUILD_TYPE=Release >/dev/null
echo "setup.sh: building in $build_dir with $jobs jobs"
cmake --build "$build_dir" -j "$jobs"

case "$mode" in
  demo)
    "$build_dir/tools/translume" demo -o "$root/out/demo"
    ;;
  test)
    ctest --test-dir "$build_dir" --output-on-failure -j "$jobs"
    ;;
esac
