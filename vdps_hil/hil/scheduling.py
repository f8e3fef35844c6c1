"""Real-time scheduling of the bench: the simulator and the pipeline ask the kernel for a
fixed-priority policy (``SCHED_FIFO``) while the bench runs, as openpilot's real-time daemons do.

Why: with a CPU-bound process beside the bench on a 2-core machine (issue 19's "hog"), the
default time-sharing policy made the bench's threads wait behind it for a slice now and then:
``vdps bench --react --calibrate paper`` measured side by side with ``chrt -f 10`` in one session
(quiet machine plus ``python3 -c 'while 1: pass'``): sensor frame -> warning frame p99 14.3 and
8.4 ms and 5,800-6,000 late sends of 24,651 under the default policy, 5.8 and 5.5 ms and 173-533
late sends under SCHED_FIFO 10.

What: :func:`request` switches the calling thread to ``SCHED_FIFO`` at ``priority`` (1-99); the
threads and processes it starts afterwards inherit it (the bench's pipeline child, its
prediction worker, the readers). :func:`restore` puts the previous policy back. Without the
privilege (not root and no ``RLIMIT_RTPRIO``, or a container without ``CAP_SYS_NICE``) nothing
changes and the result says so; the bench then runs as before. The kernel's real-time throttling
(``/proc/sys/kernel/sched_rt_runtime_us``, 95 % by default) leaves the rest of the machine a
share even if a real-time thread never sleeps.
"""

from __future__ import annotations

import os

__all__ = ["DEFAULT_PRIORITY", "NOT_ASKED", "request", "restore"]

DEFAULT_PRIORITY = 10
"""``vdps bench``'s SCHED_FIFO priority: low among real-time priorities (kernel threads that
handle interrupts run at 50)."""
NOT_ASKED = "not asked"
"""The ``reason`` of a run that asked for no real-time policy (``priority`` None or 0)."""


def request(priority: int | None) -> tuple[dict, tuple | None]:
    """Ask for SCHED_FIFO at ``priority`` for the calling thread. Returns (what the run got, as
    the summary states it: ``{"policy": "fifo", "priority": p}`` or ``{"policy": "default",
    "reason": ...}``; the previous (policy, priority) to :func:`restore`, or None when nothing
    changed). ``priority`` None or 0: leave the scheduling alone."""
    if not priority:
        return {"policy": "default", "reason": NOT_ASKED}, None
    if not 1 <= int(priority) <= 99:
        raise ValueError(f"real-time priority must be 1..99 (0: off), got {priority}")
    if not hasattr(os, "SCHED_FIFO"):
        return {"policy": "default", "reason": "this system has no SCHED_FIFO"}, None
    try:
        prev = (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority)
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(int(priority)))
    except PermissionError:
        return {"policy": "default",
                "reason": "SCHED_FIFO not permitted (needs root, CAP_SYS_NICE or RLIMIT_RTPRIO)"}, None
    except OSError as e:
        return {"policy": "default", "reason": f"SCHED_FIFO refused: {e.strerror or e}"}, None
    return {"policy": "fifo", "priority": int(priority)}, prev


def restore(prev: tuple | None) -> None:
    """Put back the policy :func:`request` replaced (nothing when it replaced none)."""
    if prev is None:
        return
    try:
        os.sched_setscheduler(0, prev[0], os.sched_param(prev[1]))
    except OSError:
        pass
