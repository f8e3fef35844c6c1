# Two commands (README): `make run` runs the main job, `make test` passes the tests.
# Both create .venv/ at the repo root with the package installed editable on a fresh machine.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.vdps-installed

.PHONY: setup run test bench clean browser

setup: $(STAMP)

# pip byte-compiles what it installs in one process (about 24 s of the install here); compileall
# on every core does it in about 11 s, and compiles this package's own modules too, which every
# command and test process imports (where PYTHONDONTWRITEBYTECODE is set, as on this machine,
# Python never caches them itself: 0.3-0.4 s more per process). A file it cannot compile is
# reported and compiled at import instead (the leading '-').
$(STAMP): pyproject.toml Makefile
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet --no-compile -e '.[test,mdf,dask]'
	-$(PY) -m compileall -q -j 0 $(VENV)/lib vdps_hil
	$(PY) -m vdps_hil.jit --warm
	touch $(STAMP)

run: setup
	$(VENV)/bin/vdps bench --react --calibrate paper --speed auto -o bench.mcap

# headless Chromium for the HTML report tests (Debian package; the tests fail under CI without it)
browser:
	@command -v chromium >/dev/null 2>&1 || { (apt-get update -qq && apt-get install -y -qq chromium >/dev/null) || echo "make: could not install chromium (report tests will say so)"; }

# Two phases, both always run, either failing fails the target (pytest's exit 5, no test run, too):
# everything but the real-time tests on all cores (pytest-xdist, a module to a worker; one worker
# more than the cores this process may use, to fill the time tests wait on subprocesses, sockets
# and the browser, and to hold the suite's share of the CPU beside other work), then the
# real-time tests (tests/conftest.py REALTIME_MODULES) on their own, collecting only their modules
# (collecting the whole suite took 10 s; the full tree if the list cannot be read): two at a time
# when the machine leaves two cores idle at that moment (tools/realtime_workers.py), in two pytest
# processes side by side, the bench and the served logger (REALTIME_TOGETHER) in one of them so
# they never overlap, each process's output printed when both have ended; otherwise one at a time
# in one process (one at a time they use 0.73 of a core and took 161 s, two at a time 87 s on a
# quiet machine; beside one CPU-bound process they run one at a time, as they always did).
# One BLAS thread per test process: numpy's OpenBLAS otherwise starts a thread per core in each of
# the first phase's three workers (and in the process pools some tests start), which then spin
# against each other on two cores. tests/test_ranking.py alone, side by side in one session:
# 143.6 s of CPU and 75.7 s wall with OpenBLAS's default, 111.4 s and 59.6 s with one thread.
TESTENV := OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1
PYTEST := $(TESTENV) $(PY) -m pytest -q -p no:cacheprovider --timeout 600
WORKERS := $(shell echo $$(( $$(nproc) + 1 )))
RT_MODULES = $(PY) -P -c "import sys; sys.path.insert(0, 'tests'); import conftest; \
	print(' '.join(f'tests/{m}.py' for m in sorted(conftest.REALTIME_MODULES)))"
RT_SPLIT = $(PY) -P -c "import sys; sys.path.insert(0, 'tests'); import conftest as c; \
	t = sorted(c.REALTIME_TOGETHER); r = sorted(c.REALTIME_MODULES - c.REALTIME_TOGETHER); \
	print(' '.join(f'tests/{m}.py' for m in t)); print(' '.join(f'tests/{m}.py' for m in r))"
test: setup browser
	@$(PYTEST) -n $(WORKERS) --dist loadfile --durations 15 -m "not realtime" tests; a=$$?; \
	rt=$$($(RT_MODULES)) || rt=tests; \
	n=$$($(PY) tools/realtime_workers.py) || n=1; \
	split=$$($(RT_SPLIT)) || split=""; heavy=$$(echo "$$split" | sed -n 1p); rest=$$(echo "$$split" | sed -n 2p); \
	if [ "$${n:-1}" -gt 1 ] 2>/dev/null && [ -n "$$heavy" ] && [ -n "$$rest" ]; then \
		log=$$(mktemp -d); \
		$(PYTEST) --durations 5 -m realtime $$heavy > $$log/heavy 2>&1 & pid=$$!; \
		$(PYTEST) --durations 5 -m realtime $$rest > $$log/rest 2>&1; b2=$$?; \
		wait $$pid; b1=$$?; cat $$log/heavy $$log/rest; rm -rf $$log; \
		echo "make test: real-time tests exit $$b1 ($$heavy), $$b2 (the others)"; \
		b=$$(( b1 != 0 || b2 != 0 )); \
	else \
		$(PYTEST) --durations 5 -m realtime $${rt:-tests}; b=$$?; \
	fi; \
	echo "make test: other tests exit $$a, real-time tests exit $$b"; [ $$a -eq 0 ] && [ $$b -eq 0 ]

clean:
	rm -rf $(VENV) .pytest_cache
