# Two entry points for a newcomer on a fresh machine (see README.md):
#   make demo   set everything up, start the default service, run the paper's experiment
#   make test   set everything up and run the whole test suite
#   make test-quick  the inner loop, under a minute: the unit tests and one integration smoke test
#   make docs   the documentation site, built strictly (mkdocs.yml)
#   make wheels the release wheels (scripts/build-wheels.sh)
#   make lint   ruff (lint and format) over the tree, mypy --strict over the modules pyproject.toml
#               lists, import-linter over the layers ([tool.importlinter] in pyproject.toml)
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin

.PHONY: setup demo test test-quick lint clean mutation mutation-changed docs

setup: $(VENV)/.installed

# the compiled parts: one list, fxis_shm/_compiledparts.py (setup.py builds them, _compiled.py checks them)
COMPILED_SOURCES := fxis_shm/_compiledparts.py $(shell $(PYTHON) fxis_shm/_compiledparts.py)

$(VENV)/.installed: pyproject.toml setup.py $(COMPILED_SOURCES) scripts/install-system-packages.sh
	bash scripts/install-system-packages.sh
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[aravis,genicam,record,video,foxglove,ros2,rerun,lerobot]" --group test --group lint --group bench --group docs --group mutation
	touch $@

# Real ROS 2 nodes for the bridge's tests (tests/rclpy_peer.py), each distribution from its wheels in
# a venv of its own (the wheels re-run Python to set their library path): Kilted also runs the bridge
# itself on rclpy (fxis run --ros2-python .venv-ros/bin/python), so it holds fxis-shm too, with PyAV
# for video snapshots (its
# compiled parts are the checkout's own, built by setup: FXIS_PURE_PYTHON=1 skips building them again).
ROS_KILTED := 'ros-kilted-rclpy[fastrtps]==9.1.2' ros-kilted-rmw-fastrtps-cpp==9.3.3 ros-kilted-sensor-msgs==5.5.1 \
              ros-kilted-std-msgs==5.5.1 ros-kilted-diagnostic-msgs==5.5.1
ROS_JAZZY  := 'ros-jazzy-rclpy[fastrtps]==7.1.6' ros-jazzy-rmw-fastrtps-cpp ros-jazzy-sensor-msgs ros-jazzy-std-msgs \
              ros-jazzy-diagnostic-msgs
ROS_VENVS  := .venv-ros/.installed .venv-ros-jazzy/.installed

.PHONY: ros-venvs
ros-venvs: $(ROS_VENVS)

.venv-ros/.installed: $(VENV)/.installed
	$(PYTHON) -m venv .venv-ros
	.venv-ros/bin/python -m pip install --quiet --upgrade pip
	.venv-ros/bin/python -m pip install --quiet $(ROS_KILTED)
	FXIS_PURE_PYTHON=1 .venv-ros/bin/python -m pip install --quiet -e ".[ros2,record,video]"
	touch $@

.venv-ros-jazzy/.installed:
	$(PYTHON) -m venv .venv-ros-jazzy
	.venv-ros-jazzy/bin/python -m pip install --quiet --upgrade pip
	.venv-ros-jazzy/bin/python -m pip install --quiet $(ROS_JAZZY)
	touch $@

# lerobot 0.4.4 (the newest on Python 3.11) with the LeRobot camera plugin (integrations/lerobot), for
# tests/integration/test_lerobot.py, test_lerobot_export.py and bench/compare/lerobot_sync.py: torch is the
# CPU 2.13.0 wheel, with torchcodec 0.13.0 built for it (LeRobotDataset's video decoder; lerobot 0.4.4 pins
# torchcodec<0.11, built for the older torch), lerobot is installed without its torch<2.11 pin and its other
# requirements are installed as listed.
.venv-lerobot/.installed: $(VENV)/.installed integrations/lerobot/pyproject.toml integrations/lerobot/lerobot-0.4.4-requirements.txt
	$(PYTHON) -m venv .venv-lerobot
	.venv-lerobot/bin/python -m pip install --quiet --upgrade pip
	.venv-lerobot/bin/python -m pip install --quiet torch==2.13.0 torchcodec==0.13.0
	.venv-lerobot/bin/python -m pip install --quiet --no-deps lerobot==0.4.4
	.venv-lerobot/bin/python -m pip install --quiet -r integrations/lerobot/lerobot-0.4.4-requirements.txt
	FXIS_PURE_PYTHON=1 .venv-lerobot/bin/python -m pip install --quiet -e .
	.venv-lerobot/bin/python -m pip install --quiet --no-deps -e integrations/lerobot
	touch $@

