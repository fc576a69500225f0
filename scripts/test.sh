#!/usr/bin/env bash
# Set up the workspace (idempotent) and run every check: ruff, then pytest (core, node and
# multi-process DDS tests). Extra arguments go to pytest, e.g. `scripts/test.sh tests/model -x`.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
# shellcheck disable=SC1091
source scripts/env.sh
echo "test: ruff check"
ruff check .
echo "test: pytest"
python -m pytest "$@"
