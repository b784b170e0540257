#!/usr/bin/env bash
# The test command (`make test`): unit, node, graph, ament-layout and demo tests.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$ROOT/scripts/setup.sh"
# shellcheck disable=SC1091
source "$ROOT/scripts/env.sh"
cd "$ROOT"
exec python -m pytest -p no:cacheprovider "$@"
