# ssi_bridge: `make run` starts the node on its simulated default, `make test` runs every test
# but the slow tier (load, stress, soak, two hosts), `make test-all` runs them all.
# Both set up first (idempotent): a CPython 3.12 venv with the pinned wheels, then a colcon
# build of msg_defs/ (ssi_bridge_msgs) and this package into install/.

SHELL := /bin/bash
.SHELLFLAGS := -eu -o pipefail -c
.DEFAULT_GOAL := help

VENV        := .venv
STAMP_VENV  := $(VENV)/.requirements.stamp
STAMP_BUILD := install/.build.stamp
ENV         := source scripts/env.sh
ARGS        ?=
PYTEST_ARGS ?=
#: pytest-xdist workers of `make test` (0: one process); the slow tier always runs alone.
#: Four on two cores: the node tests mostly wait on the wire and on DDS, so four nearly halve
#: the wall time of two, idle and beside two CPU burners alike (figures: the README's "Tests")
TEST_WORKERS ?= 4
ONLY        ?=

SOURCES := $(shell find msg_defs config launch resource -type f 2>/dev/null) setup.py setup.cfg package.xml

.PHONY: help setup run monitor test test-slow test-all bench lock clean

help:
	@echo "make run    set up if needed, then run ssi_bridge_node (ARGS='--ros-args ...' passes through)"
	@echo "make monitor  print joints, diagnostics and bus load of a running node each second (ARGS='--namespace ns')"
	@echo "make test   set up if needed, then run the test suite but the slow tier (PYTEST_ARGS=... passes through)"
	@echo "make test-all  make test, then the slow tier: load, stress, soak and two-host tests (make test-slow alone)"
	@echo "make bench  run the benchmarks in bench/ (ONLY=<name> runs bench/bench_<name>.py)"
	@echo "make setup  create .venv from requirements.lock and colcon-build into install/"

setup: $(STAMP_BUILD)

$(STAMP_VENV): requirements.lock scripts/find_python.sh
	@py=$$(scripts/find_python.sh); \
	if [ ! -x $(VENV)/bin/python ]; then echo "setup: creating $(VENV) with $$py"; "$$py" -m venv $(VENV); fi
	$(VENV)/bin/python -m pip install --quiet --disable-pip-version-check --upgrade pip==26.3
	$(VENV)/bin/python -m pip install --quiet --disable-pip-version-check -r requirements.lock
	@touch $@

$(STAMP_BUILD): $(STAMP_VENV) $(SOURCES)
	@echo "setup: colcon build (ssi_bridge_msgs, ssi_bridge) -> install/"
	@$(ENV) && colcon --log-base log build --symlink-install --paths . msg_defs \
	    --event-handlers console_cohesion- status- --cmake-args -DBUILD_TESTING=OFF > log/colcon-build.txt 2>&1 \
	    || { tail -n 60 log/colcon-build.txt; echo "setup: colcon build failed (full log: log/colcon-build.txt)"; exit 1; }
	@touch $@

log:
	@mkdir -p log
$(STAMP_BUILD): | log

run: setup
	@$(ENV) && exec install/ssi_bridge/lib/ssi_bridge/ssi_bridge_node $(ARGS)

monitor: setup
	@$(ENV) && exec install/ssi_bridge/lib/ssi_bridge/monitor $(ARGS)

# make test: TEST_WORKERS processes (pytest-xdist), each module's tests in one of them (they
# share the module's node); the slow tier one test at a time, nothing beside it
# Both compile the package's bytecode first (only what changed): each node and station process
# of the tests would otherwise compile every module it imports, ~0.1 s of CPU per process
# (PYTHONDONTWRITEBYTECODE set in the environment stops Python writing the cache, not reading it)
BYTECODE = python -m compileall -q -j 0 ssi_bridge > /dev/null

test: setup
	@$(ENV) && $(BYTECODE) && python -m pytest -m "not slow" -n $(TEST_WORKERS) --dist loadscope $(PYTEST_ARGS)

test-slow: setup
	@$(ENV) && $(BYTECODE) && python -m pytest -m slow $(PYTEST_ARGS)

test-all: test test-slow

bench: setup
	@$(ENV) && mkdir -p bench/results && : > bench/results/latest.jsonl && \
	for f in bench/bench_$(if $(ONLY),$(ONLY),*).py; do \
	  case "$$f" in *bench_soak.py) [ -n "$(ONLY)" ] || { echo "# $$f: minutes long, run it with make bench ONLY=soak"; continue; };; esac; \
	  echo "# $$f"; python "$$f" || echo "# $$f exited $$?"; done

# a venv of its own (not a fixed /tmp path two checkouts would share), removed afterwards
lock:
	@py=$$(scripts/find_python.sh); tmp=$$(mktemp -d); trap 'rm -rf "$$tmp"' EXIT; \
	"$$py" -m venv "$$tmp/venv" && \
	"$$tmp/venv/bin/python" -m pip install --quiet --upgrade pip==26.3 && \
	"$$tmp/venv/bin/python" scripts/lock.py

clean:
	rm -rf build install log $(VENV)
