# The two commands: `make demo` runs the main job, `make test` runs the tests.
# Both create .venv and build ros_ws first when needed (scripts/setup.sh is idempotent).
.PHONY: setup demo test bench clean

setup:
	@bash scripts/setup.sh

demo: setup
	@bash scripts/demo.sh

test: setup
	@bash scripts/test.sh

bench: setup
	@bash scripts/bench.sh

clean:
	rm -rf .venv ros_ws/build ros_ws/install ros_ws/log
