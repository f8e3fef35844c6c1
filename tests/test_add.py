"""--add: the added effect joins the identification from its generic prior, the error falls on
held-out time (models fitted only before each prediction's start), and the paper's own case --
the rollover prediction with a Magic Formula tire fitted before the prediction start."""

from __future__ import annotations

import numpy as np
import pytest

from vdps_hil.experiments.workbench_study import HIDDEN, cached_drive, study_profile
from vdps_hil.model.effects import EffectSet
from vdps_hil.model.params import load_vehicle
from vdps_hil.prediction.metrics import PAPER_INACCURACY_PCT, PoseTrajectory, compare_trajectories
from vdps_hil.prediction.config import PredictorConfig
from vdps_hil.prediction.initial_state import InputTrajectory
from vdps_hil.prediction.predictor import Predictor
from vdps_hil.record.reader import RecordingReader
from vdps_hil.sim.drive import Drive
from vdps_hil.sim.scenarios import load_scenario
from vdps_hil.workbench.add import (WORSE_FRACTION, WORSE_NOISE, add_effects, before_after, fit_model, residual_change,
                                    worse_equations, worse_predictions)
from vdps_hil.workbench.candidates import candidate_for
from vdps_hil.workbench.dataset import load_drive, reestimator
from vdps_hil.workbench.simulation_errors import _initial_state

VEH = load_vehicle("sedan-model")


@pytest.fixture(scope="module")
def drag(drive_cache):
    cache = drive_cache
    man, spec = HIDDEN["aero_drag"]
    out = {}
    for label, specs in (("hidden", [spec]), ("null", [])):
        tab = load_drive(cached_drive(cache, man, specs, seed=21), VEH)
        # refits every 4 s (default 2 s; test time): every prediction still uses a model fitted
        # only on data before its start
        out[label] = add_effects(tab, VEH, EffectSet(), ["aero_drag"], refit_every_s=4.0)
    return out


def test_add_starts_from_the_generic_prior_and_finds_the_magnitude(drag):
    cda = drag["hidden"].parameters["aero_drag"]["cda_m2"]
    assert cda["value"] == pytest.approx(0.7, abs=0.07)
    assert 0.0 < cda["sigma"] < 0.05
    assert drag["null"].parameters["aero_drag"]["cda_m2"]["value"] < 0.07  # nothing there: ~0


def test_add_removes_half_the_attributable_error_on_held_out_time(drag):
    """attributable = simulation error with the effect hidden minus with nothing hidden (same
    maneuver and seed), before adding; after adding it must fall by >= 50 % of that."""
    for h in ("1", "2"):
        for q in ("position_m", "speed_mps"):
            before = drag["hidden"].before["simulation_error"][h][q]
            after = drag["hidden"].after["simulation_error"][h][q]
            null = drag["null"].before["simulation_error"][h][q]
            attributable = before - null
            assert attributable > 0.05 * before, (h, q)
            assert before - after >= 0.5 * attributable, (h, q, before, after, null)


def test_add_before_after_tables_have_every_equation(drag):
    b, a = drag["hidden"].before, drag["hidden"].after
    assert set(b["residual_rms"]) == set(a["residual_rms"]) and "long" in b["residual_rms"]
    assert a["residual_rms"]["long"] < 0.2 * b["residual_rms"]["long"]  # drag is the long residual
    assert set(b["simulation_error"]) == {"0.5", "1", "2"}


def test_add_refuses_unknown_or_present_effects(drag):
    tab = None
    with pytest.raises(ValueError, match="unknown effect"):
        add_effects(tab, VEH, EffectSet(), ["warp_drive"])
    with pytest.raises(ValueError, match="already in the model"):
        add_effects(tab, VEH, EffectSet([candidate_for(__import__("vdps_hil.model.effects", fromlist=["REGISTRY"])
                                                       .REGISTRY["aero_drag"]).effect([0.7])]), ["aero_drag"])


T0_S = 10.25
T_END_S = 11.5


@pytest.fixture(scope="module")
def rollover(tmp_path_factory):
    """The paper's rollover scenario (Magic Formula truth, torque step at 10.25 s)."""
    path = tmp_path_factory.mktemp("rollover") / "paper-rollover.mcap"
    Drive(load_scenario("paper-rollover"), seed=7, profile=study_profile()).run(path)
    tab = load_drive(path, VEH)
    with RecordingReader(path) as r:
        truth = [doc["values"] for _, _, doc in r.iter_messages(["/truth/state"])]
    return tab, truth


