# Every target bootstraps .venv from nothing but python3.11 and make, idempotently:
# the venv is rebuilt only when pyproject.toml changes.
PYTHON ?= python3.11
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: demo test check bench clean venv test-lowest

venv: $(STAMP)

$(STAMP): pyproject.toml
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[test,check,cluster]'
	@touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/fbs demo --out out

# The static checks first (seconds), then the suite: ruff's lint and its formatter (pyproject
# [tool.ruff]), mypy over every package (zero errors, every import resolved), and the import
# contracts of the one-way data flow (pyproject [tool.importlinter]).
check: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .
	$(VENV)/bin/mypy
	$(VENV)/bin/lint-imports

# One pytest worker per core and one more (pytest-xdist), a file to a worker (its module fixtures
# made once); the files of end-to-end runs first (tests/conftest.py). The extra worker fills what
# the others leave idle - console tests that wait on their pilot, runs polled from outside, the
# last files: on an idle 2-core box 3 workers took 16 min 9 s - 16 min 53 s (four fresh clones),
# 2 took 17 min 44 s - 18 min 50 s (cores busy 91 % against 82 %), 4 took 16 min 56 s.
# (--dist loadgroup would spread a file's tests, but xdist 3.8 cannot name groups under pytest 9:
# every test landed anywhere.)
# The sim rig runs in virtual time: a busy machine changes how long a test takes, not its verdict.
# The packages' bytecode is written first: where PYTHONDONTWRITEBYTECODE is set (these machines
# set it), each of the ~200 `fbs` processes the suite starts compiled the modules it imports
# from source again (all of them: 0.5-0.7 s of CPU). compileall writes only what is out of date.
TEST_WORKERS ?= $(shell echo $$(( $$(nproc 2>/dev/null || echo 1) + 1 )))
test: check
	$(PY) -m compileall -q drivers daq simhw procedures console fbs
	$(PY) -m pytest -q -n $(TEST_WORKERS) --dist loadfile --durations=25

# The suite with every runtime dependency at its lower bound in pyproject.toml (a fresh venv in a
# temporary copy of the work tree, .ci/lowest); 20-40 min, so not part of `make test` or CI.
test-lowest:
	bash .ci/lowest

bench: $(STAMP)
	$(PY) bench/run_all.py

clean:
	rm -rf $(VENV) out .pytest_cache .mypy_cache .ruff_cache .import_linter_cache
