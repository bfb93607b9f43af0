# Two commands for a newcomer: `make demo` and `make test`. Both bootstrap the venv first.
VENV ?= .venv
SHELL := /bin/bash
ACT := source $(VENV)/setup.bash &&
SCENARIO ?=
# pytest-xdist workers for `make test` (auto: one per core; 0: in this process)
PYTEST_WORKERS ?= auto
export ROS_AUTOMATIC_DISCOVERY_RANGE ?= LOCALHOST

.PHONY: venv demo test lint typecheck pytest benchmark clean

venv:
	@./.ci/bootstrap.sh $(VENV)

demo: venv
	@$(ACT) demo $(SCENARIO)

test: venv
	@$(MAKE) --no-print-directory lint typecheck pytest

lint:
	@$(ACT) echo '[lint] ruff' && ruff check lf_predictor_ros sim_ros test docs/scripts setup.py

typecheck:
	@$(ACT) echo '[typecheck] mypy' && mypy

pytest:
	@$(ACT) echo '[pytest]' && python -m pytest -n $(PYTEST_WORKERS) --dist loadfile $(PYTEST_ARGS)

benchmark: venv
	@$(ACT) benchmark $(BENCHMARK_ARGS)

clean:
	rm -rf build install log .pytest_cache .mypy_cache .ruff_cache *.egg-info
