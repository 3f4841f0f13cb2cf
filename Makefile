# `make demo` and `make test` create .venv when missing and install fourd with what it needs.
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-stamp

.PHONY: demo test bench bench-quick lint clean

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e ".[dev,usd,abc,fast,uv]"
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/fourd demo

test: $(STAMP)
	$(PY) -m pytest -q --durations=25

# Both write into benchmarks/out/ (git-ignored); the tracked record is rewritten only on
# purpose: fourd bench -o benchmarks/BENCHMARKS.md
bench: $(STAMP)
	$(VENV)/bin/fourd bench

bench-quick: $(STAMP)
	$(VENV)/bin/fourd bench --quick

lint: $(STAMP)
	$(VENV)/bin/ruff check src tests benchmarks experiments

clean:
	rm -rf demo-out benchmarks/out .pytest_cache
