#!/usr/bin/env bash
# Benchmarks (`make bench`): prints figures and ratios against raw PyBullet taken in the same run.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
# shellcheck disable=SC1091
source "$ROOT/scripts/env.sh"
START="$(date +%s)"
python "$ROOT/bench/bench_sim.py"
python "$ROOT/bench/bench_recorder.py"
python "$ROOT/bench/bench_kinematics.py"
python "$ROOT/bench/bench_arm_ik.py"
python "$ROOT/bench/bench_youbot.py"
python "$ROOT/bench/bench_vision.py"
python "$ROOT/bench/bench_pipeline.py"
python "$ROOT/bench/bench_live_view.py"
python "$ROOT/bench/bench_requests.py"
# Joint speed limits in random cells and every example world (issue 48); the brake's cost.
python "$ROOT/bench/bench_joint_limits.py" --cells 12 --examples
# The closed loop's CPU against the open loop's last revision, side by side (issue 63).
python "$ROOT/bench/bench_closed_loop.py"
# What the youBot's laser scanner and its localization cost, with and without it (issue 63).
python "$ROOT/bench/bench_laser.py"
# The issue-12 goals, from the figures of this run only.
python "$ROOT/bench/goals.py" --since "$START"
