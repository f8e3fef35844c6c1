"""workbench.row_kernel: every row's residuals in one compiled call equal ``RowModel.residual``
row by row, bit for bit -- the 14 residuals, the wheel-speed parts, the two velocity-nuisance
columns (forward differences of 0.02 m/s, as ``compute_residuals`` takes them) and the slip
columns -- on random rows (states near a cornering car, inputs, banked and graded roads, wind,
measured suspension on some rows and not on others) for the sedan, the CommonRoad model file
(anti-roll bar, parallel steer) and the sedan with every chassis part, each with the linear
tire, the Magic Formula tire (the slip from the tire law by Newton) and the other compiled
effects. A model whose core is not compiled has no packed arrays (the per-row path runs)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from vdps_hil import jit
from vdps_hil.model.chassis import Chassis
from vdps_hil.model.core import Env, Inputs
from vdps_hil.model.core_kernel import N_DIAG
from vdps_hil.model.effects import EffectSet, make_effect
from vdps_hil.model.params import load_vehicle
from vdps_hil.workbench.residuals import RowStates
from vdps_hil.workbench.row_kernel import NUISANCE_STEP_MPS, residual_rows
from vdps_hil.workbench.row_model import RowModel

CHASSIS = Chassis(anti_roll_stiffness_front_nmprad=30000.0, anti_roll_stiffness_rear_nmprad=12000.0,
                  roll_centre_height_front_m=0.05, roll_centre_height_rear_m=0.12, ackermann_fraction=0.5)
EFFECT_SETS = {
    "linear": [],
    "magic_formula": [("magic_formula_tire", {})],
    "several": [("magic_formula_tire", {"peak_friction": 0.8}), ("aero_drag", {"cda_m2": 0.7}),
                ("load_dependent_cornering_stiffness", {}), ("rolling_resistance", {}),
                ("crosswind", {"wind_speed_mps": 4.0, "wind_to_rad": 1.0})],
}


def _vehicle(name):
    if name == "sedan-chassis":
        return dataclasses.replace(load_vehicle("sedan-model"), chassis=CHASSIS)
    return load_vehicle(name)


def _rows(rng, n: int) -> RowStates:
    """Random rows: 8-30 m/s with sideslip, rates, wheel speeds near rolling, roll and pitch of a
    few degrees, steering +-90 deg at the wheel, drive and brake torques, bank and grade, wind;
    measured deflections +-3 cm on most rows, NaN (not measured) on every fifth."""
    xs, us, envs = [], [], []
    for _ in range(n):
        v = rng.uniform(8.0, 30.0)
        x = [0.0, 0.0, rng.uniform(-0.05, 0.05), rng.uniform(-0.06, 0.06), rng.uniform(-0.04, 0.04),
             rng.uniform(-3.0, 3.0), v, rng.uniform(-0.8, 0.8), rng.uniform(-0.1, 0.1),
             *rng.uniform(-0.3, 0.3, 2), rng.uniform(-0.6, 0.6)]
        x += list(v / 0.31 * (1.0 + rng.uniform(-0.05, 0.05, 4)))
        xs.append(x)
        us.append(Inputs(rng.uniform(-1.6, 1.6), tuple(rng.uniform(-300.0, 600.0, 4)),
                         tuple(rng.uniform(0.0, 200.0, 4) * (rng.random() < 0.3))))
        envs.append(Env(rng.uniform(-0.05, 0.05), rng.uniform(-0.05, 0.05), tuple(rng.uniform(-5.0, 5.0, 3))))
    meas = np.column_stack([rng.normal(0.0, 4.0, (n, 3)), rng.normal(0.0, 1.0, (n, 3)), rng.normal(0.0, 30.0, (n, 4)),
                            np.array([x[12:16] for x in xs]) * (1.0 + rng.normal(0.0, 0.01, (n, 4))),
                            rng.uniform(-0.03, 0.03, (n, 4)), rng.normal(0.0, 0.1, (n, 4))])
    meas[::5, 14:22] = math.nan
    return RowStates(np.arange(n), xs, us, envs, meas, has_susp=True)


def _reference(rm: RowModel, st: RowStates):
    """``compute_residuals``' per-row path for one row set: residuals, wheel-speed parts,
    nuisance (velocity columns, then the slip columns)."""
    n, h = len(st.x), NUISANCE_STEP_MPS
    vals, ws, nu, sl = np.empty((n, 14)), np.empty((n, 8)), np.empty((n, 14, 2)), np.empty((n, 14, 8))
    rows = st.meas.tolist()
    for j in range(n):
        r, _ = rm.residual(st.x[j], st.u[j], st.env[j], rows[j], want_slip=True)
        vals[j], ws[j], sl[j] = r, rm.last_ws, rm.last_slip_cols
        for c in range(2):
            xp = list(st.x[j])
            xp[6 + c] += h
            nu[j, :, c] = (np.array(rm.residual(xp, st.u[j], st.env[j], rows[j])[0]) - np.array(r)) / h
    return vals, ws, nu, sl


def _compiled(rm: RowModel, st: RowStates, nuisance: bool = True):
    X, U, ENV = st.arrays()
    n = len(X)
    out = (np.empty((n, X.shape[1])), np.empty((n, N_DIAG)), np.empty((n, 14)), np.empty((n, 8)),
           np.empty((n, 14, 2)), np.empty((n, 14, 8)))
    residual_rows(X, U, ENV, np.ascontiguousarray(st.meas), *rm.packed(), nuisance, *out)
    return out


@pytest.mark.parametrize("effects", sorted(EFFECT_SETS))
@pytest.mark.parametrize("name", ["sedan-model", "cr1-model", "sedan-chassis"])
def test_all_rows_compiled_equal_the_row_model_bit_for_bit(rng, name, effects):
    veh = _vehicle(name)
    rm = RowModel(veh, EffectSet([make_effect(e, **p) for e, p in EFFECT_SETS[effects]]))
    if not jit.ENABLED:
        pytest.skip("VDPS_JIT=0: no compiled core")
    st = _rows(rng, 60)
    vals, ws, nu, sl = _reference(rm, st)
    xd, dg, cvals, cws, cnu, csl = _compiled(rm, st)
    assert np.isfinite(vals).all() and np.abs(vals[:, 1]).max() > 100.0  # rows that load the tires
    for a, b in ((vals, cvals), (ws, cws), (nu, cnu), (sl, csl)):
        assert np.array_equal(a, b), np.abs(a - b).max()
    # the core's own outputs at each row are Model.f's (the named quantities are made from them)
    for j in (0, 5, 37):
        raw: dict = {}
        assert rm.model.f(st.x[j], st.u[j], st.env[j], raw) == xd[j].tolist()
        assert [tuple(dg[j, 16 * i:16 * i + 16]) for i in range(4)] == raw["_rec"]


def test_suspension_rows_take_the_measured_loads_and_without_nuisance_only_the_residuals_are_written(rng):
    """The measured deflections move the force rows (eq 14 loads instead of the pose's) and only
    those rows; ``nuisance=False`` leaves the nuisance and slip outputs untouched."""
    rm = RowModel(_vehicle("cr1-model"), EffectSet())
    if not jit.ENABLED:
        pytest.skip("VDPS_JIT=0: no compiled core")
    st = _rows(rng, 20)
    with_susp = _compiled(rm, st)[2]
    st.meas[:, 14:22] = math.nan
    st2 = RowStates(st.index, st.x, st.u, st.env, st.meas, has_susp=False)
    out = _compiled(rm, st2, nuisance=False)
    unmeasured = out[2]
    assert np.array_equal(with_susp[::5], unmeasured[::5])  # rows 0, 5, ... had no deflections already
    moved = np.abs(with_susp - unmeasured).max(axis=0)
    assert (moved[0:6] > 0.0).all() and (moved[6:14] == 0.0).all()
    sentinel = _compiled(rm, st2, nuisance=True)
    assert np.array_equal(sentinel[2], unmeasured)


def test_a_model_without_a_compiled_core_has_no_packed_arrays():
    from vdps_hil.model.effects import DynamicsEffect

    class Plain(DynamicsEffect):  # a user's effect: no compiled form
        name = "plain_test_effect"
        HOOKS = ("body_wrench",)

        def body_wrench(self, vel_b, omega_b, air_b):
            return (0.0,) * 6

    rm = RowModel(load_vehicle("sedan-model"), EffectSet([Plain()]))
    assert rm.model.kernel_arrays is None and rm.packed() is None
