#!/usr/bin/env python3
"""Batch engine benchmark: speed-up from 1 to N workers on a local Dask cluster for a set of
simulated drives, peak memory per worker, and (``--memory FILE``) the memory of one worker
replaying one long recording (``tools/make_long_drive.py``).

Usage:
  .venv/bin/python tools/bench_batch.py [--drives 8] [--duration 10] [--workers 1 2]
                                        [--dir /tmp/vdps-bench-batch] [--backend dask]
  .venv/bin/python tools/bench_batch.py --memory long-drive.mcap [--poll 2] [--max-wall S]
                                        [--fix-pipeline-log] [--log]

Speed-up: the same ``vdps batch replay`` tasks (``system.replay_file`` per drive) on a fresh
LocalCluster of 1 and of N worker processes; times are the batch alone (cluster start-up
reported separately) and the speed-up is T(1) / T(N). The results of every run are checked to
be identical apart from the timing fields.

On a shared machine the wall-clock speed-up is only meaningful when nothing else runs (the
load average is printed before and after). The CPU time of every task (``run.cpu_s``) depends
little on contention, so the tool also prints a contention-free estimate: the 1-worker run's
total task CPU over the makespan of the largest-first schedule of the N-worker run's task CPU
times on N workers (labelled as an estimate: it leaves out the scheduler and the client, which
are idle between tasks, and memory-bandwidth sharing between the cores).

Memory: ``run.peak_rss_mib`` of each task is the worker process's peak resident set
(``getrusage``), so the maximum over a worker's tasks is that worker's peak. With ``--memory``
one task runs on a 1-worker cluster while this process samples the worker's RSS (psutil)
every ``--poll`` seconds: the curve shows whether memory grows with the drive (it must not).

Measured (this 2-core VM, quiet: load average 0.4 before the run)
-----------------------------------------------------------------
``bench_batch.py --drives 8 --duration 10 --workers 1 2``: 1 worker 31.4 s, 2 workers 16.5 s:
speed-up 1.90x (batch only; the same with cluster start-up), results identical; peak RSS per
worker 203-207 MiB; contention-free estimate from the task CPU times 1.94x.

Earlier run on the same VM while it was loaded (shared with other jobs: load average 3.6-6.9)
-----------------------------------------------------------------------------------------
8 drives of 10 s, LocalCluster: 1 worker 64.0 s, 2 workers 37.4 s: speed-up 1.71x wall
(1.67x with cluster start-up, ~1 s); results identical. Task CPU 36.2 s vs 35.7 s in total
(no per-task overhead from parallelism), split 17.8 / 17.9 s: the contention-free estimate is
2.01x; the workers got about half a core each from the shared machine (CPU share 57 % / 48 %).
Peak RSS per worker 231-238 MiB.

One-hour drive (``make_long_drive.py -o /tmp/h10/long-drive.mcap``: 'paper', table1-susp1k, seed
0, 997 MiB, 12.7 M messages), one worker, library as it is now (the estimator pipeline's log
cleared, the warning chain keeping counts and its last 100 frames/assessments,
``pipeline.node.WARNING_HISTORY``): ``bench_batch.py --memory /tmp/h10/long-drive.mcap --poll 5``:
3600 s of drive in 1507 s of worker CPU (2.39 s of drive per CPU s; 3083 s wall, load average
4-7 from other jobs), **peak RSS 328 MiB** (getrusage); RSS at 0/103/290/405/663/1025/1505 CPU s:
63 (idle worker)/266/308/327/327/327/327 MiB: it rises over the first ~16 min of drive, then
stays at 327 MiB to the end (growth 0 MiB over the last ~44 min of drive).

Before the warning-chain bound (same drive and machine, with ``--fix-pipeline-log``): 1587 s of
worker CPU (2.27 s of drive per CPU s), peak RSS 359 MiB (RSS at 1/139/345/729/1065/1585 CPU
s: 125/257/299/328/342/358 MiB; the remaining slope, ~55 MiB per hour of drive, was the warning
chain keeping every sent frame and assessment: ~230 B each, 50 frames/s).
Before the pipeline-log fix the worker grew by ~3.4 MiB per CPU s (1.55 GiB after 389 CPU s,
stopped there): extrapolated ~5.6 GiB for the hour (an extrapolation, not a measurement):
``EstimatorPipeline`` appended every sample to its replay log and ``VdpsSystem.clear_input_log``
did not clear it (it does now; ``--fix-pipeline-log`` is kept for the comparison).

Diagnose (not this tool: ``vdps_hil.batch.tasks.diagnose_drive`` in one process,
with_simulation off, drives from ``make_long_drive.py --duration 30/60/120``): peak RSS
637 / 2438 / 10527 MiB. The workbench holds every decoded sample (~2 MiB per second of drive)
and its ranking's dense columns grow with the square of the drive length: a one-hour drive
cannot be diagnosed in one piece (``batch.tasks`` docstring).
"""

from __future__ import annotations

