#!/usr/bin/env bash
# The check before each commit (`make check`): lint, types and the fast unit tests, in under
# 3 minutes here. `make test` (scripts/test.sh) runs the whole suite, as CI does.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$ROOT/scripts/setup.sh"
# shellcheck disable=SC1091
source "$ROOT/scripts/env.sh"
cd "$ROOT"
start=$SECONDS
python -m pytest -p no:cacheprovider -m 'unit and not slow' "$@"
echo "make check: passed in $((SECONDS - start)) s (make test runs the whole suite)"
