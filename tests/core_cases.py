"""Random evaluation points of the physics core, shared by the tests that compare two forms of
it (the specialised reduced core, the compiled core): a state near trim with perturbed pose,
rates and slips, random steering, drive and brake torques, a banked and graded road."""

import random

from vdps_hil.model.core import Env, Inputs, Model


def random_case(model: Model, rng: random.Random, lift: bool, wind: bool = False):
    """(x, u, env) at 5-30 m/s with perturbed attitude, rates, slips (a large roll when ``lift``,
    so wheels leave the ground), random steering, drive torques and brakes, and a road; with
    ``wind`` an ambient wind, and for the truth model perturbed unsprung deflections and rates."""
    env = Env(rng.uniform(-0.08, 0.08), rng.uniform(-0.08, 0.08))
    x = model.design_state(rng.uniform(5.0, 30.0), env, heading_rad=rng.uniform(-3.0, 3.0))
    x[3] += rng.gauss(0.0, 0.3 if lift else 0.02)
    x[4] += rng.gauss(0.0, 0.02)
    for j in (0, 1, 2):
        x[j] += rng.gauss(0.0, 0.02)  # heave: loads from compressed to unloaded
    for j in (7, 8, 9, 10, 11):
        x[j] += rng.gauss(0.0, 0.5)
    for j in range(12, 16):
        x[j] *= 1.0 + rng.gauss(0.0, 0.05)
    brakes = [rng.uniform(0.0, 800.0) if rng.random() < 0.5 else 0.0 for _ in range(4)]
    u = Inputs(rng.uniform(-3.0, 3.0), [rng.gauss(0.0, 400.0) for _ in range(4)], brakes)
    if model.unsprung_dof:
        for j in range(16, 24):
            x[j] += rng.gauss(0.0, 0.01 if j < 20 else 0.3)
    if wind:
        env = Env(env.bank_rad, env.grade_rad, (rng.gauss(0.0, 8.0), rng.gauss(0.0, 8.0), 0.0))
    return x, u, env
