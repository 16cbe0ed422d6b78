# robocell: `make demo` and `make test` are all a new machine needs.
# The first run creates .venv and installs the project (compiling core_cy's kernels) into it.

PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.robocell-installed

.PHONY: install demo test bench bench-cell bench-scale contract clean

# A bare `make`: the venv with robocell installed, nothing run.
install: $(STAMP)

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

# Build tools go in first so that re-installs can skip pip's isolated build environment.
$(STAMP): $(BIN)/python pyproject.toml setup.py $(wildcard core_cy/*.pyx)
	$(BIN)/python -m pip install --quiet "setuptools>=77" wheel "cython>=3.0,<4" "numpy>=2.0,<3"
	$(BIN)/python -m pip install --quiet --no-build-isolation -e '.[test]'
	touch $@

test: $(STAMP)
	$(BIN)/python -m pytest

demo: $(STAMP)
	$(BIN)/robocell demo

bench: $(STAMP)
	$(BIN)/python bench/bench_core.py

bench-cell: $(STAMP)
	$(BIN)/python bench/bench_cell.py

bench-scale: $(STAMP)
	$(BIN)/python bench/bench_scale.py

# Scores `robocell reconstruct` on scans from a renderer written apart from ours.
contract: $(STAMP)
	$(BIN)/python ../shared/tools/contract_check.py $(BIN)/robocell

clean:
	rm -rf $(VENV) build *.egg-info core_cy/*.so core_cy/_*_cy.c
