# Two commands set everything up on a fresh machine: `make demo` and `make test`.
# Python 3.11 where it is installed under that name (the version the project is developed
# and tested on), else python3 (3.10 or newer); `make PY=python3.12 demo` picks another.
PY ?= $(shell command -v python3.11 2>/dev/null || echo python3)
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
TEST_STAMP := $(VENV)/.installed-test

.PHONY: demo test test-slow lint bench clean

# (a failed creation, e.g. a Debian Python without python3-venv, leaves no half venv behind
# that later runs would take as made)
$(BIN)/python:
	$(PY) -m venv $(VENV) || { rm -rf $(VENV); exit 1; }
	$(BIN)/python -m pip install --quiet --upgrade pip || { rm -rf $(VENV); exit 1; }

$(STAMP): pyproject.toml | $(BIN)/python
	@$(BIN)/python -c 'import sys; sys.exit(sys.version_info < (3, 10))' || { echo \
	  "$(VENV) was made with `$(BIN)/python -V 2>&1`; facetlift needs 3.10 or newer:" \
	  "run 'make clean', then 'make PY=python3.11 demo' (or another Python >= 3.10)"; exit 1; }
	$(BIN)/python -m pip install --quiet --only-binary=:all: -e .
	touch $@

$(TEST_STAMP): pyproject.toml $(STAMP)
	$(BIN)/python -m pip install --quiet --only-binary=:all: -e '.[test]'
	touch $@

demo: $(STAMP)
	$(BIN)/python examples/demo.py --out demo_output

test: $(TEST_STAMP)
	$(BIN)/python -m pytest -q -n 2 --dist loadfile

test-slow: $(TEST_STAMP)  # tests marked slow: >= 10,000 property examples, the CLI campaign beyond the default sixth
	$(BIN)/python -m pytest -q -m slow || [ $$? -eq 5 ]

lint: $(TEST_STAMP)
	$(BIN)/ruff check src tests benchmarks examples

bench: $(STAMP)
	$(BIN)/python benchmarks/bench_dgp.py

clean:
	rm -rf $(VENV) demo_output build *.egg-info src/*.egg-info
