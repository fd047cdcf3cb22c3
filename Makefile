# Two commands for a fresh machine: `make demo` and `make test`. Both create .venv and install cotwin.
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-stamp
OUT ?= out/demo

.PHONY: install demo test bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	touch $(STAMP)

install: $(STAMP)

demo: install
	$(VENV)/bin/cotwin check examples/ur5e
	$(VENV)/bin/cotwin verify examples/ur5e/arm.rst
	$(VENV)/bin/cotwin build examples/ur5e/cotwin.toml -o $(OUT)
	$(VENV)/bin/cotwin run examples/ur5e/cotwin.toml -o $(OUT)
	$(VENV)/bin/cotwin run examples/ur5e/cotwin.toml -o $(OUT)/gauss-seidel --algorithm gauss-seidel
	$(VENV)/bin/cotwin run examples/ur5e/pick_place_project.toml -o $(OUT)/pick-place
	@echo "results: $(OUT)/outputs.csv, $(OUT)/figure.png, $(OUT)/gauss-seidel/, $(OUT)/pick-place/ (multimodel: $(OUT)/multimodel.json)"

test: install
	$(PY) -m pytest -q

bench: install
	$(PY) benchmarks/run.py

clean:
	rm -rf $(VENV) out build dist src/*.egg-info .pytest_cache .hypothesis
