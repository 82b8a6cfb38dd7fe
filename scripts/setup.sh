#!/usr/bin/env bash
# Set up spacemap on a fresh Debian machine (run as root): the Debian packages open3d and
# MuJoCo's offscreen GL need, when missing; a .venv in the repo; the package with its deps.
set -euo pipefail
cd "$(dirname "$0")/.."

PY=${PYTHON:-python3.11}
command -v "$PY" >/dev/null 2>&1 || PY=python3

need=()
for pkg in libusb-1.0-0 libgl1 libegl1 libgl1-mesa-dri libegl-mesa0 libosmesa6 iproute2; do
  dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || need+=("$pkg")
done
if ! "$PY" -m venv --help >/dev/null 2>&1 || ! "$PY" -c "import ensurepip" >/dev/null 2>&1; then
  need+=(python3-venv)
fi
if [ ${#need[@]} -gt 0 ]; then
  echo "setup: installing Debian packages: ${need[*]}"
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends "${need[@]}"
fi

[ -x .venv/bin/python ] || "$PY" -m venv .venv
.venv/bin/python -m pip install -q --upgrade pip
.venv/bin/python -m pip install -q -e ".[dev]"
# the edge's compiled Dijkstra (numba) is compiled once here and cached beside its source,
# not in a mission's first plan
.venv/bin/python -m services.common.grid_search
echo "setup: done ($(.venv/bin/python --version))"
