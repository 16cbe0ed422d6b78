# robocell: `make demo` and `make test` are all a new machine needs.
# The first run creates a venv and installs the project (compiling core_cy's kernels) into it.

# The Python: PYTHON=... if given, else python3 when it is 3.11-3.13, else the newest of those found
# (.ci/find-pythons also looks in pyenv's versions). Each Python has its own venv: .venv for the
# default one, .venv-X.Y for another (VENV=... overrides).
DEFAULT_PYTHON := $(shell .ci/find-pythons --default)
PYTHON ?= $(DEFAULT_PYTHON)
version_of = $(shell $(1) -c 'import sys; print("%d.%d" % sys.version_info[:2])' 2>/dev/null)
PYTHON_VERSION := $(call version_of,$(PYTHON))
VENV ?= $(if $(filter $(call version_of,$(DEFAULT_PYTHON)),$(PYTHON_VERSION)),.venv,.venv-$(PYTHON_VERSION))
BIN := $(VENV)/bin
STAMP := $(VENV)/.robocell-installed

.PHONY: install python demo test bench bench-cell bench-scale bench-grasp bench-soak contract clean

# A bare `make`: the venv with robocell installed, nothing run.
install: $(STAMP)

# Says which Python it uses; refuses one that does not run or is too old, and a venv another made.
python:
	@if [ -z "$(PYTHON)" ]; then echo "make: no Python 3.11, 3.12 or 3.13 found (on PATH or in pyenv's" \
	    "versions): install one, or name it: make PYTHON=/path/to/python3.X" >&2; exit 1; fi
	@if [ -z "$(PYTHON_VERSION)" ]; then echo "make: $(PYTHON) does not run; Pythons found here:" \
	    $$(.ci/find-pythons | cut -d' ' -f2) >&2; exit 1; fi
	@$(PYTHON) -c 'import sys; sys.exit(sys.version_info < (3, 11) and "make: $(PYTHON) is Python $(PYTHON_VERSION): robocell needs 3.11 to 3.13")'
	@if [ -n "$(call version_of,$(BIN)/python)" ] && [ "$(call version_of,$(BIN)/python)" != $(PYTHON_VERSION) ]; then \
	    echo "make: $(VENV) holds Python $(call version_of,$(BIN)/python), not $(PYTHON_VERSION): remove it," \
	    "or name another: make VENV=.venv-$(PYTHON_VERSION)" >&2; exit 1; fi
	@echo "robocell: Python $(PYTHON_VERSION) ($(PYTHON)), venv $(VENV)"

$(BIN)/python: | python
	$(PYTHON) -m venv $(VENV) || { rm -rf $(VENV); echo "make: $(PYTHON) could not make a venv" \
	    "(on Debian or Ubuntu: apt install python$(PYTHON_VERSION)-venv)" >&2; exit 1; }
	$(BIN)/python -m pip install --quiet --upgrade pip

# Build tools go in first so that re-installs can skip pip's isolated build environment.
$(STAMP): $(BIN)/python pyproject.toml setup.py $(wildcard core_cy/*.pyx core_cy/*.pxd) | python
	$(BIN)/python -m pip install --quiet "setuptools>=77" wheel "cython>=3.0,<4" "numpy>=2.0,<3"
	$(BIN)/python -m pip install --quiet --no-build-isolation -e '.[test]'
	touch $@

# Two test files at a time (pyproject.toml says why); `pytest` alone runs one at a time.
test: $(STAMP)
	$(BIN)/python -m mypy
	$(BIN)/python -m pytest -n 2 --dist loadfile

demo: $(STAMP)
	$(BIN)/robocell demo

# The core on the red scenes and real photographs, then finding printed objects of any colour.
bench: $(STAMP)
	$(BIN)/python bench/bench_core.py
	$(BIN)/python bench/bench_segment.py
	$(BIN)/python bench/bench_segment_apart.py

bench-cell: $(STAMP)
	$(BIN)/python bench/bench_cell.py

bench-scale: $(STAMP)
	$(BIN)/python bench/bench_scale.py

bench-soak: $(STAMP)   # not in the test suite; --jobs 2000 for issue 23's target
	$(BIN)/python bench/bench_soak.py --retention

# Grasps planned on real reconstructions of simulated scenes, judged against the true objects.
bench-grasp: $(STAMP)
	$(BIN)/python bench/bench_grasp.py

# Scores `robocell reconstruct` on scans from a renderer written apart from ours.
contract: $(STAMP)
	$(BIN)/python ../shared/tools/contract_check.py $(BIN)/robocell

# Every Python's venv: they all use the kernels built in core_cy/.
clean:
	rm -rf .venv .venv-* $(VENV) build *.egg-info core_cy/*.so core_cy/_*_cy.c
