"""How many pytest workers the real-time phase of ``make test`` may use: one per core the machine
leaves idle now, measured, at least one and at most the cores.

The real-time tests (``tests/conftest.py`` REALTIME_MODULES) must hold on a loaded machine, and
they hold beside one CPU-bound process when they run one module at a time. Two at a time they
take about half the wall time on a quiet machine (87 s instead of 161 s, 2026-12-06) and held
beside one CPU-bound process, but beside two such processes two logger tests lost data (README,
"make test"). So the phase runs two at a time only where the machine has the cores for it:
``/proc/stat`` over ``--window`` seconds, a core counted when at least ``--free`` of it was idle.
Prints the number (and one line on stderr saying why); prints 1 where ``/proc/stat`` cannot be
read.

    python tools/realtime_workers.py [--window 1.0] [--free 0.8]
"""

from __future__ import annotations

import argparse
import os
import sys
import time


def _cpu_times() -> tuple[int, int]:
    """(idle + iowait, total) jiffies of all CPUs, from the first line of /proc/stat."""
    with open("/proc/stat") as f:
        fields = [int(v) for v in f.readline().split()[1:]]
    idle = fields[3] + (fields[4] if len(fields) > 4 else 0)
    return idle, sum(fields[:8])  # guest times are already in user and nice


def idle_cores(window_s: float) -> float:
    """Cores' worth of idle time over the next ``window_s`` seconds."""
    i0, t0 = _cpu_times()
    time.sleep(window_s)
    i1, t1 = _cpu_times()
    if t1 <= t0:
        return 0.0
    return (i1 - i0) / (t1 - t0) * (os.cpu_count() or 1)


def workers(idle: float, cores: int, free: float) -> int:
    """One worker per ``free`` core's worth of idle time, between 1 and ``cores``."""
    return max(1, min(cores, int(idle / free + 1e-9)))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--window", type=float, default=1.0, help="seconds to measure over (default 1)")
    ap.add_argument("--free", type=float, default=0.8, help="idle share of a core that counts it (default 0.8)")
    a = ap.parse_args(argv)
    if not (0.05 <= a.window <= 60 and 0 < a.free <= 1):
        print("realtime_workers: --window must be 0.05-60 s and --free in (0, 1]", file=sys.stderr)
        return 2
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    try:
        idle = idle_cores(a.window)
    except (OSError, ValueError, IndexError):
        print(1)
        print("realtime_workers: /proc/stat unreadable: 1 worker", file=sys.stderr)
        return 0
    n = workers(idle, cores, a.free)
    print(n)
    print(f"realtime_workers: {idle:.2f} of {cores} cores idle over {a.window:g} s: {n} worker(s)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
