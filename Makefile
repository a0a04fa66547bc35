# Two entry points from nothing: `make demo` and `make test`. Both create .venv and install
# the package with the exact pins of constraints.txt (torch 2.13.0, the CPU build).
PY ?= python3
VENV ?= .venv
BIN := $(VENV)/bin

.PHONY: install demo test bench clean

$(BIN)/python:
	$(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip

# warmup compiles the numba CPU kernels into numba's cache (once per install, 20-25 s of CPU; a second run only
# loads them), so that the first forward of `make demo`, `make test` or a user's script does not wait for it
install: $(BIN)/python
	$(BIN)/pip install -q -c constraints.txt -e ".[test]"
	$(BIN)/torch-depth-sr warmup

demo: install
	$(BIN)/torch-depth-sr demo --out out/demo --json out/demo/demo.json

test: install
	$(BIN)/python -m pytest -q

clean:
	rm -rf $(VENV) out build *.egg-info
