import os
import shutil
import tempfile
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
REAL_DATA = SHARED / "data" / "real"


_CACHE_ENV = "VDPS_CACHE_DIR"
_saved_cache_env: list = []


def pytest_configure(config):
    """The DBC description cache (vdps_hil.codecs.dbc_cache) of the test run: a fresh temporary
    directory, never the user's ~/.cache; set before collection (test modules load DBCs at
    import) and inherited by subprocesses."""
    _saved_cache_env.append(os.environ.get(_CACHE_ENV))
    os.environ[_CACHE_ENV] = tempfile.mkdtemp(prefix="vdps-test-cache-")


def pytest_unconfigure(config):
    if not _saved_cache_env:
        return
    shutil.rmtree(os.environ.get(_CACHE_ENV, ""), ignore_errors=True)
    old = _saved_cache_env.pop()
    if old is None:
        os.environ.pop(_CACHE_ENV, None)
    else:
        os.environ[_CACHE_ENV] = old


REALTIME_MODULES = frozenset({"test_bench", "test_bench_cmd", "test_log_cmd", "test_recover_cmd", "test_node",
                              "test_fdreader", "test_live_view"})
"""Test modules whose behaviour depends on keeping up with the wall clock (the HIL bench, the
logger at Table 1 rates, kill -9 while logging, the node reading real ptys and a CAN bus fed at
the recording's pace). They carry the ``realtime`` marker: ``make test`` runs them in a phase of
their own, after the rest has run on both cores, so they meet the machine's own load, not the
load of the test suite's other half; there they run two at a time when the machine leaves two
cores idle at that moment (``tools/realtime_workers.py``; two pytest processes side by side, the
modules of ``REALTIME_TOGETHER`` in one of them), one at a time otherwise (beside a CPU-bound
process). (``test_node`` joined on 2026-12-05: scheduled beside the
three heaviest modules on the two cores, its live IMU stamps, mapped from the device clock by
the host's receive times, re-anchored under the delay and came out in another order than the
recording's decoding, twice in one run; it passed in every run where it met less load.
``test_fdreader`` joined on 2026-12-06: its writers pace a pty by the wall clock against a reader
process, and its full-buffer test lost whole writes twice beside the heaviest modules, through
a drain at quit that did not wait for bytes still in the terminal layer, since fixed.
``test_live_view`` joined the same day: its served logger and bench run live devices at Table 1
rates; beside the heaviest modules the logger lost 22,496 CAN frames to sequence gaps and its
two WebSocket clients received nothing in 90 s (keepalive ping timeout), while the same test
alone passes in 6 s.)"""


REALTIME_TOGETHER = frozenset({"test_bench", "test_live_view"})
"""Real-time modules that must not run at the same time as each other. Where the real-time phase
runs two at a time, ``make test`` runs these in one pytest process, one after the other, and the
other real-time modules in a second process beside it (xdist's ``loadgroup`` would say the same,
but with pytest 9.2 it no longer groups: pytest-xdist issue 1386, seen here too). Two at a time
under ``--dist loadfile``, 2026-12-06 (fresh clone of 2c39bd5, quiet machine), the two overlapped:
the bench's react test warned 0.87 s before the point of no return (>= 1.0 asked) while
``test_live_view``'s served logger answered no WebSocket ping for 20 s and served nothing in
90 s. Each passed alone (16.7 s and 13.1 s), and the phase passed two at a time in 82 s right
after."""


def pytest_collection_modifyitems(config, items):
    for item in items:
        if item.path.stem in REALTIME_MODULES:
            item.add_marker(pytest.mark.realtime)


@pytest.fixture
def rng():
    """Every test's random numbers come from this seeded generator."""
    return np.random.default_rng(12345)


@pytest.fixture(scope="session")
def drive_cache(tmp_path_factory) -> Path:
    """The folder of the simulated drives of this test run (``workbench_study.cached_drive``):
    one for every pytest-xdist worker of the run (beside the workers' own temporary folders), so
    a drive several modules read is simulated once, by the first worker that asks for it."""
    base = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER") and base.name.startswith("popen-"):
        base = base.parent  # the run's own folder (xdist's layout); never one shared by other runs
    folder = base / "shared_drives"
    folder.mkdir(exist_ok=True)
    return folder


@pytest.fixture
def real_data() -> Path:
    if not REAL_DATA.is_dir():
        if os.environ.get("CI"):
            pytest.fail(f"real data folder missing under CI: {REAL_DATA}")
        pytest.skip(f"real data folder not present: {REAL_DATA}")
    return REAL_DATA
