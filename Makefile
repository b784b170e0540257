# The two commands: `make demo` runs the main job, `make test` runs the tests.
# Both create .venv and build ros_ws first when needed (scripts/setup.sh is idempotent).
.PHONY: setup demo demo-mini panel trials study check test bench container container-test clean

setup:
	@bash scripts/setup.sh

demo: setup
	@bash scripts/demo.sh

# The mini robot drives a square from the scripted teleop (the first source document).
demo-mini: setup
	@bash scripts/demo_mini_robot.sh

# Drive a robot from the browser (the report's control panel) and watch it in Foxglove, until
# Ctrl-C: make panel, or make panel WORLD=youbot.
panel: setup
	@bash scripts/panel.sh

# The paper's Table 2 over many seeded trials: make trials TRIALS=100 PARALLEL=2; on a Ray
# cluster: make trials TRIALS=110 RAY=auto (docs/pipeline.md: "A campaign on a Ray cluster").
# TIME_STEP=0.008333333333333333 takes 1/120 s physics steps (docs/benchmarks.md).
# WORLD=cell_four_classes (a world of world_description/worlds) or WORLD=path/to/cell.yaml runs
# a campaign on another cell (docs/writing-a-cell.md).
trials: setup
	@bash -c 'source scripts/env.sh && w="$${WORLD:-}" && \
	  case "$$w" in ""|*/*|*.yaml) ;; *) w="package://world_description/worlds/$$w.yaml" ;; esac && \
	  run_trials --trials $${TRIALS:-10} $${w:+--world "$$w"} \
	  $${PARALLEL:+--parallel $$PARALLEL} $${RAY:+--ray $$RAY} \
	  $${TIME_STEP:+--time-step $$TIME_STEP}'

# A what-if study: the paper's cell with perturbations on, its belt speed swept
# (docs/studies.md): make study [SWEEP=name=START:STOP:STEP] [SWEEP2=...] [TRIALS_PER_POINT=4];
# or a study file: make study STUDY=package://studies/study_files/belt_speed.yaml [RESUME=DIR].
study: setup
	@bash scripts/study.sh

# Before each commit: lint, types and the fast unit tests (under 3 minutes).
check: setup
	@bash scripts/check.sh

# The whole suite (CI's command).
test: setup
	@bash scripts/test.sh

bench: setup
	@bash scripts/bench.sh

# The container image (docker/Dockerfile, docs/docker.md) with podman or docker:
# make container [BASE=ubuntu:24.04] [CA_CERT=corp-ca.pem] [CONTAINER_ENGINE=docker];
# make container-test also runs the demo in it and checks it prints what `make demo` does here.
container:
	@bash docker/build.sh

container-test:
	@bash docker/test.sh

clean:
	rm -rf .venv ros_ws/build ros_ws/install ros_ws/log