def _predict(tab, model, truth):
    t0_rel = T0_S - tab.t0_ns * 1e-9
    k = int(np.searchsorted(tab.t_s, t0_rel - 1e-9))
    init = _initial_state(tab, k)
    c = tab.columns
    sl = slice(k, len(tab))
    inp = InputTrajectory(tab.t_s[sl] - tab.t_s[k], c["steer_wheel_angle_rad"][sl],
                          np.column_stack([c[f"wheel_torque_nm_{i}"][sl] for i in range(1, 5)]))
    pred = Predictor(model.vehicle, PredictorConfig(horizon_s=T_END_S - T0_S + 0.02, stop_at_point_of_no_return=False),
                     EffectSet(model.effects.dynamics))
    res = pred.predict(init, inp)
    p = PoseTrajectory.from_prediction(res)
    t0 = p.t_s[0]
    tr = PoseTrajectory.from_snapshots(truth, t0 - 1e-3, T_END_S + 0.05)
    # the truth at exactly the prediction's start, then its samples
    tr = tr.at(np.concatenate([[t0], tr.t_s[tr.t_s > t0 + 1e-9]]))
    return compare_trajectories(p, tr)


@pytest.mark.xfail(strict=True, reason=(
    "measured (seed 7): linear tire 30.7 %, Magic Formula fitted before 10.25 s 23.0 % (peak friction 1.01; "
    "last session 41.0 % with mu 0.74; the change came with commits merged before this branch), "
    "truth's own parameters and tire "
    "23.2 %: the floor is the estimate the prediction starts from (z_a channel 77 %: the EKF's height)"))
def test_rollover_prediction_with_the_tire_fitted_before_the_start(rollover):
    """Paper section 7.3: the rollover prediction from 10.25 s. The baseline is our own linear
    tire (the ten parameters identified before 10.25 s); with the Magic Formula added (peak
    friction fitted before 10.25 s, shape at its generic prior) the inaccuracy must fall well
    below it. Paper: 27.3 %; goal < 10 %."""
    tab, truth = rollover
    before = tab.t_s < T0_S - tab.t0_ns * 1e-9
    base = fit_model(tab, VEH, EffectSet(), (), mask=before)
    mf = fit_model(tab, VEH, EffectSet(), [candidate_for(__import__("vdps_hil.model.effects", fromlist=["REGISTRY"])
                                                         .REGISTRY["magic_formula_tire"])], mask=before)
    m0 = _predict(tab, base, truth)
    m1 = _predict(tab, mf, truth)
    print(f"\nrollover inaccuracy: linear tire {m0['inaccuracy_pct']:.1f} %, with the Magic Formula fitted before "
          f"10.25 s {m1['inaccuracy_pct']:.1f} % (paper {PAPER_INACCURACY_PCT['rollover']} %); peak friction "
          f"{mf.effects['magic_formula_tire'].peak_friction:.2f}")
    assert m1["inaccuracy_pct"] < 0.6 * m0["inaccuracy_pct"]
    assert m1["inaccuracy_pct"] < 10.0


def test_add_imu_bias_reestimates_and_removes_half_the_attributable_error(drive_cache):
    """A sensor effect is taken out of the IMU readings and the drive re-estimated: the hidden
    bias (ImuBias defaults, 0.05 m/s^2 and 0.1 deg/s per axis) makes the estimate's vertical
    velocity drift, which the predictions (started from the estimate, compared with it) cannot
    follow; the vertical accelerometer bias is re-solved from that drift (the heave equation
    alone confounds it). Seed 3000, 2 s horizon: after adding, the position error falls by >= 50 %
    of the attributable part (hidden minus nothing hidden, same maneuver and seed)."""
    cache = drive_cache
    man, spec = HIDDEN["imu_bias"]
    path = cached_drive(cache, man, [spec], seed=3000)
    tab = load_drive(path, VEH)
    res = add_effects(tab, VEH, EffectSet(), ["imu_bias"], refit_every_s=4.0,
                      reestimate=reestimator(path, VEH))
    null_tab = load_drive(cached_drive(cache, man, [], seed=3000), VEH)
    null = before_after(null_tab, VEH, EffectSet(), [], refit_every_s=4.0).before["simulation_error"]["2"]["position_m"]
    before = res.before["simulation_error"]["2"]["position_m"]
    after = res.after["simulation_error"]["2"]["position_m"]
    attributable = before - null
    assert attributable > 0.5 * before, (before, null)
    assert before - after >= 0.5 * attributable, (before, after, null)
    bz = res.parameters["imu_bias"]["accel_bias_z_mps2"]["value"]
    assert bz == pytest.approx(0.05, abs=0.015)  # the hidden truth (ImuBias default); the fit alone gave ~0.12


