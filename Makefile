# CloudSim: `make run` brings up the whole system on this machine, `make test` runs the suite.
VENV := .venv
BIN := $(VENV)/bin

.PHONY: install run test lint bench docs docs-serve clean

install:
	@bash deploy/install.sh

run: install
	$(BIN)/cloudsim up --demo

test: install
	$(BIN)/python -m pytest -n 2 --dist loadfile

lint: install
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/mypy cloudsim provisioners constellations templates migrations/__init__.py simulator/drcsim router/csrouter

bench: install
	$(BIN)/python -m bench.web
	$(BIN)/python -m bench.portal
	$(BIN)/python -m bench.provision
	$(BIN)/python -m bench.season
	$(BIN)/python -m bench.local_hosts
	$(BIN)/python -m bench.router
	$(BIN)/python -m bench.run_logs
	$(BIN)/python -m bench.supervision
	$(BIN)/python -m bench.metrics
	$(BIN)/python -m bench.federation
	$(BIN)/python -m bench.viewer
	$(BIN)/python -m bench.cli_start
	$(BIN)/python -m bench.verification
	$(BIN)/python -m bench.scaleout
	$(BIN)/python -m bench.mcap_log
	$(BIN)/drcsim bench

# The documentation site (mkdocs.yml): build it into site/, or serve it while editing.
docs: install
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict

docs-serve: install
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs serve --dev-addr 127.0.0.1:8000

clean:
	rm -rf $(VENV) site .pytest_cache .ruff_cache .mypy_cache
