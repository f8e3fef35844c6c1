#!/usr/bin/env python3
"""Cost of the jackknife sigmas (``identification.jackknife``, issue 17) on the replay chain,
side by side in one run: the estimator alone, the estimator + identifier with the jackknife
(the shipped ``[status] sigma_blocks``) and without it (``sigma_blocks = 0``), on one simulated
``paper`` drive, each best of ``--repeat`` in CPU seconds of this process.

Usage::

    .venv/bin/python tools/bench_jackknife.py [--duration 20] [--repeat 3] [--profile table1-susp1k]

Prints the real-time factors and the identification's share with / without the jackknife.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import tempfile
import time

from vdps_hil.identification.config import load_ident_config
from vdps_hil.model.params import load_vehicle
from vdps_hil.pipeline.node import SystemConfig, VdpsSystem
from vdps_hil.record.decode import decode_recording
from vdps_hil.sim.drive import Drive
from vdps_hil.sim.profiles import load_profile


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=20.0)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--profile", default="table1-susp1k")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "paper.mcap")
        Drive("paper", profile=args.profile, seed=1, duration_s=args.duration).run(path)
        samples = list(decode_recording(path))
    prof = load_profile(args.profile)
    veh = load_vehicle("sedan-model", "model")
    on = load_ident_config()
    off = dataclasses.replace(on, status=dataclasses.replace(on.status, sigma_blocks=0))

    def cpu_s(ident, identify: bool) -> float:
        cfg = SystemConfig.for_profile(prof.suspension.rate_hz, prof.suspension.sigma_m, identify=identify,
                                       predict=False)
        s = VdpsSystem(veh, dataclasses.replace(cfg, ident=ident))
        t0 = time.process_time()
        for x in samples:
            s.handle(x)
        return time.process_time() - t0

    runs = {"estimator": [], "jackknife_on": [], "jackknife_off": []}
    for _ in range(args.repeat):  # interleaved: a change of the machine's load hits all three
        runs["estimator"].append(cpu_s(on, False))
        runs["jackknife_on"].append(cpu_s(on, True))
        runs["jackknife_off"].append(cpu_s(off, True))
    best = {k: min(v) for k, v in runs.items()}
    for k, v in best.items():
        print(f"{k:14s} {v:6.2f} CPU s  {args.duration / v:6.2f}x real time")
    share_on, share_off = best["jackknife_on"] - best["estimator"], best["jackknife_off"] - best["estimator"]
    print(f"identification share: {share_off:.2f} s without, {share_on:.2f} s with the jackknife "
          f"({share_on / share_off:.3f}x)")


if __name__ == "__main__":
    main()
