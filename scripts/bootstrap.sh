#!/usr/bin/env bash
# kestrel set-up on a fresh Debian 12 machine: installs what is missing, builds (Release),
# then runs the main job (`demo`) or the whole test suite (`test`).
#   bash scripts/bootstrap.sh demo   # install + build + run the real-time pipeline on the built-in Cornell box
#   bash scripts/bootstrap.sh test   # install + build + run every test (ctest)
set -euo pipefail
mode=${1:-demo}
here=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
build_dir=${KESTREL_BUILD_DIR:-$here/build/release}

packages=(build-essential cmake ninja-build ccache pkg-config
  libtbb-dev libtinyobjloader-dev libtinygltf-dev nlohmann-json3-dev libstb-dev
  libpng-dev libcli11-dev libfmt-dev libgtest-dev libgmock-dev libbenchmark-dev
  libembree-dev libopenexr-dev zlib1g-dev libdnnl-dev python3 python3-matplotlib
  libsdl2-dev libsdl2-ttf-dev fonts-dejavu-core xvfb xauth
  python3-dev pybind11-dev python3-pybind11 python3-numpy python3-pytest python3-venv python3-pip
  python3-setuptools python3-wheel libopenmpi-dev openmpi-bin clang-14 libclang-rt-14-dev clang-format-14)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "bootstrap: installing ${missing[*]}"
  sudo_cmd=()
  [ "$(id -u)" -ne 0 ] && sudo_cmd=(sudo)
  export DEBIAN_FRONTEND=noninteractive
  "${sudo_cmd[@]}" apt-get update -qq
  "${sudo_cmd[@]}" apt-get install -y -qq "${missing[@]}"
fi

launcher=()
command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
# Paths under the checkout hashed relative to it (and the working directory not hashed for
# -g builds): clones in other folders, as CI's, share the cache instead of compiling cold.
export CCACHE_BASEDIR="$here" CCACHE_NOHASHDIR=1
cmake -S "$here" -B "$build_dir" -G Ninja -DCMAKE_BUILD_TYPE=Release "${launcher[@]}"
cmake --build "$build_dir" -j "$(nproc)"

case "$mode" in
  demo)
    mkdir -p "$here/out"
    # The real-time pipeline (1-spp path tracing -> neural denoiser -> neural 2x2 upsampler
    # -> tone map) along an orbit of the built-in Cornell box: frames and per-stage timings.
    "$build_dir/apps/kestrel/kestrel" run builtin:cornell_box --path orbit:30 --frames 30 \
      --res 1280x720 --internal 640x360 -o "$here/out/run" --quiet
    ;;
  test)
    cd "$build_dir" && ctest --output-on-failure -j "$(nproc)"
    ;;
  build) ;;
  *) echo "usage: bootstrap.sh demo|test|build" >&2; exit 2 ;;
esac
