# Two commands for a fresh machine: `make demo` (set-up plus the main job) and `make test`.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
COMPILED := $(VENV)/.compiled
CORE_SOURCES := $(wildcard threat_planner/core/*.py threat_planner/core/*/*.py)

.PHONY: venv demo plan-demo test bench clean

$(STAMP): setup.py setup.cfg package.xml
	@echo "[1/4] creating $(VENV)"
	$(PYTHON) -m venv $(VENV)
	@echo "[2/4] upgrading pip"
	$(BIN)/pip install --progress-bar on --upgrade pip
	@echo "[3/4] installing threat_planner with ROS 2 wheels (about a minute)"
	$(BIN)/pip install --progress-bar on -e '.[ros,record,test,bench,cluster,geo]'
	touch $(STAMP)

# Again whenever a core source changes (a pull, an edit): the cache is keyed by the kernels'
# contents, so a change to them would otherwise compile in the first plan (or test).
$(COMPILED): $(STAMP) $(CORE_SOURCES)
	@echo "[4/4] compiling the kernels into the cache (once per version of them, 50-130 s)"
	$(BIN)/threat-planner compile
	touch $(COMPILED)

venv: $(COMPILED)

# Plans the bundled 20-threat scenario, prints J and timings, writes the figure and JSON.
plan-demo: venv
	$(BIN)/threat-planner plan test/data/uniform20_0.yaml --plot demo_out/plan.png \
		--json demo_out/plan.json
	@echo "figure: demo_out/plan.png"

# The live system: planner_node + threat_publisher (drifting threats), J and timing of every
# plan as it arrives; Ctrl-C stops both and writes demo_out/last_plan.png.
demo: venv
	$(BIN)/threat_planner_demo --scenario test/data/uniform20_0.yaml --figure demo_out/last_plan.png

# Tests that measure a rate or a deadline (marked `alone`) first, by themselves: beside
# another worker's node tests a 100 Hz flood lost 11 % of its pictures in one CI run.
# Then the rest in two workers (pytest-xdist), a test file each: node tests mostly wait
# on DDS and child processes, so the second core works meanwhile (550 s -> 400 s here).
TEST_WORKERS ?= 2
test: venv
	$(BIN)/python -m pytest -q -m alone
	$(BIN)/python -m pytest -q -n $(TEST_WORKERS) --dist loadfile -m 'not alone'

bench: venv
	$(BIN)/python -m bench benchmark

clean:
	rm -rf $(VENV) build install log demo_out .pytest_cache