demo: setup
	$(BIN)/python bench/latency/paper.py

# The whole suite on the compiled hot path (the first line fails if it is not compiled) and, beside
# it, the unit tests and the ring's and the local path's tests again on the pure-Python fallback
# (docs/design.md, "The compiled hot path"). `FXIS_PURE_PYTHON=1 make test`: all of it on the fallback.
PURE_INTEGRATION := tests/integration/test_ring.py tests/integration/test_localpath.py \
                    tests/integration/test_localwaits.py

# Tests run on this many pytest-xdist workers, each test's services, hosts and DDS domain its own.
# A module's tests stay on one worker, in order: its shared services start once. Five workers on
# 2 cores: most tests wait on cameras, sockets and processes more than they compute (4 workers
# used 1.6 cores; 5 ran the suite in 275 s to 4's 310). The longest files of the last run start
# first (tests/filetimes.py). TEST_WORKERS=0: one process, in order.
TEST_WORKERS ?= 5
XDIST := $(if $(filter 0,$(TEST_WORKERS)),-p no:xdist,-n $(TEST_WORKERS) --dist loadscope)
# The sync logic is tested in virtual time (tests/virtualtime, tests/unit/test_virtual_sync.py),
# exact whatever the load, and a failure there is a defect. The parallel pass reruns nothing: a
# test of it that fails on a loaded machine has failed (issue 41).
# The real-time tier: the tests marked `realtime` (pyproject.toml), which judge a real timer's
# residuals, skews across real clocks, a file's playback rate, a DDS reader and a camera keeping up,
# 26 tests today (tests/integration/test_realtime.py 4, tests/integration/test_ros2.py 8,
# tests/integration/test_lockstep.py 3, tests/integration/test_capture_at.py 2,
# tests/integration/test_lerobot.py 2, tests/integration/test_trigger.py 2, tests/backends/test_aravis.py 1,
# tests/backends/test_opencv.py 1, tests/integration/test_dashboard.py 1,
# tests/integration/test_foxglove.py 1, tests/integration/test_localwaits.py 1). They run after
# the parallel pass, alone, one at a time, their services at SCHED_FIFO (--realtime, as a cell
# that needs its cameras in step runs them); a failed one runs once more, and every rerun is
# written to RERUN_LOG (tests/rerunlog.py), which the run ends by listing (issue 41).
RERUN_LOG := .pytest_cache/reruns.log
REALTIME := -p no:xdist -m realtime -raR --reruns 1 -p tests.rerunlog --rerun-log $(RERUN_LOG) tests

# Every process the suite starts (services, workers, `fxis` commands: over a thousand) imports the
# package: its bytecode is written once here, as the environment may forbid writing it at import
# (PYTHONDONTWRITEBYTECODE), which made each process compile some 50 modules again.
# The pure-Python pass runs beside the main one, on one process: its services' tests first, then
# its unit tests at the lowest priority (nice 19; a service started at that priority would not
# keep real time): the main pass, waiting on cameras and sockets, leaves part of the 2 cores
# idle, and the unit tests (55 CPU-s) get what it leaves, no more. Its report follows the main one's.
# Then scripts/test-aarch64.sh's steps on this machine's own CPU (its emulated ARM64 run is by
# hand, 25 minutes): the ordering mode, and its pytest call over one file (its list ran above).
# Last, the release wheels of every CPython 3.10-3.13 installed here (`make wheels`), built from the
# sdist and each smoke-tested in a fresh venv as a user installs it (scripts/build-wheels.sh).
PURE_LOG := .pytest_cache/pure-python.log
# Its unit tests get what the main pass leaves of the CPU, at times a twelfth of it: their per-test
# timeout (a hang's guard, 120 s in pyproject.toml) is longer there, or a 10 CPU-s test times out.
PURE_UNIT_TIMEOUT := 900
test: setup lint docs mutation-changed $(ROS_VENVS) .venv-lerobot/.installed
	$(BIN)/python -c "import fxis_shm, os, sys; sys.exit(not (fxis_shm.compiled or os.environ.get('FXIS_PURE_PYTHON') == '1'))"
	$(BIN)/python -m compileall -q fxis_shm workers tests bench examples > /dev/null
	@mkdir -p .pytest_cache && rm -f $(RERUN_LOG) $(RERUN_LOG).details
	( export FXIS_PURE_PYTHON=1; PURE="$(BIN)/python -m pytest -q -p no:xdist -o cache_dir=.pytest_cache/pure"; \
	  $$PURE $(PURE_INTEGRATION); services=$$?; nice -n 19 $$PURE --timeout $(PURE_UNIT_TIMEOUT) tests/unit; exit $$((services || $$?)) \
	) > $(PURE_LOG) 2>&1 & pure=$$!; trap 'kill $$pure 2>/dev/null' INT TERM; \
	$(BIN)/python -m pytest $(XDIST) -m "not realtime"; main=$$?; \
	wait $$pure; pure_code=$$?; \
	echo "== the pure-Python pass, beside the main one (FXIS_PURE_PYTHON=1; exit code $$pure_code):"; cat $(PURE_LOG); \
	echo "== the real-time tier, alone:"; $(BIN)/python -m pytest $(REALTIME); realtime=$$?; \
	echo "== reruns ($(RERUN_LOG), whole reports in $(RERUN_LOG).details): $$(cat $(RERUN_LOG) 2>/dev/null | wc -l)"; cat $(RERUN_LOG) 2>/dev/null; \
	test $$main -eq 0 -a $$pure_code -eq 0 -a $$realtime -eq 0
	scripts/test-aarch64.sh --quick -q tests/unit/test_ordering.py
	scripts/build-wheels.sh .pytest_cache/wheels

