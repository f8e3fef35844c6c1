"""hil.scheduling: the bench's threads ask for SCHED_FIFO; what they start inherits it; the old
policy comes back; without the privilege nothing changes and the reason is given; absurd
priorities are refused."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from vdps_hil.hil import scheduling

POLICY_OF_CHILD = "import os; print(os.sched_getscheduler(0), os.sched_getparam(0).sched_priority)"


def fifo_permitted() -> bool:
    """Whether this process may use SCHED_FIFO (asked in a child, which changes nothing here)."""
    code = "import os; os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))"
    return subprocess.run([sys.executable, "-c", code], capture_output=True, timeout=60).returncode == 0


@pytest.mark.skipif(not fifo_permitted(), reason="this machine does not permit SCHED_FIFO")
def test_fifo_for_this_thread_and_what_it_starts_then_the_old_policy_back():
    before = (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority)
    got, prev = scheduling.request(10)
    try:
        assert got == {"policy": "fifo", "priority": 10} and prev == before
        assert os.sched_getscheduler(0) == os.SCHED_FIFO
        child = subprocess.run([sys.executable, "-c", POLICY_OF_CHILD], capture_output=True, text=True,
                               timeout=60, check=True).stdout.split()
        assert child == [str(os.SCHED_FIFO), "10"]  # the pipeline process would inherit it
    finally:
        scheduling.restore(prev)
    assert (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority) == before


def test_without_the_privilege_nothing_changes_and_the_reason_is_given():
    """As the unprivileged user 'nobody' (a child process) the request is refused by the kernel."""
    if os.geteuid() != 0:
        pytest.skip("needs root to become an unprivileged user")
    code = ("import os, json, resource; resource.setrlimit(resource.RLIMIT_RTPRIO, (0, 0)); "
            "os.setgid(65534); os.setuid(65534); from vdps_hil.hil import scheduling as s; "
            "got, prev = s.request(10); print(json.dumps([got, prev, os.sched_getscheduler(0)]))")
    import json

    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True)
    got, prev, policy = json.loads(out.stdout)
    assert got["policy"] == "default" and "not permitted" in got["reason"] and prev is None
    assert policy == os.SCHED_OTHER


def test_zero_or_none_leaves_the_scheduling_alone_and_absurd_priorities_are_refused():
    before = os.sched_getscheduler(0)
    assert scheduling.request(0) == ({"policy": "default", "reason": "not asked"}, None)
    assert scheduling.request(None)[1] is None and os.sched_getscheduler(0) == before
    for bad in (100, -1):
        with pytest.raises(ValueError, match="1..99"):
            scheduling.request(bad)
