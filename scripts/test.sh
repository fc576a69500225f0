#!/usr/bin/env bash
# Set up the workspace (idempotent) and run every check: ruff, then pytest (core, node and
# multi-process DDS tests): the full suite, what CI (.ci/run) runs. Extra arguments go to pytest,
# e.g. `scripts/test.sh tests/model -x`.
#
# `scripts/test.sh --fast [pytest args]`: the fast lane, the same with `-m 'not system'`: the
# cores and the in-process node tests, without the tests marked `system` (those that start
# processes: node executables over DDS, colcon, Dask, Chromium; tests/conftest.py marks every
# test that uses the node_processes fixture), on every core (pytest-xdist, one test module per
# worker at a time, so a module's fixtures are built once). About 2 minutes on 2 cores instead
# of the full suite's fifteen; not a substitute for the full run before a merge.
set -euo pipefail
cd "$(dirname "$0")/.."
lane=()
args=()
for arg in "$@"; do
  if [ "$arg" = --fast ]; then
    lane=(-m 'not system' -n auto --dist loadfile)
  else
    args+=("$arg")
  fi
done
scripts/setup.sh
# shellcheck disable=SC1091
source scripts/env.sh
echo "test: ruff check"
ruff check .
echo "test: pytest${lane:+ (fast lane: ${lane[*]})}"
python -m pytest "${lane[@]}" "${args[@]}"
