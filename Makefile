# Two entry points from nothing: `make demo` and `make test`. Both create .venv and install
# the package with the exact pins of constraints.txt (torch 2.13.0, the CPU build).
PY ?= python3
VENV ?= .venv
BIN := $(VENV)/bin

.PHONY: install demo test bench clean

$(BIN)/python:
	$(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip

install: $(BIN)/python
	$(BIN)/pip install -q -c constraints.txt -e ".[test]"

demo: install
	$(BIN)/torch-depth-sr demo --out out/demo --json out/demo/demo.json

test: install
	$(BIN)/python -m pytest -q

clean:
	rm -rf $(VENV) out build *.egg-info
