# Two commands set everything up on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3.11
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
# The report's xanfis peer pins numpy<=1.26.0 (we run numpy 2): it gets its own virtualenv.
# torch is pinned to 2.13.0 so pip takes the local CPU wheel, not several GB of CUDA.
XVENV  := $(VENV)-xanfis
XANFIS_REQS := torch==2.13.0 xanfis==1.1.0
# ament_index_python looks packages up here; the ROS wheels live in the venv.
export AMENT_PREFIX_PATH := $(abspath $(VENV))
# Never inherit the ROS wheels' re-exec guard from another virtualenv.
unexport _ROS_WHEELS_BOOTSTRAP_COMPLETE
PIP_QUIET := --quiet --disable-pip-version-check

.PHONY: venv demo test bench docs screenshots clean

venv: $(STAMP)

$(STAMP): setup.py setup.cfg package.xml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install $(PIP_QUIET) --upgrade pip 2>&1 | grep -v '^WARNING: Location' || true
	$(PY) -m pip install $(PIP_QUIET) -e '.[ros,fe,fe-fast,test,report,dask,view,docs]' 2>&1 | grep -v '^WARNING: Location' || true
	$(PY) -c 'import haptic_anfis, numba, rclpy, trimesh, rosbags, matplotlib, sklearn' # fail here if the install did not
	$(VENV)/bin/haptic-anfis warmup # compile the nodes' numba kernels now, not at the first session
	$(PYTHON) -m venv $(XVENV)
	$(XVENV)/bin/python -m pip install $(PIP_QUIET) $(XANFIS_REQS) 2>&1 | grep -v '^WARNING: Location' || true
	$(XVENV)/bin/python -c 'import xanfis, torch' || echo 'WARNING: xanfis peer not installed; the report lists it as failed'
	touch $@

# Train the force models on the shipped dataset (test RMSE, evaluation speed), then run the whole
# node graph with the simulated Falcon for 10 s (loop rate, latency, forces), recording the session
# to a bag; then show the bag and re-simulate it with the current models (recomputed vs recorded force).
demo: venv
	$(VENV)/bin/haptic-anfis demo
	rm -rf out/demo_session
	$(VENV)/bin/haptic-anfis sim --duration 10 --record out/demo_session
	$(VENV)/bin/haptic-anfis bag info out/demo_session
	$(VENV)/bin/haptic-anfis bag resim out/demo_session

test: venv
	$(PY) -m pytest test

# The documentation site into site/ (warnings are errors). The reference pages (CLI, nodes, case
# table, dependencies, measurements index) are generated first by docs/gen/generate.py, a mkdocs
# hook. No --quiet: it hides the warnings that --strict counts (the build would pass broken links).
docs: venv
	NO_MKDOCS_2_WARNING=1 $(PY) -m mkdocs build --strict --site-dir site

# Every bench/bench_*.py script prints its own table (ratios and percentiles, never asserted) and
# writes it to docs/measurements/<name>.md with the date, machine and load (bench/harness.py).
bench: venv
	@set -e; for f in bench/bench_*.py; do echo "== $$f"; $(PY) $$f; done

# The browser view's pictures for the docs (docs/view_live.png, docs/view_debrief.png): an exam
# with the page open, captured by headless chromium (apt-get install chromium).
screenshots: venv
	$(PY) -m haptic_anfis.view.shots --out docs

clean:
	rm -rf $(VENV) $(XVENV) build install log site *.egg-info
