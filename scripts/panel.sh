#!/usr/bin/env bash
# Drive a robot from the browser: the simulator in real time, the control panel (the mini
# robot report's buttons and slider as a web page) and the Foxglove live bridge, until Ctrl-C.
#   make panel                      the mini robot
#   make panel WORLD=youbot         the youBot (strafe buttons appear: a Mecanum base)
#   PANEL_PORT=8080 LIVE_PORT=8765  the ports (0: any free one)
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
# shellcheck disable=SC1091
source "$ROOT/scripts/env.sh"

export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$((RANDOM % 40 + 160))}"   # (demos: 160-199)
WORLD="${WORLD:-mini_robot}"
RUN_DIR="${DEMO_RUNS_DIR:-$ROOT/runs}/panel-$(date +%Y%m%d-%H%M%S)-$$"
mkdir -p "$RUN_DIR"
# shellcheck disable=SC1091
source "$ROOT/scripts/live_view.sh"
trap stop_demo EXIT

echo "[panel] world $WORLD, DDS domain $ROS_DOMAIN_ID, logs in ${RUN_DIR#"$ROOT"/}"
sim_node --ros-args -p world:="package://world_description/worlds/$WORLD.yaml" \
  > "$RUN_DIR/sim_node.log" 2>&1 &
DEMO_PIDS+=($!)
control_panel --ros-args -p port:="${PANEL_PORT:-8080}" > "$RUN_DIR/control_panel.log" 2>&1 &
DEMO_PIDS+=($!)
LIVE_VIEW_TAG=panel DEMO_LIVE_VIEW_PORT="${LIVE_PORT:-8765}" start_live_view "$RUN_DIR/live_view.log"
url=""
for _ in $(seq 100); do
  url="$(sed -n 's/.*serving the control panel on \(http:[^;]*\);.*/\1/p' \
    "$RUN_DIR/control_panel.log" | head -1)"
  [ -n "$url" ] && break
  sleep 0.1
done
if [ -z "$url" ]; then
  echo "[panel] the control panel did not start:"; tail -5 "$RUN_DIR/control_panel.log"; exit 1
fi
echo "[panel] control panel: open $url in a browser (hold a button or key to drive; Ctrl-C here to stop)"
wait "${DEMO_PIDS[0]}"
