"""Benchmark: real-time factor of ``vdps sim paper`` with every sensor on (profile
``table1-susp1k``: IMU 1 kHz, tachometers 1 kHz, suspension 1 kHz, torque and steering 100 Hz,
GNSS 5 Hz) on one core, and where the time goes.

Usage::

    .venv/bin/python tools/bench_sim_drive.py [--scenario paper] [--profile table1-susp1k]
                                              [--repeat 3] [--json FILE] [--baseline REF [--rounds 3]]

It measures, best of ``--repeat`` runs each:

* ``physics``: the simulator alone (``Simulator(scenario).run()``, truth snapshots computed but
  not kept), the floor for any drive;
* ``physics + recorder``: the same with the sensors' per-step truth recorder hooked in;
* ``drive without recording``: the drive's session into a sink that keeps nothing
  (``sim.sinks.DriveSink``): physics, sensor models and wire encoding (CAN frames, MTData2
  packets, NMEA sentences, serial read chunks), no MCAP;
* the full drive (``sim.drive.Drive.run`` to a file in a temporary directory), with its own
  split: physics and recorder, truth writing (/truth/state JSON), sensor models and encoding,
  CAN writing (one MCAP message per frame), serial writing (read chunks);
* the CLI end to end (``vdps sim`` in a subprocess, Python start-up and imports included).

``--baseline REF`` (a git ref, e.g. ``main``) adds a side-by-side comparison in the same run:
the tree of REF (``git archive`` into a temporary directory, its own numba cache there) and
this tree each run ``Drive.run`` in a fresh process (one warm-up drive, then ``--repeat``
drives), alternating ``--rounds`` times; the figure is the least CPU time
(``time.process_time``) of a drive per tree, and its real-time factor.

The process is pinned to one CPU where the OS allows it. First bar: RTF >= 10; goal: 50.

Last measured (``--baseline main --repeat 3 --rounds 3``, shared 2-core VM at load average 5-6,
CPU time): ``Drive.run`` main 0.610 s (24.6x real time), this tree 0.433 s (34.6x, 1.41x
faster); without recording 0.160 s / 0.158 s (94x).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from vdps_hil.sim.drive import Drive  # noqa: E402
from vdps_hil.sim.scenarios import load_scenario  # noqa: E402
from vdps_hil.sim.sampling import StepRecorder  # noqa: E402
from vdps_hil.sim.simulator import Simulator  # noqa: E402
from vdps_hil.sim.sinks import DriveSink  # noqa: E402


def pin_one_core() -> str:
    if hasattr(os, "sched_setaffinity"):
        cpu = min(os.sched_getaffinity(0))
        os.sched_setaffinity(0, {cpu})
        return f"pinned to CPU {cpu}"
    return "not pinned (no sched_setaffinity)"


def best(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


_MEASURE = r"""
import json, os, sys, tempfile, time
sys.path.insert(0, sys.argv[1])
from vdps_hil.sim.drive import Drive
from vdps_hil.sim.scenarios import load_scenario
from vdps_hil.sim.sinks import DriveSink
sc = load_scenario(sys.argv[2])
out = os.path.join(tempfile.mkdtemp(), "bench.mcap")
runs, bare = [], []
for _ in range(int(sys.argv[4]) + 1):
    c0 = time.process_time()
    session = Drive(sc, profile=sys.argv[3], seed=0).start(DriveSink())
    while session.advance():
        pass
    bare.append(time.process_time() - c0)
    c0, w0 = time.process_time(), time.perf_counter()
    s = Drive(sc, profile=sys.argv[3], seed=0).run(out)
    runs.append((time.process_time() - c0, time.perf_counter() - w0))
