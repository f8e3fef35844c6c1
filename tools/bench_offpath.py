#!/usr/bin/env python3
"""Predictions off the sample path (issue 19 point 3, ``prediction/offpath.py``): the sample
path's cost per simulated second with predictions off, inline, and in a worker thread or
process, side by side in one run.

A drive of the ``paper`` scenario (``--profile``, default ``table1-susp1k``) is simulated and
decoded once; its samples are fed to ``VdpsSystem`` (identification on, started from the model
file's parameters, ``SystemConfig.for_profile``) once per configuration, in turn, ``--repeat``
times (best of):

* ``off``: ``predict=False`` (estimator and identifier only);
* ``inline``: the 5 s prediction at 10 Hz computed on the sample path at t0 (the reference);
* ``thread/wait``, ``process/wait``: the job in a worker, the sample path waiting at the deadline
  t0 + 20 ms (a replay; no miss by construction);
* ``thread/drop``, ``process/drop``: live rule, a job not done at its deadline dropped (fed as
  fast as the sample path goes, so a deadline of 20 ms of bus time is a fraction of that in wall
  time: drops here say how far ahead of real time the sample path ran, not a live miss rate;
  ``--pace`` feeds at real time, as the bench does, and shows the live rate).

Columns (best of ``--repeat`` each): ``path CPU`` = CPU seconds of the sample path's thread
(``time.thread_time``) per simulated second [ms/s]; ``chain CPU`` = the part of it spent in the
warning chain's tick (``VdpsSystem._chain_tick``: initial state, status, submitting and
collecting the job -- and the whole prediction when inline), the figure that isolates what the
worker takes off the sample path from the rest's noise on a loaded machine; ``wall`` = wall seconds per simulated second [ms/s] (with a thread
worker it includes the GIL the worker's Python holds); ``x RT`` = simulated / wall; ``used``,
``dropped`` = predictions (last run). The load average (``os.getloadavg``) is printed before and after.

Usage::

    .venv/bin/python tools/bench_offpath.py [--duration 10] [--repeat 3] [--profile table1-susp1k] [--pace]

Measured (``--duration 5 --repeat 3``, the shared 2-core VM at load average 13-17 from other
work; totals move by +-30 ms/s between runs at that load, the chain column much less)::

    config          path CPU ms/s  chain CPU ms/s  wall ms/s    x RT  used  dropped
    off                     296.5             0.7     1197.9     0.8     0        0
    inline                  342.5            43.8     1330.5     0.8    50        0
    thread/wait             317.9            29.1     1286.5     0.8    50        0
    process/wait            275.4            27.3     1251.2     0.8    50        0
    thread/drop             306.9            29.9     1672.9     0.6    45        5
    process/drop            312.7            29.3     1286.5     0.8    42        8

The prediction (1.2-1.6 ms CPU per job here) leaves the sample path; 27-29 ms/s stay in the
chain with any worker (the initial state at every 10 ms estimate, the 50 Hz frames).
"""

from __future__ import annotations

import argparse
import io
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from vdps_hil.model.params import load_vehicle  # noqa: E402
from vdps_hil.pipeline.node import SystemConfig, VdpsSystem  # noqa: E402
from vdps_hil.record.decode import decode_recording  # noqa: E402
from vdps_hil.sim.drive import Drive  # noqa: E402

CONFIGS = {
    "off": dict(predict=False),
    "inline": dict(),
    "thread/wait": dict(prediction_worker="thread"),
    "process/wait": dict(prediction_worker="process"),
    "thread/drop": dict(prediction_worker="thread", prediction_deadline="drop"),
    "process/drop": dict(prediction_worker="process", prediction_deadline="drop"),
}


def samples_of(profile: str, duration_s: float, seed: int):
    buf = io.BytesIO()
    Drive("paper", profile=profile, seed=seed, duration_s=duration_s).run(buf)
    buf.seek(0)
    return list(decode_recording(buf))


def run_once(model, samples, susp_hz: float, kw: dict, pace: bool) -> dict:
    """Feed ``samples`` to a fresh system; the worker is started (and warmed with one job)
    before the clock runs, so its start-up is not the sample path's."""
    system = VdpsSystem(model, SystemConfig.for_profile(susp_hz, 0.001, start_params=model.params, **kw))
    if system._chain is not None and system._chain.runner.worker != "inline":
        system._chain.runner._pool.submit(int, 0).result()
    chain_cpu = [0.0]
    tick = system._chain_tick

    def timed_tick(*args, **kw):  # the warning chain's share of the sample path (its CPU)
        c = time.thread_time()
        tick(*args, **kw)
        chain_cpu[0] += time.thread_time() - c

    system._chain_tick = timed_tick
    t_first = samples[0].t_ns
    w0, c0 = time.perf_counter(), time.thread_time()
    for s in samples:
        if pace:
            lag = (s.t_ns - t_first) * 1e-9 - (time.perf_counter() - w0)
            if lag > 0:
                time.sleep(lag)
        system.handle(s)
    system.finish()
    wall, cpu = time.perf_counter() - w0, time.thread_time() - c0
    p = system.status().get("prediction", {})
    return {"wall_s": wall, "cpu_s": cpu, "chain_s": chain_cpu[0], "used": p.get("used", 0), "dropped": p.get("dropped", 0)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=10.0)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--profile", default="table1-susp1k")
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--pace", action="store_true", help="feed at real time (bus time = wall time)")
    ap.add_argument("--configs", default=",".join(CONFIGS), help="comma-separated subset of " + ",".join(CONFIGS))
    a = ap.parse_args(argv)
    names = [n for n in a.configs.split(",") if n]
    model = load_vehicle("sedan-model")
    samples = samples_of(a.profile, a.duration, a.seed)
    sim_s = (samples[-1].t_ns - samples[0].t_ns) * 1e-9
    susp_hz = 1000.0 if "susp1k" in a.profile else 1.0
    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}; {len(samples)} samples, "
          f"{sim_s:.1f} s simulated, profile {a.profile}, {'paced at real time' if a.pace else 'as fast as possible'}")
    runs: dict[str, list] = {}
    for _ in range(a.repeat):
        for n in names:  # configurations interleaved: a load change hits all of them alike
            r = run_once(model, samples, susp_hz, CONFIGS[n], a.pace)
            runs.setdefault(n, []).append(r)
    print(f"{'config':14s} {'path CPU ms/s':>14s} {'chain CPU ms/s':>15s} {'wall ms/s':>10s} {'x RT':>7s} "
          f"{'used':>5s} {'dropped':>8s}")
    for n in names:
        best = {k: min(r[k] for r in runs[n]) for k in ("cpu_s", "chain_s", "wall_s")}
        last = runs[n][-1]
        print(f"{n:14s} {1e3 * best['cpu_s'] / sim_s:14.1f} {1e3 * best['chain_s'] / sim_s:15.1f} "
              f"{1e3 * best['wall_s'] / sim_s:10.1f} {sim_s / best['wall_s']:7.1f} {last['used']:5d} {last['dropped']:8d}")
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
