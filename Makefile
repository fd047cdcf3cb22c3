# Two commands for a fresh machine: `make demo` and `make test`. Both create .venv and install cotwin:
# the demo with its runtime extras only (`.[sim]`: MuJoCo, pythonfmu, pika, asyncua, SQLAlchemy...),
# the tests with the test extras added (`.[test]`: Ray, Playwright, pytest, libcosimpy...).
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
RUNTIME := $(VENV)/.runtime-stamp
STAMP := $(VENV)/.installed-stamp
OUT ?= out/demo

.PHONY: install install-runtime demo test bench clean

$(RUNTIME): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[sim]'
	touch $(RUNTIME)

$(STAMP): $(RUNTIME)
	$(PY) -m pip install --quiet -e '.[test]'
	touch $(STAMP)

install-runtime: $(RUNTIME)

install: $(STAMP)

demo: install-runtime
	$(VENV)/bin/cotwin check examples/ur5e
	$(VENV)/bin/cotwin verify examples/ur5e/arm.rst
	$(VENV)/bin/cotwin build examples/ur5e/cotwin.toml -o $(OUT)
	$(VENV)/bin/cotwin run examples/ur5e/cotwin.toml -o $(OUT)
	$(VENV)/bin/cotwin run examples/ur5e/cotwin.toml -o $(OUT)/gauss-seidel --algorithm gauss-seidel
	$(VENV)/bin/cotwin run examples/ur5e/pick_place_project.toml -o $(OUT)/pick-place
	$(VENV)/bin/cotwin testgen examples/ur5e/arm.rst examples/ur5e/mapping.pm examples/ur5e/ur5e.pm -o $(OUT)/tests && $(VENV)/bin/cotwin test examples/ur5e/cotwin.toml $(OUT)/tests --junit $(OUT)/tests/report.xml
	COTWIN=$(VENV)/bin/cotwin scripts/live-demo.sh $(OUT)/twin
	@if [ -f ../shared/data/ur5e/rtde_run1.csv ]; then \
		$(VENV)/bin/cotwin twin examples/ur5e/replay.toml -o $(OUT)/replay 2> $(OUT)/replay.log; \
	else echo "replay of the real UR5e's log skipped: ../shared/data/ur5e/rtde_run1.csv is not here"; fi
	$(VENV)/bin/cotwin run examples/ur3e/cotwin.toml -o $(OUT)/ur3e
	$(VENV)/bin/cotwin run examples/flexcell2/cotwin.toml -o $(OUT)/flexcell2
	$(VENV)/bin/cotwin run examples/flexcell2/collide.toml -o $(OUT)/flexcell2-collide
	$(VENV)/bin/cotwin twin examples/flexcell2/twin.toml -o $(OUT)/flexcell2-twin
	$(VENV)/bin/cotwin check examples/turtlebot
	$(VENV)/bin/cotwin run examples/turtlebot/cotwin.toml -o $(OUT)/turtlebot
	@if [ -f ../shared/robosim/mobile/OA_mapping.pm ]; then \
		$(VENV)/bin/cotwin run examples/turtlebot/published.toml -o $(OUT)/turtlebot-published; \
	else echo "the published TurtleBot models are not in ../shared/robosim/mobile: only cotwin's own walk"; fi
	COTWIN=$(VENV)/bin/cotwin scripts/turtlebot-live.sh $(OUT)/turtlebot-twin
	@echo "results: $(OUT)/outputs.csv, $(OUT)/figure.png, $(OUT)/gauss-seidel/, $(OUT)/pick-place/ (multimodel: $(OUT)/multimodel.json)"
	@echo "live twin (PT over OPC UA, DT in MuJoCo, commands from RabbitMQ): $(OUT)/twin/figure.png, $(OUT)/twin/deviation.json"
	@echo "TurtleBot3 random walk (Fig. 18 and a top view): $(OUT)/turtlebot/figure.png, $(OUT)/turtlebot/path.png; live: $(OUT)/turtlebot-twin/"

test: install
	$(PY) -m pytest -q -n auto --dist loadfile --no-loadscope-reorder

bench: install
	$(PY) benchmarks/run.py

clean:
	rm -rf $(VENV) out build dist src/*.egg-info .pytest_cache .hypothesis
