"""Benchmark: real-time factor of the CommonRoad truth backend (``vdps sim --truth
commonroad-mb:N``), simulated seconds per CPU second of this process, beside our own simulator on
the same scenario.

Usage::

    .venv/bin/python tools/bench_truth_cr.py [--scenario cr-sine-accel] [--duration S]
                                            [--sets 1 3] [--integrators rk2 rk4] [--json FILE]

For each truth (ours, then ``commonroad-mb:N`` per set and integrator) it measures:

* ``physics``: the truth alone (``CommonRoadTruth(...).run()`` / ``Simulator(...).run()``,
  snapshots computed and kept);
* ``drive``: the whole ``sim.drive.Drive.run`` to a recording in a temporary directory (every
  sensor of profile ``table1-susp1k`` on its wire format).

CPU time (``time.process_time``) is reported, not wall time: the 2-core machine is shared. The
process is pinned to one CPU where the OS allows it.

Last measured (2026-12-01, ``--integrators rk2 rk4 --duration 20``, cr-sine-accel; this 2-core
VM shared with other sessions, load average 12-15, so CPU seconds are inflated by contention;
compare the rows of one run)::

    truth                   physics   drive (table1-susp1k)
    ours (sedan-truth)      16.0x     8.1x
    commonroad-mb:1 rk2      8.6x     5.0x      (the backend's default)
    commonroad-mb:1 rk4      4.4x
    commonroad-mb:3 rk2      8.0x     5.0x
    commonroad-mb:3 rk4      5.0x

The package's right-hand side costs about 75 us per evaluation in pure Python (its 16 tire
calls, plus our 8 for the mirror-symmetric combined slip); RK2 needs two evaluations per 1 ms
step above 8.2 m/s (one sub-step). A 60 s drive on the CommonRoad truth is about 12 CPU seconds.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tools"))  # its sibling tools, also in safe-path mode (-P)

from vdps_hil.sim.drive import Drive  # noqa: E402
from vdps_hil.sim.scenarios import load_scenario  # noqa: E402
from vdps_hil.sim.simulator import Simulator  # noqa: E402
from vdps_hil.sim.truth_cr import CommonRoadTruth  # noqa: E402

from bench_sim_drive import pin_one_core  # noqa: E402  (tools/, inserted above)


def cpu_s(fn) -> float:
    t0 = time.process_time()
    fn()
    return time.process_time() - t0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="cr-sine-accel")
    ap.add_argument("--duration", type=float, default=10.0, help="simulated seconds (default 10)")
    ap.add_argument("--sets", type=int, nargs="+", default=[1, 3])
    ap.add_argument("--integrators", nargs="+", default=["rk2"], choices=["rk2", "rk4"])
    ap.add_argument("--json", default=None, help="write the figures to FILE")
    a = ap.parse_args()
    pin = pin_one_core()
    sc = load_scenario(a.scenario)
    dur = a.duration
    rows = []

    def record(truth, physics, drive, note=""):
        rows.append({"truth": truth, "physics_rtf": dur / physics, "drive_rtf": (dur / drive) if drive else None,
                     "physics_cpu_s": physics, "drive_cpu_s": drive, "note": note})
        d = f"{dur / drive:6.2f}" if drive else "     -"
        print(f"{truth:<26} physics {dur / physics:6.2f}x   drive {d}x   {note}", flush=True)

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "d.mcap"
        record("ours", cpu_s(lambda: Simulator(scenario=sc).run(dur)),
               cpu_s(lambda: Drive(sc, duration_s=dur).run(out)))
        for set_id in a.sets:
            for integ in a.integrators:
                sims = []

                def phys():
                    s = CommonRoadTruth(set_id, sc, integrator=integ)
                    s.run(dur)
                    sims.append(s)
                p = cpu_s(phys)
                d = cpu_s(lambda: Drive(sc, duration_s=dur, truth=f"commonroad-mb:{set_id}").run(out)) \
                    if integ == "rk2" else None
                record(f"commonroad-mb:{set_id} {integ}", p, d, f"max sub-steps {sims[-1].max_substeps}")
    doc = {"scenario": a.scenario, "duration_s": dur, "pinning": pin, "rows": rows}
    print(f"({pin}; CPU seconds of this process; the drive uses the backend's default integrator rk2)")
    if a.json:
        Path(a.json).write_text(json.dumps(doc, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