# The inner loop: every unit test and one smoke test of a real service (a tuple's pixels checked
# against its metadata), without lint; `make test` (and CI) still runs everything.
QUICK_TESTS := tests/unit tests/integration/test_requests.py::test_tuple_pixels_are_the_frames_the_metadata_names

test-quick: setup
	$(BIN)/python -m pytest -q $(if $(filter 0,$(TEST_WORKERS)),-p no:xdist,-n $(TEST_WORKERS) --dist load) $(QUICK_TESTS)

# The documentation as a site (mkdocs.yml): docs/*.md, the CLI reference generated from the parsers
# (scripts/cli_reference.py; a test fails when it differs from --help) and the API reference from the
# docstrings; strict, so a broken link or anchor, a page left out of the site or an API name that
# does not resolve fails it. `make test` builds it; open .pytest_cache/site/index.html.
docs: setup
	PYTHONPATH=. NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --quiet -d .pytest_cache/site

lint: setup
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/mypy
	$(BIN)/lint-imports

# Mutation testing of the pure core's decision modules (the full run: minutes on 2 cores; `make
# test` runs mutation-changed, below): mutmut plants one fault at a time ([tool.mutmut] in
# pyproject.toml) and runs the unit tests that cover it; fails if a mutant survives that
# docs/mutation.md does not explain, else records the run (docs/mutation-record.json).
# Its work is left in mutants/ (`.venv/bin/mutmut show NAME` shows a mutant).
# (mutmut comes with setup now, as `make test` runs it; this stays for trees set up before)
$(VENV)/.mutation-installed: $(VENV)/.installed pyproject.toml
	$(BIN)/python -c "import mutmut" 2>/dev/null || $(BIN)/python -m pip install --quiet --group mutation
	touch $@

mutation: $(VENV)/.mutation-installed
	rm -rf mutants
	FXIS_PURE_PYTHON=1 $(BIN)/mutmut run --max-children 2
	$(BIN)/mutmut results
	$(BIN)/python scripts/mutation_changed.py record

# Part of `make test` (and CI): mutation over what changed since the last full run, as
# docs/mutation-record.json (written by `make mutation`, committed) has it: every mutant of a
# function changed since, and those a changed test killed. Fails on a survivor docs/mutation.md
# does not explain; nothing changed: nothing to run (docs/mutation.md, "In make test").
mutation-changed: $(VENV)/.mutation-installed
	$(BIN)/python scripts/mutation_changed.py run

clean:
	rm -rf $(VENV) .venv-ros .venv-ros-jazzy build *.egg-info bench/results

# Release wheels: manylinux wheels for every CPython 3.10-3.13 installed here, from the sdist, each
# smoke-tested in a fresh venv (scripts/build-wheels.sh says how; WHEEL_PYTHONS picks versions).
.PHONY: wheels
wheels:
	scripts/build-wheels.sh dist
