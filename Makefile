# Two entry points, each does all the set-up it needs on a fresh machine:
#   make run   - create .venv, install, run the main job (paper reproduction + report)
#   make test  - create .venv, install, run the test suite, then the linters (make lint: ruff, mypy)
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: run test setup lint bench clean

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	# torch pinned to the CPU build that lies on this machine's disk (unpinned pulls a multi-GB CUDA build);
	# installed first, it satisfies torch>=2.8 of the train, torchrl and bench extras as is
	$(BIN)/python -m pip install --quiet torch==2.13.0
	# every extra (the base install is the maths core alone) and the dev tools; torch named again, or BenchMARL's
	# torchvision moves it to the newest release
	$(BIN)/python -m pip install --quiet -e ".[all,dev]" torch==2.13.0
	touch $(STAMP)

setup: $(STAMP)

run: $(STAMP)
	$(BIN)/formation-env report --out out

# the linters after the tests: a lint failure fails `make test` (and CI, .ci/run) without hiding the tests' results
test: $(STAMP)
	SDL_VIDEODRIVER=dummy $(BIN)/python -m pytest -q
	$(MAKE) --no-print-directory lint

lint: $(STAMP)
	$(BIN)/ruff check . && $(BIN)/ruff format --check . && $(BIN)/mypy

bench: $(STAMP)
	$(BIN)/formation-env bench --out .

clean:
	rm -rf $(VENV) out .pytest_cache .hypothesis
