# volec: the two commands a user needs are `make paper` and `make test`.
SHELL := /bin/bash
.SHELLFLAGS := -eu -o pipefail -c
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.volec-installed
QUICK ?= 0
NOTEBOOKS := $(sort $(wildcard notebooks/[0-9][0-9]_*.ipynb))
export VTK_DEFAULT_OPENGL_WINDOW ?= vtkEGLRenderWindow
export MPLBACKEND ?= Agg

.PHONY: setup test test-all lint paper paper-quick notebooks data retrain clean

setup: $(STAMP)

# Re-runs only when the lock or the package metadata change; a second `make setup` is a no-op.
$(STAMP): environment.lock pyproject.toml scripts/ensure_system_deps.sh
	@scripts/ensure_system_deps.sh
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	@# torch first, by its exact pin: this resolves to the CPU build (see ENVIRONMENT notes).
	$(PY) -m pip install -q "$$(grep -E '^torch==' environment.lock)"
	$(PY) -m pip install -q --no-deps -r environment.lock
	$(PY) -m pip install -q --no-deps --no-build-isolation -e .
	$(PY) -m pip check
	$(PY) -m ipykernel install --prefix $(VENV) --name volec --display-name "volec (.venv)" >/dev/null
	@touch $(STAMP)

test: setup
	$(PY) -m pytest -q -m "not slow" tests

test-all: setup
	$(PY) -m pytest -q tests

lint: setup
	$(VENV)/bin/ruff check .

# Every table and figure, from the ordered notebooks, headless. QUICK=1 for the CI-sized run.
# Each executed notebook is also exported to HTML, to browse the results without Jupyter.
paper: setup
	@mkdir -p build/notebooks figures
	@for nb in $(NOTEBOOKS); do \
	  echo "== $$nb"; \
	  $(VENV)/bin/papermill --log-level WARNING -k volec -p quick $(QUICK) \
	    "$$nb" "build/notebooks/$$(basename $$nb)" || exit 1; \
	  $(VENV)/bin/jupyter-nbconvert --log-level WARN --to html --embed-images \
	    --output-dir build/notebooks "build/notebooks/$$(basename $$nb)" || exit 1; \
	done
	@echo "figures and tables are in figures/; executed notebooks in build/notebooks/ (.ipynb, and .html to read in a browser)"

paper-quick:
	$(MAKE) paper QUICK=1

# The notebooks' reviewed sources are notebooks/NN_name.py (jupytext, percent format); this
# brings each paired .ipynb up to date with its .py (tests/test_notebooks.py checks they agree).
notebooks: setup
	$(VENV)/bin/jupytext --sync notebooks/[0-9][0-9]_*.py

# The 21-item synthetic benchmark captures (data/benchmark/ITEM/{capture,ground_truth}).
data: setup
	$(VENV)/bin/volec synth all --out data/benchmark

# Retrain the completion network (preset cpu_upright, about an hour on 2 cores) and replace the shipped
# checkpoint; the training data goes to data/completion-data. `make paper` only uses the checkpoint.
retrain: setup
	$(PY) -m volec.completion.train --preset cpu_upright --out volec/completion/weights/symmcompletion_cpu.pt

clean:
	rm -rf build .pytest_cache .ruff_cache
