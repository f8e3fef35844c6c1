#!/usr/bin/env python3
"""Time per update of each identification problem (eq 20-23) and of ``Identifier.update``.

Usage: .venv/bin/python tools/bench_rls.py [--n 5000] [--seed 0]

Prints, for both RLS forms (covariance/Joseph and square-root information), the median time
of: building the regressor, one RLS update, and one full ``Identifier.update`` (all four
problems). Inputs are random excitation (the timing does not depend on their consistency).
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import time

import numpy as np

from vdps_hil.identification.config import PROBLEM_NAMES, load_ident_config
from vdps_hil.identification.identifier import Identifier
from vdps_hil.identification.inputs import IdentInputs, gravity_aux_mps2
from vdps_hil.identification.problems import REGRESSORS
from vdps_hil.model.params import load_vehicle


def random_inputs(rng: np.random.Generator, k: int) -> IdentInputs:
    slip = rng.choice([-1.0, 1.0], 4) * rng.uniform(0.006, 0.05, 4)
    steer = rng.normal(0.0, 0.05)
    speed = rng.uniform(10.0, 30.0)
    return IdentInputs(
        t_ns=k * 10_000_000, xdd_a_mps2=rng.normal(0, 1), ydd_a_mps2=rng.normal(0, 2),
        zdd_a_mps2=rng.normal(0, 0.5), xd_a_mps=speed, yd_a_mps=rng.normal(0, 0.5),
        psi_v_dot_radps=rng.normal(0, 0.2),
        gravity_aux_mps2=gravity_aux_mps2(rng.normal(0, 0.03), rng.normal(0, 0.03), rng.uniform(-3, 3)),
        omega_radps=tuple(rng.normal(0, 0.3, 3)), omega_dot_radps2=tuple(rng.normal(0, 1.0, 3)),
        susp_deflection_m=tuple(rng.normal(0, 0.02, 4)), susp_rate_mps=tuple(rng.normal(0, 0.1, 4)),
        wheel_speed_radps=tuple(speed * (1 + slip) / 0.31), wheel_accel_radps2=tuple(rng.normal(0, 5, 4)),
        wheel_torque_nm=tuple(rng.normal(0, 300, 4)), slip_ratio=tuple(slip),
        slip_angle_rad=tuple(rng.normal(0, 0.03, 4)),
        wheel_angle_rad=(steer * 1.08, steer * 0.93, 0.0, 0.0))


def _median_us(fn, n: int) -> float:
    times = []
    for _ in range(n):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e6 * statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=5000, help="updates per measurement")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    model = load_vehicle("sedan-model", "model")
    base = load_ident_config()
    rng = np.random.default_rng(args.seed)
    inputs = [random_inputs(rng, k + 1) for k in range(args.n)]
    print(f"identification benchmark: {args.n} updates, median time per call [us]")
    print(f"{'form':18s} {'problem':10s} {'regressor':>10s} {'rls update':>11s}")
    for form in ("covariance", "sqrt_information"):
        cfg = dataclasses.replace(base, form=form, upstream_min_updates=0)
        ident = Identifier(model, cfg)
        for inp in inputs[:200]:
            ident.update(inp)  # warm up: every problem full rank
        for name in PROBLEM_NAMES:
            rls = ident.problem(name)
            regs = [REGRESSORS[name](inp, model, ident.params, cfg) for inp in inputs]
            it = iter(inputs)
            t_reg = _median_us(lambda: REGRESSORS[name](next(it), model, ident.params, cfg), args.n)
            rit = iter(regs)

            def one():
                r = next(rit)
                rls.update(r.a, r.b, r.rows, db_dtheta=r.db_dup)
            t_rls = _median_us(one, args.n)
            print(f"{form:18s} {name:10s} {t_reg:10.1f} {t_rls:11.1f}")
        ident = Identifier(model, cfg)
        it = iter(inputs)
        t_all = _median_us(lambda: ident.update(next(it)), args.n)
        print(f"{form:18s} {'Identifier.update (all four)':29s} {t_all:10.1f}")


if __name__ == "__main__":
    main()
