#!/usr/bin/env bash
# Runs the Blender extension's suite (tests/blender) on other Blenders than the two that
# scripts/test.sh covers (bpy 5.0.1 and 5.3.0): by default the LTS releases 4.2 and 4.5, and on
# request 5.1 and 5.2. Each bpy gets its own venv: the Python 3.11 ones (4.2, 4.5) under
# build-blender-versions/, the Python 3.13 ones (5.1, 5.2) inside the Debian 13 root of
# scripts/setup_py313.sh (/opt/venv-bpy-<version>). Besides bpy they install the pins of
# requirements-blender.txt (3.11) or requirements-blender-5.3.txt (3.13). Needs scripts/setup.sh
# first (the core, the extension zip and, for 5.x, the root). Logs go to
# build-blender-versions/bpy-<version>.log; the exit status is non-zero when a suite failed.
#
# Usage: scripts/test_blender_versions.sh [4.2] [4.5] [5.1] [5.2]
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"

declare -A pins=(
  [4.2]=4.2.23   # the last 4.2 LTS on PyPI
  [4.5]=4.5.15   # the last 4.5 LTS on PyPI
  [5.1]=5.1.2
  [5.2]=5.2.4    # LTS
)
versions=("$@")
[ ${#versions[@]} -gt 0 ] || versions=(4.2 4.5)
for series in "${versions[@]}"; do
  if [ -z "${pins[$series]:-}" ]; then
    echo "test_blender_versions: unknown version $series (known: ${!pins[*]})" >&2
    exit 2
  fi
done

out=$root/build-blender-versions
mkdir -p "$out"
failed=()
for series in "${versions[@]}"; do
  bpy=${pins[$series]}
  log=$out/bpy-$bpy.log
  start=$(date +%s)
  case $series in
    4.*)
      venv=$out/venv-$bpy
      [ -x "$venv/bin/python" ] || "${PYTHON:-python3}" -m venv "$venv"
      "$venv/bin/python" -m pip install -q --disable-pip-version-check "bpy==$bpy" \
        -r <(grep -v '^bpy==' requirements-blender.txt)
      set +e
      PYTHONPATH="$root/build/python:$root/blender_addon" AFFINITY_REQUIRE_CORE=1 \
        nice "$venv/bin/python" -m pytest -q -W error -rs tests/blender >"$log" 2>&1
      status=$?
      set -e
      ;;
    5.*)
      venv=/opt/venv-bpy-$bpy
      # The requirements are read inside the root, from the repository mounted there.
      grep -v '^bpy==' requirements-blender-5.3.txt >"$out/requirements-5.x.txt"
      scripts/in_py313_root.sh sh -c "[ -x $venv/bin/python ] || python3.13 -m venv $venv
        $venv/bin/python -m pip install -q --disable-pip-version-check bpy==$bpy \
          -r build-blender-versions/requirements-5.x.txt"
      scripts/in_py313_root.sh python -m pip install -q --no-deps --no-index --disable-pip-version-check \
        --upgrade --target build-py313/python blender_addon/affinity_denoiser/wheels/affinity_core-*-cp313-*.whl
      set +e
      scripts/in_py313_root.sh env PYTHONPATH="$root/build-py313/python:$root/blender_addon" \
        AFFINITY_REQUIRE_CORE=1 nice "$venv/bin/python" -m pytest -q -W error -rs tests/blender >"$log" 2>&1
      status=$?
      set -e
      ;;
  esac
  summary=$(grep -E '^(=+ )?[0-9]+ (passed|failed)|[0-9]+ (passed|failed|error)' "$log" | tail -n 1)
  echo "bpy $bpy: ${summary:-no summary, see $log} ($(($(date +%s) - start)) s; log: ${log#"$root"/})"
  if [ $status -ne 0 ]; then
    grep -E '^(FAILED|ERROR) ' "$log" || true
    failed+=("$bpy")
  fi
done
if [ ${#failed[@]} -gt 0 ]; then
  echo "test_blender_versions: failures on bpy ${failed[*]}" >&2
  exit 1
fi
