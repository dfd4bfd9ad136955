#!/usr/bin/env bash
# Runs a command inside the Debian 13 root of scripts/setup_py313.sh (Python 3.13, and bpy 5.3 in
# /opt/venv-blender), in the repository's folder: the repository is mounted at the same path
# inside the root, so paths mean the same in and out. /proc, /dev and /sys are mounted too.
# The mounts are made in a private mount namespace (unshare), so they vanish with the command,
# however it ends, and the host never sees them. The environment is reset to PATH (the bpy venv
# first), HOME, LANG, TERM and PIP_CERT (the host's CA bundle, copied in by setup_py313.sh);
# pass others with `env`. Needs root (or sudo).
#
# Usage: scripts/in_py313_root.sh COMMAND [ARG...]
#   e.g. scripts/in_py313_root.sh env PYTHONPATH=blender_addon python -m pytest -q tests/blender
set -euo pipefail
repo=$(cd "$(dirname "$0")/.." && pwd)
rootfs=$repo/build-py313/root
if [ $# -eq 0 ]; then
  echo "usage: $0 COMMAND [ARG...]" >&2
  exit 2
fi
if [ ! -x "$rootfs/usr/bin/python3.13" ]; then
  echo "in_py313_root: $rootfs has no python3.13 (run scripts/setup_py313.sh)" >&2
  exit 1
fi
sudo_cmd=""; [ "$(id -u)" -ne 0 ] && sudo_cmd="sudo"
cwd=$(pwd)
case "$cwd/" in
  "$repo"/*) ;;
  *) echo "in_py313_root: run it from inside $repo (only the repository is mounted)" >&2; exit 1 ;;
esac

# Inside the namespace: "$@" of this heredoc's shell is root, repo, cwd, then the command.
exec $sudo_cmd unshare --mount --propagation private /bin/sh -e -c '
  rootfs=$1 repo=$2 cwd=$3; shift 3
  mount -t proc proc "$rootfs/proc"
  mount --rbind /dev "$rootfs/dev"
  mount --rbind /sys "$rootfs/sys"
  mkdir -p "$rootfs$repo"
  mount --bind "$repo" "$rootfs$repo"
  exec chroot "$rootfs" /usr/bin/env -i \
    PATH=/opt/venv-blender/bin:/usr/local/bin:/usr/bin:/bin HOME=/root LANG=C.UTF-8 \
    TERM="${TERM:-dumb}" PIP_CERT=/etc/ssl/certs/host-ca-certificates.crt /bin/sh -c "cd \"\$0\" && exec \"\$@\"" "$cwd" "$@"
' in_py313_root "$rootfs" "$repo" "$cwd" "$@"
