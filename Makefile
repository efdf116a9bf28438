# PBD-AG: `make demo` runs the service fed by a simulated robot; `make test` runs every check.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
BIN := $(VENV)/bin

.PHONY: setup demo serve test lint format openapi vendor bench eval results soak fuzz suite-figures clean

setup: $(VENV)/.installed

$(VENV)/.installed: pyproject.toml
	@bash scripts/system-deps.sh
	@$(PYTHON) -c 'import sys; sys.exit(0 if sys.version_info[:2] == (3, 11) else "PBD-AG needs Python 3.11")'
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[dev,eval,ingest]'
	@touch $@

demo: setup  ## the service on SQLite, fed live by the simulated robot
	$(BIN)/python -m sim.demo_service

serve: setup  ## the API with its in-process worker
	$(BIN)/pbdag serve

test: setup lint  ## lint, types, then the whole test suite (PostgreSQL tests when a server answers)
	$(BIN)/pytest

lint: setup
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/mypy

format: setup
	$(BIN)/ruff format .
	$(BIN)/ruff check --fix .

openapi: setup  ## regenerate api_schema/openapi.json from the app
	$(BIN)/pbdag openapi

vendor:  ## refetch the vendored Swagger UI assets from the npm registry (pinned, sha256 checked)
	bash scripts/vendor-assets.sh

bench: setup  ## the performance benchmarks (figures printed and written to bench/results/), then one table of every figure, its goal and its peer, from which the table of docs/benchmarks.md is rewritten
	$(BIN)/pip install --quiet -e '.[bench]'
	$(BIN)/python -m bench.bench_render
	$(BIN)/python -m bench.bench_decide
	$(BIN)/python -m bench.bench_fixture_step
	$(BIN)/python -m bench.bench_stream
	$(BIN)/python -m bench.bench_plan
	$(BIN)/python -m bench.bench_rollout
	$(BIN)/python -m bench.bench_store append --postgres postgresql+psycopg://postgres@127.0.0.1:5432/test
	$(BIN)/python -m bench.bench_store as-of --postgres postgresql+psycopg://postgres@127.0.0.1:5432/test
	$(BIN)/python -m bench.bench_store versus --postgres postgresql+psycopg://postgres@127.0.0.1:5432/test
	$(BIN)/python -m bench.bench_store raw
	$(BIN)/python -m bench.bench_blobs --postgres postgresql+psycopg://postgres@127.0.0.1:5432/test
	$(BIN)/python -m bench.bench_memory
	$(BIN)/python -m bench.bench_service --postgres postgresql+psycopg://postgres@127.0.0.1:5432/test --ramp 6,8,10,12
	$(BIN)/python -m bench.summary --write-docs

soak: setup  ## the long fault runs: 40 SIGKILLs, a PostgreSQL restart, a poison batch; blobs in PostgreSQL, then in a shared folder; SQLite (about 6 minutes)
	$(BIN)/python -m tests.e2e.fault_run --kills 40 --postgres-restart --poison
	$(BIN)/python -m tests.e2e.fault_run --kills 40 --poison --blob-backend folder
	$(BIN)/python -m tests.e2e.fault_run --kills 40 --sqlite

suite-figures: setup  ## run the suite once and rewrite its counts and duration in docs/install.md
	$(BIN)/python -m tests.suite_figures --write

fuzz: setup  ## schemathesis with 200 examples per operation (make test runs 15)
	PBDAG_FUZZ_EXAMPLES=200 $(BIN)/pytest tests/service/test_schemathesis.py

DEV := evaluation/results/dev
TEST := evaluation/results/test

eval: setup  ## the paper's protocols on the shipped (development) worlds, seeds 7 17 27; the ablation; the gate's miss causes on 6 generated development worlds
	$(BIN)/pbdag eval fixtures --jobs 2 --out $(DEV)/fixtures
	$(BIN)/pbdag eval dynamic --jobs 2 --out $(DEV)/dynamic
	$(BIN)/pbdag eval ablation --jobs 2 --out $(DEV)/ablation
	$(BIN)/pbdag eval active --jobs 2 --seeds 7 --out $(DEV)/active
	$(BIN)/pbdag eval active --jobs 2 --seeds 7 --orders pbdag --profile paper --out $(DEV)/active-paper
	$(BIN)/python -m evaluation.miss_causes --generated 6 --out $(DEV)/miss_causes

results: eval  ## and on the generated test split, then the README's tables (see evaluation/README.md for durations)
	$(BIN)/pbdag eval fixtures --generated 30 --split test --jobs 2 --out $(TEST)/fixtures
	$(BIN)/pbdag eval dynamic --generated 30 --split test --jobs 2 --out $(TEST)/dynamic
	$(BIN)/pbdag eval ablation --generated 30 --split test --jobs 2 --out $(TEST)/ablation
	$(BIN)/pbdag eval active --generated 20 --split test --jobs 2 --out $(TEST)/active
	$(BIN)/pbdag eval active --generated 20 --split test --jobs 2 --orders pbdag --profile paper --out $(TEST)/active-paper
	$(BIN)/python -m evaluation.sweep --jobs 2 --out $(DEV)/sweep
	$(BIN)/python -m evaluation.publish --dev $(DEV) --test $(TEST)

clean:
	rm -rf $(VENV) data bench/results evaluation/results .pytest_cache .mypy_cache .ruff_cache
