# nearopt: `make run` sets everything up and plans the paper's example; `make test` sets everything
# up and runs the whole test suite. Both work from a clean clone on a machine with Python 3.11,
# make and apt (as root); everything else is installed here, into .venv/.

PYTHON   ?= python3
VENV     := .venv
BIN      := $(VENV)/bin
STAMP    := $(VENV)/.installed
CHROMIUM := /usr/bin/chromium

.PHONY: setup run test bench clean

setup: $(STAMP)

# A Debian python3 may lack venv/ensurepip: install python3-venv with apt when it does.
$(BIN)/python:
	@$(PYTHON) -c 'import sys; assert sys.version_info >= (3, 11), sys.version' || \
	  { echo "nearopt needs Python >= 3.11 as $(PYTHON)"; exit 1; }
	@$(PYTHON) -m venv $(VENV) 2>/dev/null || { \
	  rm -rf $(VENV); \
	  apt-get update -qq && apt-get install -y -qq python3-venv >/dev/null && \
	  $(PYTHON) -m venv $(VENV); }
	$(BIN)/python -m pip install -q --upgrade pip

$(STAMP): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install -q -e '.[test,bench,viz,batch]'
	@touch $(STAMP)

run: setup
	$(BIN)/python scripts/01_paper_example.py

# The browser test drives Debian's chromium (no browser download: there may be no internet).
$(CHROMIUM):
	apt-get update -qq && apt-get install -y -qq chromium >/dev/null

# the style checks first (seconds), then the suite
test: setup $(CHROMIUM)
	$(BIN)/ruff check nearopt tests scripts
	$(BIN)/ruff format --check nearopt tests scripts
	$(BIN)/python -m pytest -n auto

bench: setup
	$(BIN)/python scripts/bench_dynamics.py
	$(BIN)/python scripts/bench_timing.py
	$(BIN)/python scripts/bench_planner.py
	$(BIN)/python scripts/bench_cell.py

clean:
	rm -rf $(VENV) out .pytest_cache