def test_an_equation_the_added_effect_makes_worse_is_named():
    """The relative change per equation, and the equations whose residual rose by more than
    WORSE_FRACTION (10 %) and WORSE_NOISE (half) of its noise sigma: on the real RAV4 drive an IMU bias added against the ranking's
    verdict halved the yaw residual and raised the lateral one 46 % (819 -> 1196 N)."""
    before = {"residual_rms": {"lat": 819.1, "yaw": 800.8, "long": 0.0, "roll": 10.0}}
    after = {"residual_rms": {"lat": 1196.4, "yaw": 398.3, "long": 5.0, "roll": 10.0 * (1 + WORSE_FRACTION)}}
    ch = residual_change(before, after)
    assert ch["lat"] == pytest.approx(0.4606, abs=1e-3) and ch["yaw"] == pytest.approx(-0.5026, abs=1e-3)
    assert ch["long"] is None  # nothing to compare with
    assert set(worse_equations(before, after)) == {"lat"}  # a rise of exactly 10 % is not "worse"
    assert worse_equations(before, None) == {}
    # a rise within half the equation's noise sigma is the noise of re-estimating, not "worse"
    assert worse_equations(before, after, {"lat": 377.2 / WORSE_NOISE + 1.0}) == {}
    assert set(worse_equations(before, after, {"lat": 377.2 / WORSE_NOISE - 1.0})) == {"lat"}


def test_a_held_out_prediction_the_added_effect_makes_worse_is_named():
    """A quantity of the held-out prediction error that rises by more than WORSE_FRACTION (10 %):
    CommonRoad set 3's circle ramp (tuning seed 100), ``--add magic_formula_tire``: position
    0.555 -> 0.973 m, yaw 2.81 -> 3.20 deg at 2 s; a diverged (None) or non-finite figure is not
    compared."""
    q = ("position_m", "yaw_deg", "roll_deg", "speed_mps")
    before = {"simulation_error": {"0.5": dict(zip(q, (0.1, 0.4, 0.9, 0.04))), "2": dict(zip(q, (0.555, 2.81, 0.6, 0.2)))}}
    after = {"simulation_error": {"0.5": dict(zip(q, (0.1, 0.44, 0.9, None))),
                                  "2": dict(zip(q, (0.973, 3.20, 0.6 * (1 + 0.99 * WORSE_FRACTION), float("nan"))))}}
    w = worse_predictions(before, after)
    assert set(w) == {"2"} and set(w["2"]) == {"position_m", "yaw_deg"}  # roll: 9.9 % is not "worse"
    assert w["2"]["position_m"] == pytest.approx(0.7532, abs=1e-3)
    assert worse_predictions(before, None) == {} and worse_predictions({}, after) == {}


def test_add_steering_offset_takes_it_out_of_the_steering_and_removes_half_the_error(drive_cache):
    """``steering_offset`` through ``--add`` on a drive where the ranking does not offer it (a lane
    change: no half turn, ``candidates.TURN_NEEDED_RAD``): the steering-angle sensor reads 0.03 rad
    (1.7 deg) high (seed 21). The fitted
    offset is the hidden one within 10 %, and after adding it the 1 s and 2 s prediction errors of
    position and yaw fall by >= 50 % of their attributable part (hidden minus nothing hidden, same
    maneuver and seed). Measured: 0.02997 +- 0.00016 rad; 2 s position 1.79 -> 0.19 m."""
    cache = drive_cache
    path = cached_drive(cache, "lane-change", ["steering_offset:offset_rad=0.03"], seed=21)
    res = add_effects(load_drive(path, VEH), VEH, EffectSet(), ["steering_offset"], refit_every_s=4.0,
                      reestimate=reestimator(path, VEH))
    null_tab = load_drive(cached_drive(cache, "lane-change", [], seed=21), VEH)
    null = before_after(null_tab, VEH, EffectSet(), [], refit_every_s=4.0).before["simulation_error"]
    off = res.parameters["steering_offset"]["offset_rad"]
    assert off["value"] == pytest.approx(0.03, rel=0.1) and 0.0 < off["sigma"] < 0.003, off
    for h in ("1", "2"):
        for q in ("position_m", "yaw_deg"):
            before, after = res.before["simulation_error"][h][q], res.after["simulation_error"][h][q]
            attributable = before - null[h][q]
            assert attributable > 0.5 * before, (h, q, before, null[h][q])
            assert before - after >= 0.5 * attributable, (h, q, before, after, null[h][q])


