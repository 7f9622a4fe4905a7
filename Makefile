# The README's two commands: `make campaign` and `make test`.
# Everything lives in .venv, built from the system Python (>= 3.11); re-running is fast
# because installation is redone only when a package's setup.py/package.xml or the pins change.

PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
PACKAGES := rig_runtime multisine_gen pitch_actuator pressure_scanner wing_sim aero_identification aero_rig
PKG_FILES := $(foreach p,$(PACKAGES),src/$(p)/setup.py src/$(p)/package.xml)

.PHONY: test test-fast campaign lint format typecheck bench venv clean

venv: $(STAMP)

$(BIN)/python:
	@$(PYTHON) -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else 1)' || \
	  { echo "error: $(PYTHON) is older than 3.11; set PYTHON=python3.11 (or newer)"; exit 1; }
	@$(PYTHON) -m venv $(VENV) || { rm -rf $(VENV); \
	  echo "error: '$(PYTHON) -m venv' failed. On Debian/Ubuntu install the venv module:"; \
	  echo "       sudo apt install python3-venv   (or python3.11-venv for that interpreter)"; exit 1; }
	@test -x $(BIN)/pip || { rm -rf $(VENV); \
	  echo "error: the venv has no pip (ensurepip missing): sudo apt install python3-venv"; exit 1; }

$(STAMP): $(BIN)/python $(PKG_FILES) requirements-dev.txt constraints.txt
	$(BIN)/pip install --quiet --upgrade pip setuptools wheel
	$(BIN)/pip install --quiet -c constraints.txt -r requirements-dev.txt \
	  $(foreach p,$(PACKAGES),-e src/$(p))
	@touch $(STAMP)

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

format: $(STAMP)
	$(BIN)/ruff format .
	$(BIN)/ruff check --fix .

typecheck: $(STAMP)
	$(BIN)/mypy

# The full suite: lint, types, every test (graph tests and campaigns included).
test: lint typecheck
	$(BIN)/pytest

# Unit tests only (no node graph, no campaign, no build): under a minute.
test-fast: $(STAMP)
	$(BIN)/pytest -m "not slow"

campaign: $(STAMP)
	$(BIN)/aero-rig campaign --plan default $(CAMPAIGN_ARGS)

bench: $(STAMP)
	@for b in bench/*.py; do echo "== $$b"; $(BIN)/python $$b || exit 1; done

clean:
	rm -rf $(VENV) build install log .pytest_cache .ruff_cache
