#!/usr/bin/env bash
# make study: a what-if study (docs/studies.md). The paper's cell with realistic perturbations
# on (pipeline_cell_perturbed.yaml), its belt speed swept from 0.05 to 0.35 m/s, 4 trials at
# each point, 2 at a time; the report names where the cell starts to fail and plots each rate
# and the completion time against the belt speed.
#   SWEEP="belt_speed=0.05:0.35:0.05"   (a second SWEEP2=... makes a grid)
#   TRIALS_PER_POINT=4  PARALLEL=2  WORLD=package://...  BREAK_BELOW=0.9  OUT=runs/study-...
# STUDY=FILE runs a study file instead (a search under a constraint, or a screening: e.g.
# STUDY=package://studies/study_files/belt_speed.yaml); RESUME=DIR goes on with a stopped study
# or sweep (STUDY= may be left out: the directory's own study file is taken).
# Exit 0 when the study ran (whether or not the cell failed at some points: that is what a
# study looks for), 2 on a bad option, 130 when stopped (run_trials --resume OUT goes on).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
# shellcheck disable=SC1091
source "$ROOT/scripts/env.sh"
OUT="${OUT:-$ROOT/runs/study-$(date +%Y%m%d-%H%M%S)}"
if [ -n "${RESUME:-}" ] && [ -z "${STUDY:-}" ]; then
  # (RESUME alone goes on with what the directory holds: a study with its own study file, a
  # sweep with its own plan; run_trials refuses anything else in one line.)
  if [ -e "$RESUME/study.json" ]; then
    exec run_trials --study "$RESUME/study.yaml" --resume "$RESUME" --parallel "${PARALLEL:-2}"
  fi
  exec run_trials --resume "$RESUME" --parallel "${PARALLEL:-2}"
fi
if [ -n "${STUDY:-}" ]; then
  if [ -n "${RESUME:-}" ]; then
    exec run_trials --study "$STUDY" --resume "$RESUME" --parallel "${PARALLEL:-2}"
  fi
  exec run_trials --study "$STUDY" --out "$OUT" --parallel "${PARALLEL:-2}"
fi
set +e
run_trials --world "${WORLD:-package://world_description/worlds/pipeline_cell_perturbed.yaml}" \
  --sweep "${SWEEP:-belt_speed=0.05:0.35:0.05}" ${SWEEP2:+--sweep "$SWEEP2"} \
  --trials-per-point "${TRIALS_PER_POINT:-4}" --parallel "${PARALLEL:-2}" \
  --break-below "${BREAK_BELOW:-0.9}" --out "$OUT"
code=$?
set -e
case "$code" in
  0|1) sed -n '/^## The sweep/,/^!\[rates/p' "$OUT/report.md"
       echo "[study] report: $OUT/report.md (sweep_rates.png, sweep_times.png)"
       exit 0 ;;
  *) exit "$code" ;;
esac
