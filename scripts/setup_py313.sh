#!/usr/bin/env bash
# Python 3.13 beside the host's 3.11, for Blender 5.1 and later (their Python is 3.13): a Debian 13
# ("trixie") root in build-py313/root, made with debootstrap from the Debian mirror apt uses here.
# It gives two things:
#   - build-py313/build-venv: Debian 13's python3.13 run on this host through Debian 13's own
#     dynamic loader, with scikit-build-core and pybind11 (pins of requirements.txt), and the
#     Python 3.13 headers in build-py313/include. scripts/build_extension.sh builds the cp313
#     wheel with it: the host's CMake, compiler and libraries, so the module needs the host's
#     glibc (2.34 after auditwheel) and not Debian 13's 2.41.
#   - /opt/venv-blender inside the root: bpy 5.3 (requirements-blender-5.3.txt) for the tests,
#     run by scripts/in_py313_root.sh.
# Needs root (or sudo): debootstrap and chroot. Idempotent and quick when everything is there.
#
# Usage: scripts/setup_py313.sh            (scripts/setup.sh runs it)
set -euo pipefail
repo=$(cd "$(dirname "$0")/.." && pwd)
cd "$repo"
sudo_cmd=""; [ "$(id -u)" -ne 0 ] && sudo_cmd="sudo"

dir=$repo/build-py313
rootfs=$dir/root
# Python with headers and venv, and the shared libraries bpy loads at import (X11, GL, EGL,
# Wayland client), which a minbase system lacks.
packages=(python3.13 python3.13-venv python3.13-dev ca-certificates
          libx11-6 libxrender1 libxxf86vm1 libxfixes3 libxi6 libxkbcommon0 libsm6 libgl1 libegl1
          libxext6 libwayland-client0)
marker=$rootfs/.affinity-packages

if [ ! -f "$marker" ] || [ "$(cat "$marker")" != "${packages[*]}" ]; then
  if ! command -v debootstrap >/dev/null 2>&1; then
    echo "setup_py313: installing debootstrap" >&2
    $sudo_cmd apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo_cmd apt-get install -y -qq debootstrap >/dev/null
  fi
  # The first non-security Debian archive of apt's sources (deb822 "URIs:" or one-line "deb").
  mirror=${AFFINITY_DEBIAN_MIRROR:-$(set +o pipefail
    cat /etc/apt/sources.list /etc/apt/sources.list.d/*.list /etc/apt/sources.list.d/*.sources 2>/dev/null \
    | grep -E '^[[:space:]]*(URIs:|deb[[:space:]])' \
    | sed -E 's/^[[:space:]]*URIs:[[:space:]]*//; s/^[[:space:]]*deb[[:space:]]+(\[[^]]*\][[:space:]]+)?//' \
    | tr ' ' '\n' | grep -E '^https?://' | grep -v -- '-security' | head -n 1)}
  if [ -z "$mirror" ]; then
    echo "setup_py313: no Debian mirror in /etc/apt/sources.list*; set AFFINITY_DEBIAN_MIRROR" >&2
    exit 1
  fi
  echo "setup_py313: debootstrap trixie from $mirror into $rootfs" >&2
  start=$(date +%s)
  $sudo_cmd rm -rf "$rootfs.tmp"
  mkdir -p "$dir"
  include=$(IFS=,; echo "${packages[*]}")
  if ! $sudo_cmd debootstrap --variant=minbase --include="$include" trixie "$rootfs.tmp" "$mirror" \
      >"$dir/debootstrap.log" 2>&1; then
    tail -n 30 "$dir/debootstrap.log" >&2
    echo "setup_py313: debootstrap failed (log: $dir/debootstrap.log)" >&2
    exit 1
  fi
  $sudo_cmd rm -rf "$rootfs"
  $sudo_cmd mv "$rootfs.tmp" "$rootfs"
  echo "${packages[*]}" | $sudo_cmd tee "$marker" >/dev/null
  echo "setup_py313: Debian 13 root made in $(($(date +%s) - start)) s" >&2
fi

# pip inside the root reaches PyPI as the host does: same resolver and CA bundle (which may hold
# a proxy's certificate that Debian's bundle lacks).
$sudo_cmd cp /etc/resolv.conf "$rootfs/etc/resolv.conf"
$sudo_cmd cp /etc/ssl/certs/ca-certificates.crt "$rootfs/etc/ssl/certs/host-ca-certificates.crt"
# Blender lists the mounted file systems from /etc/mtab, which minbase leaves out (a warning
# at every start without it).
[ -e "$rootfs/etc/mtab" ] || [ -L "$rootfs/etc/mtab" ] || $sudo_cmd ln -s ../proc/self/mounts "$rootfs/etc/mtab"

# --- The build interpreter: Debian 13's python3.13 on this host. Its glibc is newer than the
# host's, so it runs through the root's loader with the root's libraries; pyvenv.cfg makes it a
# venv whose base is the root's /usr, and --argv0 makes sys.executable this script, so that
# CMake and scikit-build-core can run it again.
venv=$dir/build-venv
python=$venv/bin/python3.13
mkdir -p "$venv/bin" "$venv/lib/python3.13/site-packages"
printf 'home = %s/usr/bin\ninclude-system-site-packages = false\nversion = 3.13\n' "$rootfs" \
  >"$venv/pyvenv.cfg"
cat >"$python.new" <<EOF
#!/bin/sh
exec "$rootfs/usr/lib/x86_64-linux-gnu/ld-linux-x86-64.so.2" --library-path \
  "$rootfs/usr/lib/x86_64-linux-gnu" --argv0 "\$0" "$rootfs/usr/bin/python3.13" "\$@"
EOF
chmod +x "$python.new"
mv "$python.new" "$python"
ln -sf python3.13 "$venv/bin/python"
# The build tools, pinned in requirements.txt; pure Python, installed by the host's pip for 3.13.
mapfile -t tools < <(grep -E '^(scikit-build-core|pybind11)==' requirements.txt)
stamp=$venv/.tools
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "${tools[*]}" ]; then
  "$repo/.venv/bin/python" -m pip install -q --disable-pip-version-check --upgrade \
    --target "$venv/lib/python3.13/site-packages" --python-version 3.13 --only-binary=:all: \
    "${tools[@]}"
  echo "${tools[*]}" >"$stamp"
fi
# Debian's /usr/include/python3.13/pyconfig.h includes <x86_64-linux-gnu/python3.13/pyconfig.h>,
# which the host compiler would look for in the host's /usr/include: a copy of the headers with
# the real pyconfig.h, so that no other Debian 13 header (glibc's!) is ever on the include path.
headers=$dir/include/python3.13
if [ ! -f "$headers/Python.h" ] || [ "$rootfs/usr/include/python3.13/Python.h" -nt "$headers/Python.h" ]; then
  rm -rf "$headers"
  mkdir -p "$(dirname "$headers")"
  cp -r "$rootfs/usr/include/python3.13" "$headers"
  cp "$rootfs/usr/include/x86_64-linux-gnu/python3.13/pyconfig.h" "$headers/pyconfig.h"
fi
"$python" -c 'import sys; assert sys.version_info[:2] == (3, 13), sys.version' \
  || { echo "setup_py313: $python does not run" >&2; exit 1; }

# --- bpy 5.3 for the tests, in a venv inside the root.
"$repo/scripts/in_py313_root.sh" sh -c '
  set -e
  [ -x /opt/venv-blender/bin/python ] || python3.13 -m venv /opt/venv-blender
  /opt/venv-blender/bin/python -m pip install -q \
    --disable-pip-version-check -r requirements-blender-5.3.txt'
