# Two commands set everything up on a fresh machine: `make demo` and `make test`.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
TEST_STAMP := $(VENV)/.installed-test

.PHONY: demo test test-slow lint bench clean

$(BIN)/python:
	$(PY) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(STAMP): pyproject.toml | $(BIN)/python
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
