# One-command set-up, tests, demo and benchmarks for lvws_ros.
# `make test` and `make demo` create .venv when missing; re-running is a fast no-op.

SHELL := /bin/bash
PYTHON ?= python3
VENV := $(CURDIR)/.venv
PY := $(VENV)/bin/python
BUILD := $(CURDIR)/build
MSG_SRCS := $(wildcard msg_defs/msg/*.msg) $(wildcard msg_defs/srv/*.srv) $(wildcard msg_defs/action/*.action) msg_defs/CMakeLists.txt msg_defs/package.xml
PKG_SRCS := setup.py setup.cfg package.xml resource/lvws_ros $(wildcard config/*) \
  $(shell find lvws_ros -name '*.py' -o -name '*.pt' -o -name '*.json' 2>/dev/null)
EXES := lvws scheduler cell_sim recorder fake_robots dispatcher

# The environment is an ament prefix; these make ament_index and rclpy find it.
export AMENT_PREFIX_PATH := $(VENV)$(if $(AMENT_PREFIX_PATH),:$(AMENT_PREFIX_PATH))
export PYTHONDONTWRITEBYTECODE := 1

.PHONY: env env-dev msgs test lint browser demo compare docs bench fuzz clean distclean

# The set-up, as stamps in .venv: the ROS 2 wheels (.stamp-ros); then the interfaces compile
# (.stamp-msgs) while pip installs the run-time packages (.stamp-deps); then the package
# (.stamp-pkg). `env` is what the demo and the commands need (requirements.txt); `env-dev`
# adds the tests', checks' and docs' tools (requirements-dev.txt), before the package's
# install so that no two pips write into .venv at once.
# (make -q first: up to date, it says nothing.)
JOBS ?= 2
SETUP = @$(MAKE) --no-print-directory -q $(1) 2>/dev/null || $(MAKE) --no-print-directory -j$(JOBS) $(1)
env:
	$(call SETUP,$(VENV)/.stamp-pkg)
env-dev:
	$(call SETUP,$(VENV)/.stamp-pkg DEV_STAMP=$(VENV)/.stamp-dev)

$(PY):
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip

# At the versions the run-time pins give (numpy, PyYAML...), so the next step changes none of
# them under the interfaces' build.
$(VENV)/.stamp-ros: requirements-ros.txt requirements-python.txt | $(PY)
	$(PY) -m pip install --quiet -r requirements-ros.txt -c requirements-python.txt
	touch $@

# Without pip's byte-compiling of every module (some 11,000, most of them never imported by
# lvws: about a minute of CPU); one import of the heavy packages the commands use writes the
# byte code of what they load (a wrong or missing name here costs speed, not correctness).
# env-dev compiles the rest: make's commands run with PYTHONDONTWRITEBYTECODE.
WARM_IMPORTS := torch ortools.sat.python.cp_model matplotlib.pyplot PIL.Image pymunk rosbags.highlevel \
  rosbags.rosbag2 rosbags.typesys mcap_ros2.decoder tqdm yaml
$(VENV)/.stamp-deps: requirements.txt requirements-ros.txt requirements-python.txt $(VENV)/.stamp-ros
	$(PY) -m pip install --quiet --no-compile -r requirements.txt
	PYTHONDONTWRITEBYTECODE= $(PY) -c 'import importlib, sys; [importlib.import_module(m) for m in sys.argv[1:]]' $(WARM_IMPORTS)
	touch $@

# compileall: some packages ship files that are not Python 3 (templates, examples), which it
# reports and pip's own compiling skips silently.
$(VENV)/.stamp-dev: requirements-dev.txt $(VENV)/.stamp-deps
	$(PY) -m pip install --quiet -r requirements-dev.txt
	$(PY) -m compileall -q -q -j$(JOBS) $$($(PY) -c 'import sysconfig; print(sysconfig.get_path("purelib"))') || true
	touch $@

# lvws_msgs: plain cmake against the environment (no colcon on pip installs), the C
# interfaces that rclpy uses only (msg_defs/CMakeLists.txt, LVWS_MSGS_CPP).
$(VENV)/.stamp-msgs: $(MSG_SRCS) $(VENV)/.stamp-ros
	rm -rf $(BUILD)/lvws_msgs && mkdir -p $(BUILD)/lvws_msgs
	cd $(BUILD)/lvws_msgs && cmake $(CURDIR)/msg_defs -DCMAKE_BUILD_TYPE=Release \
	  -DCMAKE_PREFIX_PATH=$(VENV) -DCMAKE_INSTALL_PREFIX=$(VENV) -DLVWS_MSGS_CPP=OFF \
	  -DPython3_EXECUTABLE=$(PY) -DBUILD_TESTING=OFF > cmake.log \
	  || { cat cmake.log; exit 1; }
	MAKEFLAGS= $(MAKE) -C $(BUILD)/lvws_msgs -j$(JOBS) install > $(BUILD)/lvws_msgs/make.log \
	  || { tail -50 $(BUILD)/lvws_msgs/make.log; exit 1; }
	touch $@

# lvws_ros: a regular (not editable) install, since only that installs the ament
# marker, package.xml and config/ under share/; then link the executables where
# ros2run looks (<prefix>/lib/lvws_ros/), as setup.cfg does for colcon builds.
$(VENV)/.stamp-pkg: $(PKG_SRCS) $(VENV)/.stamp-msgs $(VENV)/.stamp-deps | $(DEV_STAMP)
	$(PY) -m pip install --quiet --no-deps --no-build-isolation .
	rm -rf $(BUILD)/lib $(BUILD)/bdist.* lvws_ros.egg-info
	mkdir -p $(VENV)/lib/lvws_ros
	for exe in $(EXES); do ln -sf $(VENV)/bin/$$exe $(VENV)/lib/lvws_ros/$$exe; done
	grep -q AMENT_PREFIX_PATH $(VENV)/bin/activate || \
	  echo 'export AMENT_PREFIX_PATH="$$VIRTUAL_ENV$${AMENT_PREFIX_PATH:+:$$AMENT_PREFIX_PATH}"' >> $(VENV)/bin/activate
	touch $@

msgs: $(VENV)/.stamp-msgs

test: env-dev lint browser
	$(PY) -m pytest -q -rs --durations=15 test  # -rs: every skip prints its reason; the 15 slowest tests are listed

# The paper's case study end to end: cell_sim + scheduler (default policy: auto, with the shipped
# LVWS model) + recorder; the bag lands in bags/, Gantt PNG, GIF and logs in out/. Then three
# policies' plans with travel, executed in the simulator told the travel and not (make compare:
# all five of docs/ros.md's table). No step is silent for more than a few seconds: the set-up
# prints its elapsed time every 5 s, the launch its run's progress, the comparison a progress bar.
DEMO_COMPARE := grp,lvws,exact
demo:
	@echo "Set-up (.venv, ROS 2 interfaces, the package; about 2 minutes on a fresh clone, none after):"
	@start=$$(date +%s); ( while sleep 5; do echo "  ... set-up: $$(( $$(date +%s) - start )) s"; done ) & beat=$$!; \
	  trap 'kill $$beat 2>/dev/null' EXIT; $(MAKE) --no-print-directory env
	@echo "The case study on ROS 2 (simulator, scheduler, recorder as processes):"
	$(PY) -m lvws_ros.cli launch --bag-dir bags --out-dir out
	@echo "Plans with and without travel, executed in the simulator (lvws sim --compare; make compare: all five):"
	$(PY) -m lvws_ros.cli sim --compare $(DEMO_COMPARE)

# The table of docs/ros.md: five policies' plans executed told the travel and not (minutes:
# lvws_beam's search is the long one; a progress bar shows each policy).
compare: env
	$(PY) -m lvws_ros.cli sim --compare grp,lvws,auto,exact,lvws_beam

# Debian's Chromium for the dashboard's browser tests (test/ros/test_dashboard.py), when
# missing: as root with apt-get; elsewhere those tests skip and say why.
browser:
	@command -v chromium >/dev/null 2>&1 || { [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1 && \
	  { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium; } >/dev/null 2>&1; } \
	  || echo "Chromium could not be installed (needs root and apt-get): the browser tests will skip"

# The documentation site (Sphinx + MyST, API reference from the docstrings): build/docs/index.html.
docs: env-dev
	$(PY) -m sphinx -q -W --keep-going -b html docs $(BUILD)/docs
	@echo "documentation site: $(BUILD)/docs/index.html"

# Property-based fuzzing of the file formats: 10^4 examples per property, counts printed.
fuzz: env-dev
	LVWS_FUZZ_EXAMPLES=10000 $(PY) -m pytest -q -s -p no:cacheprovider test/core/test_fuzz_formats.py

# Benchmarks print figures (with the machine); they assert nothing and are not in `make test`.
bench: env
	$(PY) -m lvws_ros.cli.bench

# ruff; mypy (strict on the core); import-linter's layer, cycle and dependency contracts
# (.importlinter) on the source tree.
lint: env-dev
	$(PY) -m ruff check lvws_ros test
	$(PY) -m mypy lvws_ros
	$(PY) -m mypy --strict lvws_ros/core lvws_ros/errors.py
	PYTHONPATH=$(CURDIR) $(VENV)/bin/lint-imports --no-cache

clean:
	rm -rf $(BUILD) *.egg-info .pytest_cache .mypy_cache .ruff_cache .import_linter_cache

distclean: clean
	rm -rf $(VENV)