os.remove(out)
print(json.dumps({"duration_s": s.duration_s, "runs": runs[1:], "bare": bare[1:]}))
"""


def side_by_side(ref: str, scenario: str, profile: str, repeat: int, rounds: int) -> dict:
    """Least CPU time of ``Drive.run`` (and wall time of that run) and of the drive without
    recording, with the tree of git ``ref`` and with this tree, in alternating fresh processes
    (module docstring): {tree: (cpu_s, wall_s, bare_cpu_s, duration_s)}."""
    runs: dict[str, list] = {ref: [], "this tree": []}
    bare: dict[str, list] = {ref: [], "this tree": []}
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(tmp) / "baseline"
        base.mkdir()
        archive = subprocess.run(["git", "-C", str(REPO), "archive", ref], capture_output=True, check=True)
        subprocess.run(["tar", "-x", "-C", str(base)], input=archive.stdout, check=True)
        trees = {ref: (base, dict(os.environ, NUMBA_CACHE_DIR=str(Path(tmp) / "numba"))),
                 "this tree": (REPO, dict(os.environ))}
        for _ in range(rounds):
            for name, (tree, env) in trees.items():
                r = subprocess.run([sys.executable, "-c", _MEASURE, str(tree), scenario, profile, str(repeat)],
                                   cwd=tmp, env=env, capture_output=True, text=True)
                if r.returncode != 0:
                    raise RuntimeError(f"{name}: {r.stderr.strip().splitlines()[-1:]}")
                doc = json.loads(r.stdout.strip().splitlines()[-1])
                runs[name] += [(cpu, wall, doc["duration_s"]) for cpu, wall in doc["runs"]]
                bare[name] += doc["bare"]
    return {name: (*min(runs[name])[:2], min(bare[name]), runs[name][0][2]) for name in runs}


def print_side_by_side(res: dict) -> None:
    print("  side by side (one run, alternating fresh processes; least CPU time of a drive):")
    print(f"  {'tree':<14} {'drive CPU [s]':>13} {'(wall [s])':>10} {'ms/sim s':>9} {'RTF':>6}   "
          f"{'no recording CPU [s]':>20} {'ms/sim s':>9} {'RTF':>6}")
    for name, (cpu, wall, bare, dur) in res.items():
        print(f"  {name:<14} {cpu:13.3f} {wall:10.3f} {1000 * cpu / dur:9.1f} {dur / cpu:6.1f}   "
              f"{bare:20.3f} {1000 * bare / dur:9.1f} {dur / bare:6.1f}")
    (c0, _, b0, _), (c1, _, b1, _) = res.values()
    print(f"  this tree / baseline CPU time: drive {c1 / c0:.3f} ({c0 / c1:.2f}x faster), "
          f"no recording {b1 / b0:.3f} ({b0 / b1:.2f}x faster)")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="paper")
    ap.add_argument("--profile", default="table1-susp1k")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--json", default=None, help="write the figures to FILE")
    ap.add_argument("--baseline", default=None, help="git ref to compare with, side by side (e.g. main)")
    ap.add_argument("--rounds", type=int, default=3, help="alternations of baseline and this tree")
    a = ap.parse_args()
    pin = pin_one_core()
    sbs = side_by_side(a.baseline, a.scenario, a.profile, a.repeat, a.rounds) if a.baseline else None
    sc = load_scenario(a.scenario)
    dur = sc.duration_s

    def physics():
        Simulator(scenario=sc, record_truth=False).run()

    def physics_recorder():
        sim = Simulator(scenario=sc, record_truth=False)
        rec = StepRecorder(sim)
        while sim.n < round(dur * 1000) and not sim.stopped:
            sim.step()
            if sim.n % 500 == 0:
                rec.take()

    def no_recording():
        session = Drive(sc, profile=a.profile, seed=0).start(DriveSink())
        while session.advance():
            pass

    t_phys = best(physics, a.repeat)
    t_rec = best(physics_recorder, a.repeat)
    t_norec = best(no_recording, a.repeat)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "bench.mcap"
        runs = []
        for _ in range(a.repeat):
            s = Drive(sc, profile=a.profile, seed=0).run(out)
            runs.append(s)
        s = min(runs, key=lambda x: x.wall_time_s)
        size = out.stat().st_size
        t0 = time.perf_counter()
        cli = subprocess.run([sys.executable, "-c", "from vdps_hil.cli.main import entry; entry()",
                              "sim", a.scenario, "--profile", a.profile, "-o", str(out)],
                             cwd=REPO, capture_output=True, text=True)
        t_cli = time.perf_counter() - t0
        if cli.returncode != 0:
            print(cli.stderr, file=sys.stderr)
            return 1
    tm = s.timing_s
    n_msgs = sum(s.messages.values())
    rows = [("physics alone (simulator)", t_phys),
            ("physics + per-step recorder", t_rec),
            ("drive without recording (null sink)", t_norec),
            ("drive: physics + recorder", tm["physics_and_recorder"]),
            ("drive: /truth/state writing", tm["truth_write"]),
            ("drive: sensor models + encoding", tm["sensors"]),
            ("drive: CAN frame writing", tm["can_write"]),
            ("drive: serial chunk writing", tm["serial_write"]),
            ("drive: total", s.wall_time_s),
            ("vdps sim (CLI, start-up included)", t_cli)]
    print(f"bench_sim_drive: scenario {a.scenario} ({dur:g} s simulated), profile {a.profile}, "
          f"best of {a.repeat}, {pin}")
    print(f"  {'part':<36} {'wall [s]':>9} {'ms per sim s':>13} {'RTF':>8}")
    for name, t in rows:
        print(f"  {name:<36} {t:9.3f} {1000 * t / dur:13.1f} {dur / t:8.1f}")
    print(f"  messages {n_msgs} ({n_msgs / dur:.0f} per simulated s, "
          f"{1e6 * tm['can_write'] / max(s.messages.get('/raw/can/vdps', 1), 1):.1f} us per CAN frame), "
          f"file {size / 1e6:.1f} MB")
    rtf = dur / s.wall_time_s
    print(f"  real-time factor {rtf:.1f}x: first bar 10x {'met' if rtf >= 10 else 'NOT met'}, "
          f"goal 50x {'met' if rtf >= 50 else 'not met'}")
    if sbs:
        print_side_by_side(sbs)
    if a.json:
        doc = {"scenario": a.scenario, "profile": a.profile, "duration_s": dur,
               "rtf": rtf, "rtf_cli": dur / t_cli, "physics_s": t_phys, "no_recording_s": t_norec, "physics_recorder_s": t_rec,
               "drive_timing_s": tm, "drive_wall_s": s.wall_time_s, "messages": s.messages,
               "file_bytes": size,
               "side_by_side": {k: {"cpu_s": v[0], "wall_s": v[1], "no_recording_cpu_s": v[2], "duration_s": v[3]}
                                for k, v in (sbs or {}).items()}}
        Path(a.json).write_text(json.dumps(doc, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
