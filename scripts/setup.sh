#!/usr/bin/env bash
# Sets up everything the project needs on a fresh Debian 12 machine, then builds it.
# Idempotent: packages already present are not reinstalled, an existing build is reused.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"

debian_packages=(
  build-essential cmake ninja-build pkg-config
  libembree-dev libtbb-dev libopenexr-dev nlohmann-json3-dev libglm-dev libstb-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  clang clang-format libclang-rt-14-dev
  libtorch-dev libopenblas0-pthread libdnnl-dev ocl-icd-opencl-dev
  python3 python3-dev python3-venv
  debootstrap
)
missing=()
for p in "${debian_packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "setup: installing ${missing[*]}" >&2
  sudo_cmd=""; [ "$(id -u)" -ne 0 ] && sudo_cmd="sudo"
  $sudo_cmd apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo_cmd apt-get install -y -qq "${missing[@]}" >/dev/null
fi

python=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  "$python" -m venv .venv
fi
.venv/bin/python -m pip install -q --disable-pip-version-check -r requirements.txt
# bpy (Blender as a Python module, ~500 MB) for the Blender extension's tests, in its own venv.
if [ ! -x .venv-blender/bin/python ]; then
  "$python" -m venv .venv-blender
fi
.venv-blender/bin/python -m pip install -q --disable-pip-version-check -r requirements-blender.txt

build_dir=${AFFINITY_BUILD_DIR:-build}
cmake -S . -B "$build_dir" -G Ninja -DCMAKE_BUILD_TYPE=Release \
  -DPython_EXECUTABLE="$root/.venv/bin/python" ${AFFINITY_CMAKE_ARGS:-} >/dev/null
cmake --build "$build_dir" -j "${AFFINITY_JOBS:-2}"
# Python 3.13 (Blender 5.1 and later) from a Debian 13 root: the cp313 wheel's interpreter and
# headers, and bpy 5.3 for the tests (quick when already made).
"$root/scripts/setup_py313.sh"
# The core's wheels for Blender's Pythons in the extension, and the extension zip (skipped when
# nothing changed).
"$root/scripts/build_extension.sh"