def test_the_cleaned_residual_is_the_fitted_models_own_on_a_circle_to_the_limit(drive_cache):
    """The before/after tables' residual (``cleaned_residuals``) takes the estimator's errors out
    at the identified point with the slow body-velocity nuisance held as the fit held it
    (``ranking.identification.capped_design``): refitting there moves neither cornering stiffness
    by more than 5 % of its identified value. On a circle ramped to the tires' limit (CommonRoad
    set 1, seed 21 as tests/test_builtin_candidates.py) the refit without that hold is another
    fit: the lateral knots take up the saturation and both stiffnesses move by more than 30 %
    (CommonRoad set 1's tuning seed 100, measured with the earlier columns: +155 / +126 kN/rad,
    and the 'cleaned' lateral residual read 15 N where the identified model's was 61 N)."""
    from vdps_hil.experiments.workbench_study import model_file
    from vdps_hil.workbench.innovations import compute_innovations
    from vdps_hil.workbench.ranking.config import RankingConfig
    from vdps_hil.workbench.ranking.design import theta_of
    from vdps_hil.workbench.ranking.identification import Point, build_design, capped_design
    from vdps_hil.workbench.residuals import row_states

    veh = load_vehicle(model_file("commonroad-mb:1"))
    path = cached_drive(drive_cache, "shipped:cr-circle-ramp", (), 21, truth="commonroad-mb:1")
    table = load_drive(path, veh)
    base = fit_model(table, veh, EffectSet())
    cfg, inn = RankingConfig(), compute_innovations(table)
    point = Point(base.vehicle, base.effects, {})
    stiff = ("cornering_stiffness_front_nprad", "cornering_stiffness_rear_nprad")
    d, cols, th = capped_design(table, row_states(table, base.vehicle), inn, veh, point, cfg)
    for p in stiff:
        step = float(theta_of(d, p, cols, th)[0])
        assert abs(step) <= 0.05 * getattr(base.vehicle.params, p), (p, step)
    # the drive exercises the hold: without it the same refit is another fit
    _, d0, cols0 = build_design(table, row_states(table, base.vehicle), inn, veh, point, cfg, {})
    th0, _ = d0.objective(cols0)
    assert all(abs(float(theta_of(d0, p, cols0, th0)[0])) > 0.3 * getattr(base.vehicle.params, p) for p in stiff)


def test_a_friction_no_step_of_the_fit_moved_is_said_to_be_at_its_start(drive_cache):
    """Our circle ramp with the Magic Formula hidden (seed 21): the generic prior of the peak
    friction is the truth's (1.0), and on this drive no fraction of the descent's first step
    lowers the objective (the step also takes the base fit's mass down; measured 2026-12-08), so
    the value is exactly the start. The fit says so (``FittedModel.at_start``), and the entry is
    "at start" without a sigma, never "fitted 1 +- 0.003"; a value the fit moved is "fitted"."""
    from vdps_hil.model.effects import REGISTRY
    from vdps_hil.workbench.added_params import parameter_entries

    man, spec = HIDDEN["magic_formula_tire"]
    tab = load_drive(cached_drive(drive_cache, man, [spec], seed=21), VEH)
    m = fit_model(tab, VEH, EffectSet(), [candidate_for(REGISTRY["magic_formula_tire"])])
    mf = m.effects["magic_formula_tire"]
    moved = mf.peak_friction != 1.0  # the ParamSpec default, where the fit starts
    assert ("magic_formula_tire" in m.at_start) == (not moved)
    entry = parameter_entries(mf, m.sigmas["magic_formula_tire"], "magic_formula_tire" in m.at_start)["peak_friction"]
    assert entry["status"] == ("fitted" if moved else "at start")
    assert not moved, "the descent moved the friction on this drive: keep the test's premise true with another drive"