import argparse
import os
import sys
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from vdps_hil.batch.engine import Engine, EngineConfig  # noqa: E402
from vdps_hil.batch.runner import strip_run  # noqa: E402
from vdps_hil.batch.tasks import replay_tasks  # noqa: E402


def make_drives(d: Path, n: int, duration_s: float) -> list[str]:
    from vdps_hil.sim.drive import Drive

    d.mkdir(parents=True, exist_ok=True)
    paths = []
    for seed in range(n):
        p = d / f"paper-{duration_s:g}s-seed{seed}.mcap"
        if not p.exists():
            tmp = p.with_suffix(".tmp")
            Drive("paper", seed=seed, duration_s=duration_s).run(tmp)
            os.replace(tmp, p)
        paths.append(os.fspath(p))
    return paths


def run_once(paths: list[str], backend: str, workers: int, trace_memory: bool = False) -> dict:
    tasks = replay_tasks(paths)
    t0 = time.perf_counter()
    with Engine(EngineConfig(backend=backend, workers=workers, dashboard=False,
                             trace_memory=trace_memory)) as eng:
        t1 = time.perf_counter()
        outcomes = list(eng.run(tasks))
        t2 = time.perf_counter()
    bad = [o for o in outcomes if not o.ok]
    if bad:
        raise SystemExit(f"{len(bad)} task(s) failed: {bad[0].id}: {bad[0].error}")
    per_pid: dict[int, dict] = {}
    for o in outcomes:
        w = per_pid.setdefault(o.run["pid"], {"tasks": 0, "busy_s": 0.0, "cpu_s": 0.0,
                                              "peak_rss_mib": 0.0, "py_heap_peak_mib": 0.0})
        w["tasks"] += 1
        w["busy_s"] += o.run["wall_s"]
        w["cpu_s"] += o.run["cpu_s"]
        w["peak_rss_mib"] = max(w["peak_rss_mib"], o.run["peak_rss_mib"])
        w["py_heap_peak_mib"] = max(w["py_heap_peak_mib"], o.run.get("py_heap_peak_mib", 0.0))
    return {"startup_s": t1 - t0, "batch_s": t2 - t1, "workers": per_pid,
            "task_cpu_s": sorted((o.run["cpu_s"] for o in outcomes), reverse=True),
            "results": {o.id: strip_run(o.result) for o in outcomes}}


def lpt_makespan(costs: list[float], n: int) -> float:
    """Makespan of the longest-processing-time-first schedule of ``costs`` on ``n`` workers
    (what the engine's largest-first submission does on an idle machine)."""
    loads = [0.0] * n
    for c in sorted(costs, reverse=True):
        i = loads.index(min(loads))
        loads[i] += c
    return max(loads)


def speedup(args) -> None:
    paths = make_drives(Path(args.dir), args.drives, args.duration)
    print(f"bench_batch: {args.drives} drives of {args.duration:g} s ('paper', table1-susp1k), "
          f"backend {args.backend}, {os.cpu_count()} CPU(s), load average before "
          f"{os.getloadavg()[0]:.1f}")
    runs = {}
    for n in args.workers:
        r = run_once(paths, args.backend, n)
        runs[n] = r
        peaks = ", ".join(f"{w['peak_rss_mib']:.0f}" for w in r["workers"].values())
        cpu = [w["cpu_s"] for w in r["workers"].values()]
        r["cpu_total_s"], r["cpu_makespan_s"] = sum(cpu), max(cpu)
        print(f"  {n} worker(s): start-up {r['startup_s']:5.1f} s, batch {r['batch_s']:6.1f} s "
              f"({args.drives * args.duration / r['batch_s']:.2f} s of drive per s), "
              f"{len(r['workers'])} worker process(es) used, peak RSS per worker [MiB]: {peaks}; "
              f"task CPU {sum(cpu):.1f} s (per worker {', '.join(f'{c:.1f}' for c in cpu)}), "
              f"CPU share of the worker time {sum(cpu) / (n * r['batch_s']):.0%}; "
              f"load average after {os.getloadavg()[0]:.1f}")
    base = runs[args.workers[0]]
    for n in args.workers[1:]:
        r = runs[n]
        same = r["results"] == base["results"]
        print(f"  speed-up {args.workers[0]} -> {n} workers: {base['batch_s'] / r['batch_s']:.2f}x "
              f"(batch only), {(base['batch_s'] + base['startup_s']) / (r['batch_s'] + r['startup_s']):.2f}x "
              f"(with start-up); results identical: {same}")
        est = sum(base["task_cpu_s"]) / lpt_makespan(r["task_cpu_s"], n)
        print(f"  contention-free estimate from task CPU times: {est:.2f}x (sum of the 1-worker "
              f"run's task CPU / the largest-first schedule of this run's task CPU on {n} "
              f"workers; an estimate for an otherwise idle machine, not a measurement)")


