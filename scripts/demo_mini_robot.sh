#!/usr/bin/env bash
# The main job: the simulator and a scripted teleop, headless. The mini robot drives a 0.5 m
# square; drive_check prints the final odometry pose against the pose that the kinematics
# predicts for the commands as the simulator applied them, and the exit code says whether they
# agree.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
# shellcheck disable=SC1091
source "$ROOT/scripts/env.sh"

export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$((RANDOM % 40 + 160))}"   # (demos: 160-199)
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
RTF="${DEMO_REAL_TIME_FACTOR:-1.0}"
SIDE_S="${DEMO_SIDE_SECONDS:-5}"           # 5 s at 0.1 m/s: 0.5 m sides
# The report's buttons: forward at half of max_speed, turns at full max_turn (0.2 rad/s).
LEG="speed 0.5, forward ${SIDE_S}s, speed 1.0, left 7.854s"
SCRIPT="$LEG, $LEG, $LEG, $LEG, stop"

RUN_DIR="${DEMO_RUNS_DIR:-$ROOT/runs}/demo-$(date +%Y%m%d-%H%M%S)-$$"
mkdir -p "$RUN_DIR"
echo "[demo] ROS_DOMAIN_ID=$ROS_DOMAIN_ID, real-time factor $RTF, logs in ${RUN_DIR#"$ROOT"/}"
echo "[demo] teleop script: $SCRIPT"

# shellcheck disable=SC1091
source "$ROOT/scripts/live_view.sh"
trap stop_demo EXIT

sim_node --ros-args -p real_time_factor:="$RTF" -p rtf_log_period:=10.0 \
  > "$RUN_DIR/sim_node.log" 2>&1 &
DEMO_PIDS+=($!)
start_live_view "$RUN_DIR/live_view.log"
# Every run is recorded (DEMO_RECORD=0 turns it off): all topics, MCAP, into the run directory.
if [ "${DEMO_RECORD:-1}" != 0 ]; then
  recorder --ros-args -p output_dir:="$RUN_DIR" -p bag_name:=bag > "$RUN_DIR/recorder.log" 2>&1 &
  recorder_pid=$!
  DEMO_PIDS+=("$recorder_pid")
  for _ in $(seq 100); do  # wait until it records the simulator's topics
    grep -q "recording /mini_robot/odom" "$RUN_DIR/recorder.log" && break
    sleep 0.1
  done
fi
drive_check --ros-args -p use_sim_time:=true -p wall_timeout:=600.0 -p script:="$SCRIPT" \
  -r cmd_vel:=/mini_robot/cmd_vel -r odom:=/mini_robot/odom -r cmd_vel_out:=/mini_robot/cmd_vel_out \
  2>&1 | tee "$RUN_DIR/drive_check.log" &
check_pid=$!
DEMO_PIDS+=("$check_pid")
teleop --ros-args -p use_sim_time:=true -p script:="$SCRIPT" -p wait_for_subscriber:=30.0 \
  -p publish_rate:=50.0 \
  -r __ns:=/mini_robot 2>&1 | tee "$RUN_DIR/teleop.log"

set +e
wait "$check_pid"
code=$?
set -e
grep -h "real-time factor" "$RUN_DIR/sim_node.log" | tail -1 | sed 's/^/[demo] sim: /' || true
if [ -n "${recorder_pid:-}" ]; then
  kill -INT "$recorder_pid" && wait "$recorder_pid" || true
  sed -n 's/^\[recorder\] /[demo] /p' "$RUN_DIR/recorder.log"
  if bag_analysis "$RUN_DIR/bag" -o "$RUN_DIR/report" > "$RUN_DIR/analysis.log" 2>&1; then
    echo "[demo] bag report: ${RUN_DIR#"$ROOT"/}/report/report.md (odometry path: paths.png)"
  else
    echo "[demo] bag analysis failed:"; cat "$RUN_DIR/analysis.log"
  fi
fi
if [ "$code" -eq 0 ]; then echo "[demo] PASS"; else echo "[demo] FAIL (exit $code)"; fi
exit "$code"
