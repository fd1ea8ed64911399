# CloudSim: `make run` brings up the whole system on this machine, `make test` runs the suite.
VENV := .venv
BIN := $(VENV)/bin

.PHONY: install run test lint bench clean

install:
	@bash deploy/install.sh

run: install
	$(BIN)/cloudsim up --demo

test: install
	$(BIN)/python -m pytest

lint: install
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/mypy cloudsim provisioners constellations templates migrations/__init__.py simulator/drcsim router/csrouter

bench: install
	$(BIN)/python bench/web.py
	$(BIN)/python bench/provision.py
	$(BIN)/python bench/local_hosts.py
	$(BIN)/python bench/router.py
	$(BIN)/python bench/run_logs.py
	$(BIN)/python bench/viewer.py
	$(BIN)/drcsim bench

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache .mypy_cache
