# wallcal: two commands on a fresh machine with Python 3.11+ and make
#   make demo   - runs the main job on the bundled example (results in out/campaign_a)
#   make test   - runs the whole test suite (installs the optional extras it exercises)
#   make mutate - mutation testing of the core modules (mutmut; slow, not part of `make test`; docs/testing.md)

comma  := ,
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
EXTRAS ?= dev,energyplus,analysis,cluster
STAMP  := $(VENV)/.installed-$(subst $(comma),-,$(EXTRAS))

.PHONY: demo test install lint bench mutate clean

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

# Core modules under mutation testing, one mutmut run each with its own test subset (tools/mutate.py: TESTS).
# Numba-jitted kernels are not mutated (mutmut skips decorated functions; see docs/testing.md).
MUTATE_MODULES ?= src/wallcal/wall.py src/wallcal/grid.py src/wallcal/metrics.py \
	src/wallcal/calibration/objective.py src/wallcal/standards/iso6946.py src/wallcal/standards/iso10456.py \
	src/wallcal/standards/iso13786.py src/wallcal/standards/iso9869.py src/wallcal/standards/insitu.py \
	src/wallcal/engines/operator.py

mutate:
	$(MAKE) install EXTRAS=$(EXTRAS),mutation
	$(BIN)/python tools/mutate.py $(MUTATE_MODULES)

bench: install
	$(BIN)/python bench/engine.py

clean:
	rm -rf $(VENV) out .pytest_cache .mutate
