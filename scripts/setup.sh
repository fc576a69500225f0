#!/usr/bin/env bash
# Set up the workspace on a fresh machine, or bring it up to date: the virtual environment in
# .venv/ with the pinned dependencies, then a colcon build into install/. Idempotent, and quick
# when nothing changed (each step is skipped while its inputs hash the same).
set -euo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)

python=${PYTHON:-python3.11}
command -v "$python" >/dev/null 2>&1 || python=python3
"$python" -c 'import sys; assert sys.version_info[:2] == (3, 11), sys.version' \
  || { echo "setup: Python 3.11 is required (set PYTHON=...)" >&2; exit 1; }

if [ ! -x .venv/bin/python ]; then
  echo "setup: creating .venv"
  "$python" -m venv .venv
fi

req_hash=$(sha256sum requirements.txt | cut -d' ' -f1)
if [ "$(cat .venv/.requirements.sha256 2>/dev/null)" != "$req_hash" ]; then
  echo "setup: installing requirements.txt into .venv"
  .venv/bin/python -m pip install --quiet --upgrade pip
  .venv/bin/python -m pip install --quiet -r requirements.txt
  echo "$req_hash" > .venv/.requirements.sha256
fi

# --symlink-install links the Python sources, so editing a module needs no rebuild; only the
# package metadata, entry points and installed data files do. tests/ is the package inflarm_tests
# (the suite, for `colcon test`).
packages=(inflarm_*/ tests/)
build_hash=$(find "${packages[@]}" -type f \( -name setup.py -o -name setup.cfg \
    -o -name package.xml -o -path '*/resource/*' -o -path '*/config/*' -o -path '*/schema/*' \
    -o -path '*/urdf/*' -o -path '*/launch/*' -o -path '*/rviz/*' \) \
    -print0 | sort -z | xargs -0 sha256sum | sha256sum | cut -d' ' -f1)
mkdir -p log
if [ "$(cat install/.build.sha256 2>/dev/null)" != "$build_hash" ]; then
  echo "setup: colcon build"
  .venv/bin/colcon --log-base log build --symlink-install --base-paths "${packages[@]}" \
    --build-base build --install-base install --event-handlers console_cohesion- summary+ \
    >log/colcon-build.txt 2>&1 || { cat log/colcon-build.txt >&2; exit 1; }
  tail -n 1 log/colcon-build.txt
  echo "$build_hash" > install/.build.sha256
fi
# The compiled kernels (numba): compiled once per source change (about a minute), later loaded
# from the on-disk cache in a second; compiling here keeps the first node start and test fast.
# shellcheck disable=SC1091
( source scripts/env.sh && python -c '
from inflarm_estimation.elastostatic import LoadTracker
from inflarm_model.elastostatics import warm_up
from inflarm_model.kinematics import FlexibleArm
from inflarm_planning.astar import plan_path
from inflarm_planning.scenario import GOAL, OBSTACLE, START
from inflarm_vision.tracker import warm_up as warm_up_vision
warm_up()
tracker = LoadTracker(FlexibleArm(), 172.71)
for _ in range(2):  # a cold start, then the compiled warm step
    tracker.update([0.3, 0.8, -1.2], [0.5, -1.0, 0.2])
plan_path(START, GOAL, [OBSTACLE], resolution=0.01, alert_margin=0.03)
warm_up_vision()
' ) || { echo "setup: compiling the kernels failed" >&2; exit 1; }
echo "setup: ready ($root)"
