#!/usr/bin/env bash
# The main job: the pipeline paper's whole run, headless. Starts the simulator (lock-step),
# the vision node, the two kinematics nodes and the coordinator as one process group, records
# the run to a bag, runs the paper's scenario once and prints its results table beside the
# paper's Table 2. Exit 0 when every material reached its destination.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
# shellcheck disable=SC1091
source "$ROOT/scripts/env.sh"

export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
DOMAIN="${ROS_DOMAIN_ID:-$((RANDOM % 40 + 160))}"   # (demos: 160-199, see tests/conftest.py)
SEED="${DEMO_SCENARIO_SEED:-0}"           # the world file's scenario
BELT="${DEMO_BELT_SPEED:-0.12}"
RUN_DIR="${DEMO_RUNS_DIR:-$ROOT/runs}/pipeline-$(date +%Y%m%d-%H%M%S)-$$"
RECORD=()
if [ "${DEMO_RECORD:-1}" != 0 ]; then RECORD=(--record); fi

echo "[demo] the pipeline run (scenario seed $SEED, belt $BELT m/s, DDS domain $DOMAIN);"
echo "[demo] sim_node + vision_node + 2 kinematics_nodes + coordinator_node, lock-step"
# A live window onto the run (scripts/live_view.sh): the Foxglove bridge on the trial's domain.
# shellcheck disable=SC1091
source "$ROOT/scripts/live_view.sh"
mkdir -p "$RUN_DIR"
trap stop_live_view EXIT
ROS_DOMAIN_ID="$DOMAIN" start_live_view "$RUN_DIR/live_view.log" \
  "live_view/layouts/pipeline_cell.json"
# SIGTERM (`docker stop`, a process manager) goes to the whole process group: run_trials winds
# the trial up and writes its report; this script waits for it (a trap, not death) and reports.
trap 'echo "[demo] SIGTERM: the trial runner wound the run up"' TERM
set +e
run_trials --seeds "$SEED" --belt-speed "$BELT" "$BELT" --domain-base "$DOMAIN" \
  "${RECORD[@]}" --out "$RUN_DIR"
code=$?
set -e
stop_live_view
echo
if [ -f "$RUN_DIR/report.md" ]; then
  sed -n '/^| /p' "$RUN_DIR/report.md"
  echo
  grep -h "^\- trial\|^Peak joint speed" "$RUN_DIR/report.md" || true
else
  echo "[demo] no report: the trial did not finish"
fi
echo "[demo] events and logs: ${RUN_DIR#"$ROOT"/}/trial_000/ (result.json, *.log$(
  [ "${DEMO_RECORD:-1}" != 0 ] && echo ', bag/'))"
[ -f "$RUN_DIR/report.md" ] && echo "[demo] report: ${RUN_DIR#"$ROOT"/}/report.md (plots: completion_times.png, success_rates.png, youbot_paths.png, timeline.png, storyboard.png)"
case "$code" in
  0) echo "[demo] PASS" ;;
  130) echo "[demo] STOPPED (exit 130): the trial was stopped before it finished" ;;
  *) echo "[demo] FAIL (exit $code)" ;;
esac
exit "$code"
