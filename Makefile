# Two commands for a fresh machine:  `make demo`  and  `make test`  (each sets up .venv first).
PYTHON ?= python3
VENV ?= .venv
BIN = $(VENV)/bin

.PHONY: demo test lint bench clean

$(BIN)/deltoctl: pyproject.toml plugins/deltoctl-canopen/pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet -e '.[test]'
	$(BIN)/python -m pip install --quiet -e plugins/deltoctl-canopen
	@touch $@

demo: $(BIN)/deltoctl
	$(BIN)/deltoctl profile list
	DELTOCTL=$(BIN)/deltoctl examples/bringup.sh
	DELTOCTL=$(BIN)/deltoctl examples/bringup-bioscara.sh
	DELTOCTL=$(BIN)/deltoctl examples/bringup-mh5.sh
	DELTOCTL=$(BIN)/deltoctl examples/bringup-cell.sh

test: $(BIN)/deltoctl
	$(BIN)/ruff check deltoctl tests bench
	$(BIN)/lint-imports
	site=$$(mktemp -d) && NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict \
	    --site-dir "$$site"; status=$$?; rm -rf "$$site"; exit $$status
	$(BIN)/python -m pytest -q
	$(BIN)/ruff check plugins/deltoctl-canopen
	$(BIN)/python -m pytest -q plugins/deltoctl-canopen/tests

bench: $(BIN)/deltoctl
	$(BIN)/python bench/startup.py
	$(BIN)/deltoctl bench loop --foxglove
	$(BIN)/deltoctl bench dynamixel
	$(BIN)/deltoctl bench feetech
	$(BIN)/deltoctl bench i2c
	$(BIN)/python bench/fleet.py --stream

clean:
	rm -rf $(VENV) build dist *.egg-info
