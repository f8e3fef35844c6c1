"""RowQuantities, the packed per-row named quantities of the workbench's residuals: each row
reads back as the dict appended (exact: float64 values), rows with other names or non-float
values are kept as they were, and an empty one is falsy (the residuals' "no quantities" case)."""

from __future__ import annotations

import math

from vdps_hil.model.effects import EffectSet
from vdps_hil.workbench.row_model import RowQuantities


def test_rows_read_back_exactly_in_order():
    q = RowQuantities()
    rows = [{"slip_angle_rad_1": 0.1 * j + 1e-17, "slip_ratio_1": -j / 3.0, "v_mps": math.pi * j} for j in range(50)]
    for r in rows:
        q.append(r)
    assert len(q) == 50 and bool(q)
    assert [q[j] for j in range(50)] == rows  # bit-exact floats, names in order
    assert list(q) == rows
    assert list(q[7]) == ["slip_angle_rad_1", "slip_ratio_1", "v_mps"]


def test_a_row_with_other_names_or_values_is_kept_as_its_dict():
    q = RowQuantities()
    q.append({"a": 1.0, "b": 2.0})
    q.append({"a": 1.0})  # other names
    q.append({"a": 3, "b": 4.0})  # an int, not a float
    q.append({"a": float("nan"), "b": float("inf")})
    assert q[1] == {"a": 1.0}
    assert q[2] == {"a": 3, "b": 4.0} and type(q[2]["a"]) is int
    assert math.isnan(q[3]["a"]) and q[3]["b"] == math.inf
    assert q[0] == {"a": 1.0, "b": 2.0}


def test_a_returned_row_is_a_copy():
    q = RowQuantities()
    q.append({"a": 1.0})
    r = q[0]
    r["a"] = 5.0
    assert q[0] == {"a": 1.0}


def test_empty_is_falsy():
    q = RowQuantities()
    assert not q and len(q) == 0 and list(q) == []


def test_numpy_float64_rows_are_packed_and_read_back_with_the_same_bits():
    """The residuals compute their quantities as numpy float64 (a float subclass): those rows are
    the ones packing exists for."""
    import numpy as np

    q = RowQuantities()
    rows = [{"a": np.float64(0.1) * j, "b": np.float64(-1.0) / (j + 3)} for j in range(20)]
    for r in rows:
        q.append(r)
    assert q.packed == 20
    assert [q[j] for j in range(20)] == rows
    assert all(float(q[j][k]).hex() == float(rows[j][k]).hex() for j in range(20) for k in "ab")
    q.append({"a": np.float32(1.5), "b": 1.0})  # float32 is not a float: kept as its dict
    assert q.packed == 20 and type(q[20]["a"]) is np.float32


def _rolled_row(vehicle):
    """A cornering row of ``vehicle``'s reduced model, rolled 3 deg with a lateral velocity and a
    yaw rate (the tires carry lateral force): (row model, x, u, env, meas with the suspension
    NaN, meas with the suspension measured at exactly the pose's deflections and rates)."""
    import numpy as np

    from vdps_hil.model.core import Inputs
    from vdps_hil.prediction.predictor import Predictor, PredictorConfig, PredictorInitialState
    from vdps_hil.workbench.row_model import RowModel

    pred = Predictor(vehicle, PredictorConfig(horizon_s=0.02, step_s=0.01))
    init = PredictorInitialState(t_ns=0, pos_g_m=(0.0, 0.0, 0.0), vel_g_mps=(15.0, 0.4, 0.0),
                                 euler_g_rad=(0.05, -0.01, 0.0), road_bank_rad=0.0, road_grade_rad=0.0,
                                 rate_b_radps=(0.0, 0.0, 0.3), wheel_speed_radps=(44.0, 44.5, 44.2, 43.8))
    x, env, _ = pred.core_state(init)
    u = Inputs(0.9, (120.0, 120.0, 0.0, 0.0))
    rm = RowModel(vehicle, EffectSet())
    raw = {"_want_air": False}
    rm.model.f(x, u, env, raw)
    h = [rc[5] for rc in raw["_rec"]]
    hd = [rc[6] for rc in raw["_rec"]]
    head = [0.1, 2.0, 9.8, 0.0, 0.0, 0.2, 1.0, 1.0, 1.0, 1.0, 44.0, 44.5, 44.2, 43.8]
    nan = [float("nan")] * 8
    return rm, x, u, env, np.array(head + nan), np.array(head + h + hd)


def test_measured_loads_keep_the_anti_roll_bars_and_roll_centres():
    """With the suspension measured at exactly the deflections of the pose, the measured-load path
    gives the pose's residual: the anti-roll bars (``[chassis]``, CommonRoad set 3: 33.9 / 7.7 kN
    m/rad) and the roll centres' linkage forces are part of the measured normal loads too. (They
    were dropped: the roll row then lacked K_arb phi, about 1.7 kN m at 3 deg on set 3, and the
    workbench recommended the ``roll_stiffness`` effect the model file already has.)"""
    import dataclasses

    import numpy as np

    from vdps_hil.model.params import load_vehicle

    cr3 = load_vehicle("cr3-model")
    with_rc = dataclasses.replace(cr3, chassis=dataclasses.replace(
        cr3.chassis, roll_centre_height_front_m=0.08, roll_centre_height_rear_m=0.12))
    for veh in (cr3, with_rc):
        rm, x, u, env, pose, measured = _rolled_row(veh)
        r_pose, _ = rm.residual(x, u, env, pose)
        r_meas, _ = rm.residual(x, u, env, measured)
        assert np.allclose(r_meas[:6], r_pose[:6], rtol=1e-9, atol=1e-6), (veh.chassis, r_pose[:6], r_meas[:6])
    # the bars matter here: without them the roll row moves by K_arb,f phi_f + K_arb,r phi_r
    bare = dataclasses.replace(cr3, chassis=dataclasses.replace(
        cr3.chassis, anti_roll_stiffness_front_nmprad=0.0, anti_roll_stiffness_rear_nmprad=0.0))
    rm0, x, u, env, _, measured = _rolled_row(bare)
    rm1 = _rolled_row(cr3)[0]
    d_roll = rm1.residual(x, u, env, measured)[0][3] - rm0.residual(x, u, env, measured)[0][3]
    tf, tr = 2 * cr3.geometry.track_half_front_m, 2 * cr3.geometry.track_half_rear_m
    h = measured[14:18]
    expect = 33948.22 * (h[1] - h[0]) / tf + 7731.374 * (h[2] - h[3]) / tr  # K_arb phi_a, body over axle
    assert abs(d_roll) > 500.0 and abs(abs(d_roll) - abs(expect)) < 0.05 * abs(expect), (d_roll, expect)
