# sphere_twin: two commands for a newcomer, `make demo` and `make test`.
# Every target runs with DDS discovery limited to this machine.
export ROS_AUTOMATIC_DISCOVERY_RANGE ?= LOCALHOST

PYTHON  ?= python3
VENV    := .venv
BIN     := $(VENV)/bin
STAMP   := $(VENV)/.installed
PYTEST_ARGS ?=
# The rung of the ladder of models the demo's simulator serves kicks from (full, sliding,
# table: docs/numerics.md); empty for the live default. `make demo FIDELITY=sliding`.
FIDELITY ?=

.PHONY: setup demo test lint typecheck bench clean clean-cache

# The physics (numba's machine code, cached once per install location) is compiled after the
# install, so that neither a node's first start nor `make demo` waits a minute for it; `setup`
# checks again each time (a second, unless a kernel changed or `make clean-cache` ran).
setup: $(STAMP)
	@$(BIN)/sphere-twin compile

# Reinstall only when a pin or the package metadata changed.
$(STAMP): requirements.txt requirements-dev.txt constraints.txt setup.py setup.cfg package.xml
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --disable-pip-version-check \
		-r requirements-dev.txt -c constraints.txt
	$(BIN)/python -m pip install --quiet --disable-pip-version-check --no-deps --no-build-isolation --use-pep517 -e .
	$(BIN)/sphere-twin compile
	@touch $(STAMP)
	@echo "setup: .venv ready"

demo: $(STAMP)
	$(BIN)/sphere-twin demo $(if $(FIDELITY),--fidelity $(FIDELITY))

lint: $(STAMP)
	$(BIN)/ruff check .

# The public API's types (mypy.ini): every function of the four packages is annotated.
typecheck: $(STAMP)
	$(BIN)/mypy

# Two passes: the physics, numerics and control tests on two workers (each file on one, so a
# module's fixture is built once); then, alone on the machine, the node tests, which measure gaps
# and timeouts in wall time (but those marked `load_tolerant`, which run in the first). A pass
# that selects nothing (status 5) is not a failure.
test: lint typecheck
	@parallel=0; serial=0; \
	$(BIN)/python -m pytest -m 'not ros or load_tolerant' -n 2 --dist loadfile $(PYTEST_ARGS) \
		|| [ $$? -eq 5 ] || parallel=1; \
	$(BIN)/python -m pytest -m 'ros and not load_tolerant' $(PYTEST_ARGS) \
		|| [ $$? -eq 5 ] || serial=1; \
	if [ $$parallel -ne 0 ]; then \
		echo 'make test: the two-worker pass failed (its summary is above the node tests)'; fi; \
	exit $$((parallel + serial))

bench: $(STAMP)
	$(BIN)/sphere-twin bench work-precision --quick

# numba's on-disk cache (__pycache__/*.nbi, *.nbc) is keyed on each function's own source file:
# a kernel that calls into an edited module keeps its old machine code until this runs.
clean-cache:
	find . -path ./$(VENV) -prune -o \( -name '*.nbi' -o -name '*.nbc' \) -print | xargs rm -f

clean: clean-cache
	rm -rf $(VENV) build install log .pytest_cache .ruff_cache .mypy_cache
