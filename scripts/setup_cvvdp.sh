#!/usr/bin/env bash
# Makes .venv-cvvdp: ColorVideoVDP (cvvdp) with PyTorch from PyPI, for scripts/cvvdp_score.py.
# Kept apart from .venv because PyTorch's wheels bring their CUDA libraries (about 5.7 GB);
# Debian's python3-torch (1.13.0a0) fails inside cvvdp with an IndexError. Only benchmark runs
# need it, never the build, the tests or the extension.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
python=${PYTHON:-python3}
[ -x .venv-cvvdp/bin/python ] || "$python" -m venv .venv-cvvdp
.venv-cvvdp/bin/python -m pip install -q --disable-pip-version-check -r requirements-cvvdp.txt