def _patch_pipeline_log() -> str:
    """Run on the worker with ``--fix-pipeline-log``: make ``VdpsSystem.clear_input_log`` also
    clear the estimator pipeline's own replay log (``EstimatorPipeline.input_log``), which a file
    replay otherwise keeps for the whole drive (an experiment of this tool, not the library)."""
    from vdps_hil.pipeline.node import VdpsSystem

    orig = VdpsSystem.clear_input_log
    if getattr(orig, "_bench_patched", False):
        return "already patched"

    def clear_input_log(self):
        orig(self)
        self.pipeline.clear_input_log()
    clear_input_log._bench_patched = True
    VdpsSystem.clear_input_log = clear_input_log
    return "patched"


def memory(args) -> None:
    import psutil

    from vdps_hil.batch.worker import execute

    path = args.memory
    size = os.path.getsize(path)
    print(f"bench_batch --memory: {path} ({size / 2**20:.0f} MiB), 1 worker, RSS sampled every "
          f"{args.poll:g} s" + (", pipeline log cleared (--fix-pipeline-log)" if args.fix_pipeline_log else "")
          + (f", stopped after {args.max_wall:g} s" if args.max_wall else ""), flush=True)
    (task,) = replay_tasks([path], options={"predict": not args.no_predict})
    samples: list[tuple[float, float, float]] = []
    with Engine(EngineConfig(backend="dask", workers=1, dashboard=False)) as eng:
        (pid,) = eng.worker_pids()
        if args.fix_pipeline_log:
            eng.client.run(_patch_pipeline_log)
        proc = psutil.Process(pid)
        base_rss = proc.memory_info().rss / 2**20
        stop = threading.Event()
        t0 = time.perf_counter()

        def poll():
            while not stop.is_set():
                try:
                    samples.append((time.perf_counter() - t0, proc.cpu_times().user + proc.cpu_times().system,
                                    proc.memory_info().rss / 2**20))
                except psutil.Error:
                    return
                if args.log:
                    t, c, r = samples[-1]
                    print(f"    t {t:7.0f} s  cpu {c:7.0f} s  rss {r:6.0f} MiB", flush=True)
                stop.wait(args.poll)

        th = threading.Thread(target=poll, daemon=True)
        th.start()
        fut = eng.client.submit(execute, task.fn, dict(task.kwargs), False, (), pure=False)
        try:
            doc = fut.result(timeout=args.max_wall) if args.max_wall else fut.result()
        except TimeoutError:
            doc = None
            fut.cancel()
        stop.set()
        th.join()
    if doc is not None and doc["status"] != "ok":
        raise SystemExit(f"task failed: {doc['error']}")
    if doc is not None:
        dur = doc["result"]["duration_s"]
        print(f"  replayed {dur:.0f} s of drive in {doc['run']['wall_s']:.0f} s wall, "
              f"{doc['run']['cpu_s']:.0f} s CPU ({dur / doc['run']['cpu_s']:.2f} s of drive per CPU s); "
              f"idle worker RSS {base_rss:.0f} MiB")
        print(f"  worker peak RSS (getrusage): {doc['run']['peak_rss_mib']:.0f} MiB")
    else:
        print(f"  stopped after {args.max_wall:g} s (partial: the curve below covers the part replayed); "
              f"idle worker RSS {base_rss:.0f} MiB")
    if samples:
        n = len(samples)
        marks = sorted({0, n // 10, n // 4, n // 2, 3 * n // 4, n - 1})
        print("  RSS over the replay [worker CPU s: MiB]: "
              + ", ".join(f"{samples[i][1]:.0f}: {samples[i][2]:.0f}" for i in marks))
        h = n // 2
        first_half = max(r for _, _, r in samples[:max(h, 1)])
        second_half = max(r for _, _, r in samples[h:])
        cpu_span = samples[-1][1] - samples[h][1]
        print(f"  max RSS first half {first_half:.0f} MiB, second half {second_half:.0f} MiB "
              f"(growth {second_half - first_half:+.0f} MiB; second half spans {cpu_span:.0f} CPU s)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--drives", type=int, default=8)
    ap.add_argument("--duration", type=float, default=10.0, help="seconds per simulated drive")
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--backend", default="dask", choices=["dask", "processes"])
    ap.add_argument("--dir", default="/tmp/vdps-bench-batch", help="where the drives are written")
    ap.add_argument("--memory", metavar="FILE", default=None,
                    help="measure one worker replaying FILE instead")
    ap.add_argument("--poll", type=float, default=2.0, help="RSS sampling period [s] (--memory)")
    ap.add_argument("--no-predict", action="store_true", help="--memory: replay without predictor")
    ap.add_argument("--fix-pipeline-log", action="store_true",
                    help="--memory: clear the estimator pipeline's replay log in the worker (experiment)")
    ap.add_argument("--max-wall", type=float, default=None, metavar="S",
                    help="--memory: stop after S seconds and report the partial curve")
    ap.add_argument("--log", action="store_true", help="--memory: print every RSS sample")
    args = ap.parse_args()
    if args.memory:
        memory(args)
    else:
        speedup(args)


if __name__ == "__main__":
    main()
