#!/usr/bin/env bash
# make container-test: build the image (docker/build.sh), run its default command (make demo)
# in a container, run `make demo` here, and compare the two: the printed results table and the
# trial's result (every figure, event and final position; the run's metadata left out). The
# demo is a lock-step run of a fixed seed, so both must be the same. Exit 0 when they are.
# KEEP=1 keeps the work folder (both runs' reports, results, logs and bags).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
# shellcheck source=docker/engine.sh
source "$ROOT/docker/engine.sh"
log() { printf '[container-test] %s\n' "$*"; }

work="$(mktemp -d /tmp/robot-sim-container-test.XXXXXX)"
name="robot-sim-test-$$"
cleanup() {
  "$ENGINE" rm -f "$name" >/dev/null 2>&1 || true
  if [ "${KEEP:-0}" = 1 ]; then log "kept $work"; else rm -rf "$work"; fi
}
trap cleanup EXIT

start=$SECONDS
bash "$ROOT/docker/build.sh"
built=$((SECONDS - start))

log "the image's default command (make demo) in a container"
start=$SECONDS
set +e
"$ENGINE" run --name "$name" "${LIMITS[@]}" "$IMAGE" > "$work/container.log" 2>&1
container_code=$?
set -e
container_time=$((SECONDS - start))
"$ENGINE" cp "$name:/opt/robot_sim/runs" "$work/container"
sed 's/^/  | /' "$work/container.log" | tail -25

log "make demo on this host"
bash "$ROOT/scripts/setup.sh" > /dev/null
start=$SECONDS
set +e
DEMO_RUNS_DIR="$work/host" DEMO_LIVE_VIEW=0 bash "$ROOT/scripts/demo.sh" > "$work/host.log" 2>&1
host_code=$?
set -e
host_time=$((SECONDS - start))

failed=0
[ "$container_code" = 0 ] || { log "FAIL: the container's demo ended with exit $container_code"; failed=1; }
[ "$host_code" = 0 ] || { log "FAIL: the host's demo ended with exit $host_code (see $work/host.log)"; failed=1; }
if ! diff <(grep '^| ' "$work/container.log") <(grep '^| ' "$work/host.log") > "$work/table.diff"; then
  log "FAIL: the printed results differ:"; cat "$work/table.diff"; failed=1
fi
# shellcheck disable=SC1091
source "$ROOT/scripts/env.sh"
python - "$work/container" "$work/host" <<'PY' || failed=1
import sys
from pathlib import Path

from trial_record.result import read_result

runs = []
for folder in sys.argv[1:]:
    found = sorted(Path(folder).glob('*/trial_000/result.json'))
    result, problem = read_result(found[-1]) if found else (None, 'no result.json')
    if result is None:
        sys.exit(f'[container-test] FAIL: {folder}: {problem}')
    runs.append(result)
container, host = runs
differ = container.differences(host)
if differ:
    sys.exit('[container-test] FAIL: the two runs differ in ' + ', '.join(differ))
print(f'[container-test] the same run: {container.status}, {container.completion_time:.1f} s '
      f'simulated, {container.delivered}/{container.total} delivered, '
      f'{len(container.events)} events, code {container.run.code} (image) / {host.run.code} (host)')
PY
size="$("$ENGINE" image inspect --format '{{.Size}}' "$IMAGE" | awk '{printf "%.2f GB", $1/1e9}')"
log "image $IMAGE: $size, built in $built s; demo: $container_time s in the container, $host_time s here"
if [ "$failed" = 0 ]; then log "PASS"; else KEEP=1; log "FAIL"; fi
exit "$failed"
