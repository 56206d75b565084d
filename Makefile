# wallcal: two commands on a fresh machine with Python 3.11+ and make
#   make demo   - runs the main job on the bundled example (results in out/campaign_a)
#   make test   - runs the whole test suite (installs the optional extras it exercises)

comma  := ,
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
EXTRAS ?= dev,energyplus,analysis
STAMP  := $(VENV)/.installed-$(subst $(comma),-,$(EXTRAS))

.PHONY: demo test install lint bench clean

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[$(EXTRAS)]"
	touch $(STAMP)

install: $(STAMP)

demo: install
	$(BIN)/wallcal run src/wallcal/examples/campaign_a/study.toml --out out/campaign_a

test: install
	$(BIN)/python -m pytest -q

lint: install
	$(BIN)/ruff check src tests bench
	$(BIN)/ruff format --check src tests bench

bench: install
	$(BIN)/python bench/engine.py

clean:
	rm -rf $(VENV) out .pytest_cache
