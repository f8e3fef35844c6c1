"""Benchmark: the compiled physics core, prediction loop and simulator steps against their Python
reference (``VDPS_JIT=0``), side by side in one run, and what a command pays for compilation
after ``python -m vdps_hil.jit --warm`` (the bench's own workloads and ``vdps sim paper
--duration 2``).

Usage::

    .venv/bin/python tools/bench_jit.py [--repeat 7] [--sim-seconds 10] [--json FILE]

Each side runs in its own child process (``VDPS_JIT=1`` then ``VDPS_JIT=0``, the same
workloads, the load average printed before and after):

* ``Model.f``: one evaluation of the truth model's core (the paper's effect set: Magic Formula
  tire), from Python, median of 2000 [us];
* one 5 s prediction (paper-left-turn from t0 = 10.25 s, the configured ROS2 predictor on the
  reduced core), and the same on the generic core path (``Predictor(fast=False)``: every step
  calls ``Model.f``), CPU time, best of ``--repeat`` [ms];
* the simulator's physics (``Simulator(paper).step_to(T)``, truth model, Heun at 1 ms, 100 Hz
  snapshots), with and without the sensors' per-step recorder: real-time factor (CPU time).

Each child also prints a SHA-256 of its outputs (prediction states and loads, every truth
snapshot and recorder row): the compiled side run twice must give the same digest (same input,
same bits), and the digest equals the Python side's (the compiled forms are the reference bit
for bit). Compilation: a fresh numba cache directory, ``--warm`` timed, then the compiled child
run on that cache: seconds spent in numba compilation (numba's ``numba:compile`` event; 0 when
every kernel came from the cache) and cache misses.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _child(repeat: int, sim_seconds: float) -> dict:
    """The workloads in this process (its VDPS_JIT decides compiled or Python)."""
    import numba.core.event as ev

    compile_timer = ev.TimingListener()
    ev.register("numba:compile", compile_timer)
    t_start = time.perf_counter()
    sys.path.insert(0, str(REPO))
    import numpy as np

    from vdps_hil import jit
    from vdps_hil.experiments.truth_init import initial_state_from_truth
    from vdps_hil.model.params import load_vehicle
    from vdps_hil.prediction.predictor import Predictor
    from vdps_hil.sim.sampling import StepRecorder
    from vdps_hil.sim.scenarios import load_scenario
    from vdps_hil.sim.simulator import Simulator

    digest = hashlib.sha256()
    out: dict = {"jit": jit.ENABLED}
    sc = load_scenario("paper-left-turn")
    sim = Simulator(scenario=sc)
    sim.step_to(10.25 + 1e-9)
    init = initial_state_from_truth(sim.snapshot())
    vehicle = load_vehicle("sedan-model").with_params(**sc.vehicle.params.as_dict())
    x, u, env = list(sim.x), sim.current_inputs(), sim.env
    f = sim.model.f
    ts = []
    for _ in range(2000):
        t = time.perf_counter()
        f(x, u, env)
        ts.append(time.perf_counter() - t)
    out["model_f_us"] = statistics.median(ts) * 1e6
    for key, fast in (("prediction_ms", True), ("prediction_generic_ms", False)):
        pred = Predictor(vehicle, fast=fast)
        best, r = float("inf"), None
        for _ in range(repeat if fast else max(1, repeat // 3)):
            t = time.process_time()
            r = pred.predict(init)
            best = min(best, time.process_time() - t)
        out[key] = best * 1e3
        digest.update(np.ascontiguousarray(r.pos_g_m).tobytes() + np.ascontiguousarray(r.normal_load_n).tobytes())
    for key, recorder in (("sim_rtf", False), ("sim_recorder_rtf", True)):
        s = Simulator(scenario=load_scenario("paper"))
        rec = StepRecorder(s) if recorder else None
        t = time.process_time()
        s.step_to(sim_seconds)
        out[key] = s.t_s / (time.process_time() - t)
        digest.update(json.dumps(s.truth, sort_keys=True).encode())
        if rec is not None:
            digest.update(rec.take().a.tobytes())
    out["digest"] = digest.hexdigest()[:16]
    out["compile_s"] = compile_timer.duration if compile_timer.done else 0.0
    out["wall_s"] = time.perf_counter() - t_start
    if jit.ENABLED:
        from numba.core.registry import CPUDispatcher
        import gc

        out["cache_misses"] = sum(sum(d.stats.cache_misses.values()) for d in gc.get_objects()
                                  if isinstance(d, CPUDispatcher) and getattr(d, "_cache", None) is not None
                                  and d.__module__.startswith("vdps_hil"))
    return out


def _run_child(env_extra: dict, args) -> dict:
    env = dict(os.environ, **env_extra)
    cmd = [sys.executable, __file__, "--child", "--repeat", str(args.repeat), "--sim-seconds", str(args.sim_seconds)]
    return json.loads(subprocess.run(cmd, env=env, capture_output=True, text=True, check=True).stdout)


_CLI = ("import atexit, sys, numba.core.event as ev; t = ev.TimingListener(); ev.register('numba:compile', t); "
        "atexit.register(lambda: print(f'compile_s={t.duration if t.done else 0.0}', file=sys.stderr)); "
        "from vdps_hil.cli.main import entry; sys.argv[0] = 'vdps'; entry()")


def _cli_compile_s(cache: str, out_dir: str) -> tuple[float, float]:
    """(seconds compiling, seconds wall) of ``vdps sim paper --duration 2`` on the cache ``cache``."""
    t = time.perf_counter()
    r = subprocess.run([sys.executable, "-c", _CLI, "sim", "paper", "--duration", "2", "-o",
                        os.path.join(out_dir, "paper.mcap")], cwd=out_dir, capture_output=True, text=True, check=True,
                       env=dict(os.environ, NUMBA_CACHE_DIR=cache, VDPS_JIT="1"))
    wall = time.perf_counter() - t
    return float(r.stderr.rsplit("compile_s=", 1)[1].split()[0]), wall


def _load() -> str:
    return "load average " + " ".join(f"{v:.2f}" for v in os.getloadavg())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--sim-seconds", type=float, default=10.0)
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        print(json.dumps(_child(args.repeat, args.sim_seconds)))
        return 0
    print(f"before: {_load()}")
    with tempfile.TemporaryDirectory(prefix="vdps-numba-") as cache:
        t = time.perf_counter()
        subprocess.run([sys.executable, "-m", "vdps_hil.jit", "--warm"], cwd=REPO, check=True, capture_output=True,
                       env=dict(os.environ, NUMBA_CACHE_DIR=cache, VDPS_JIT="1"))
        warm_s = time.perf_counter() - t
        on = _run_child({"VDPS_JIT": "1", "NUMBA_CACHE_DIR": cache}, args)
        off = _run_child({"VDPS_JIT": "0"}, args)
        again = _run_child({"VDPS_JIT": "1", "NUMBA_CACHE_DIR": cache}, args)
        with tempfile.TemporaryDirectory(prefix="vdps-sim-") as tmp:
            cli_compile, cli_wall = _cli_compile_s(cache, tmp)
    print(f"after:  {_load()}")
    print(f"--warm into a fresh cache: {warm_s:.1f} s; the compiled run after it: {on['compile_s']:.2f} s compiling, "
          f"{on['cache_misses']} cache misses, {on['wall_s']:.1f} s wall in all; `vdps sim paper --duration 2`: "
          f"{cli_compile:.2f} s compiling, {cli_wall:.1f} s wall")
    print(f"{'':34s} {'compiled':>10s} {'VDPS_JIT=0':>10s} {'ratio':>7s}")
    rows = (("Model.f, one call [us]", "model_f_us", False), ("5 s prediction [ms]", "prediction_ms", False),
            ("5 s prediction, generic core [ms]", "prediction_generic_ms", False),
            ("simulator physics [x real time]", "sim_rtf", True), ("  with the recorder [x real time]", "sim_recorder_rtf", True))
    for label, key, higher in rows:
        a, b = min(on[key], again[key]) if not higher else max(on[key], again[key]), off[key]
        print(f"{label:34s} {a:10.2f} {b:10.2f} {(a / b if higher else b / a):6.1f}x")
    same = on["digest"] == again["digest"] == off["digest"]
    print(f"output digests: compiled {on['digest']}, again {again['digest']}, VDPS_JIT=0 {off['digest']}"
          f" -> {'bit-identical' if same else 'DIFFERENT'}")
    if args.json:
        args.json.write_text(json.dumps({"warm_s": warm_s, "cli_compile_s": cli_compile, "cli_wall_s": cli_wall, "compiled": on, "compiled_again": again, "python": off},
                                        indent=2))
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
