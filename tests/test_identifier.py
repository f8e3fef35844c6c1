"""The online Identifier (section 5.2): exact recovery of all ten parameters from consistent
data, the Gauss-Seidel order and its waiting for upstream problems, gating, NaN and out-of-order
inputs, reset, status and the sigmas including the upstream uncertainty (synthetic inputs:
``ident_forward``)."""

import dataclasses
import json
import math
import warnings

import numpy as np
import pytest

from ident_forward import MODEL, TRUE, forward, rel_err, weak_prior_config
from vdps_hil.identification.config import PROBLEM_NAMES, PROBLEM_PARAMS, load_ident_config
from vdps_hil.identification.identifier import Identifier
from vdps_hil.model.params import PARAM_NAMES


@pytest.mark.parametrize("form", ["covariance", "sqrt_information"])
def test_exact_consistent_data_recover_all_ten_parameters_to_1e9(rng, form):
    # no noise, no forgetting, nontrivial Q (default config) and W (priors); weak prior
    ident = Identifier(MODEL, weak_prior_config(form=form))
    for k in range(300):
        ident.update(forward(rng, k))
    err = rel_err(ident.params)
    assert max(abs(e) for e in err.values()) < 1e-9, err
    assert all(c.updates > 150 for c in ident.counters.values())  # cornering: |a_y| < 0.5 m/s^2 gated
    assert ident.vehicle.params == ident.params and ident.vehicle.geometry == MODEL.geometry


def test_default_config_moves_every_parameter_from_prior_toward_truth(rng):
    # default prior (50 %) and weights: noise-free data, 500 samples (5 s at 100 Hz)
    ident = Identifier(MODEL)
    for k in range(500):
        ident.update(forward(rng, k))
    prior_err = rel_err(MODEL.params)
    err = rel_err(ident.params)
    for n in PARAM_NAMES:
        assert abs(err[n]) < abs(prior_err[n]) / 5.0, (n, err[n], prior_err[n])


def _warmed_up(rng, n=200):
    # 200 inputs (the cornering gate refuses |a_y| < 0.5 m/s^2, so inertia needs them to start)
    # at 5 ms steps: they end before the k >= 100 inputs (10 ms steps) of the tests
    ident = Identifier(MODEL)
    for k in range(n):
        inp = forward(rng, k)
        ident.update(dataclasses.replace(inp, t_ns=inp.t_ns // 2))
    return ident


def test_zero_slip_and_zero_steer_never_update_and_never_divide_by_zero(rng):
    ident = _warmed_up(rng)
    before, c0 = ident.params, ident.counters
    zeros4 = np.zeros(4)
    with np.errstate(all="raise"), warnings.catch_warnings():
        warnings.simplefilter("error")
        for k in range(100, 150):
            inp = forward(rng, k, slip=zeros4, alpha=zeros4, delta=zeros4, omega=np.zeros(3))
            inp = dataclasses.replace(inp, omega_dot_radps2=(0.0, 0.0, 0.0))
            ident.update(inp)
            assert ident.excited == {"mass": True, "tracking": False, "cornering": False, "inertia": False}
        _ = ident.sigmas, ident.identifiability, ident.converged
    for name in ("tracking", "cornering", "inertia"):
        assert ident.counters[name].updates == c0[name].updates
        assert ident.counters[name].not_excited == c0[name].not_excited + 50
        for n in PROBLEM_PARAMS[name]:
            assert getattr(ident.params, n) == getattr(before, n)


def test_dependent_problems_wait_for_their_upstream_problems(rng):
    ident = Identifier(MODEL)  # upstream_min_updates = 50 in the default config
    for k in range(49):
        ident.update(forward(rng, k))
    assert ident.counters["cornering"].updates == 0 and ident.waiting_upstream["cornering"] == 49
    for k in range(49, 120):
        ident.update(forward(rng, k))
    assert ident.counters["cornering"].updates > 0 and ident.counters["inertia"].updates > 0
    assert ident.waiting_upstream["inertia"] > ident.waiting_upstream["cornering"]


def test_a_never_excited_upstream_problem_delays_its_dependants_at_most_max_wait(rng):
    cfg = dataclasses.replace(load_ident_config(), upstream_max_wait=30)
    ident = Identifier(MODEL, cfg)
    for k in range(60):  # no wheel ever slips: tracking is never excited
        ident.update(forward(rng, k, slip=np.zeros(4)))
    assert ident.counters["tracking"].updates == 0
    assert ident.waiting_upstream["cornering"] == 30 and ident.counters["cornering"].updates > 0


def test_low_speed_gates_the_slip_problems(rng):
    ident = _warmed_up(rng)
    c0 = ident.counters
    for k in range(100, 120):
        ident.update(forward(rng, k, speed=1.0))
    assert ident.counters["mass"].updates == c0["mass"].updates + 20
    for name in ("tracking", "cornering", "inertia"):
        assert ident.counters[name].updates == c0[name].updates


def test_nan_inputs_are_skipped_and_counted(rng):
    ident = _warmed_up(rng)
    c0 = ident.counters
    inp = forward(rng, 100)
    bad = dataclasses.replace(inp, slip_ratio=(math.nan,) + inp.slip_ratio[1:])
    ident.update(bad)
    c = ident.counters
    assert c["tracking"].nan_rows == 1 and c["tracking"].rows_used == c0["tracking"].rows_used + 3
    assert c["cornering"].nan_rows == 2 and c["inertia"].nan_rows >= 1  # b_3, b_4 use F_a,1
    assert c["mass"].updates == c0["mass"].updates + 1
    assert all(math.isfinite(v) for v in ident.params.as_dict().values())
    assert all(math.isfinite(v) for v in ident.sigmas.values())


def test_duplicate_or_out_of_order_inputs_are_refused(rng):
    ident = Identifier(MODEL)
    ident.update(forward(rng, 5))
    ident.update(forward(rng, 5))
    ident.update(forward(rng, 4))
    assert ident.inputs_rejected == 2 and ident.counters["mass"].updates == 1


def test_identifier_refuses_a_truth_vehicle_file():
    with pytest.raises(ValueError, match="model vehicle"):
        Identifier(dataclasses.replace(MODEL, kind="truth"))


def test_reset_and_start_values(rng):
    ident = _warmed_up(rng)
    ident.reset("mass")
    assert ident.params.mass_kg == MODEL.params.mass_kg
    assert ident.params.inertia_x_kgm2 != MODEL.params.inertia_x_kgm2
    start = dataclasses.replace(MODEL.params, mass_kg=1500.0)
    ident.reset(start=start)
    assert ident.params == start and ident.counters["inertia"].updates == 0
    assert Identifier(MODEL, start=start).params == start


def test_status_is_json_and_converged_flags(rng):
    ident = Identifier(MODEL)
    assert not any(ident.converged.values())
    for k in range(300):
        ident.update(forward(rng, k))
    doc = json.loads(json.dumps(ident.status()))
    assert set(doc["params"]) == set(PARAM_NAMES) == set(doc["sigmas"])
    assert doc["converged"]["mass"] is True  # noise-free data: sigma -> 0
    assert all(doc["identifiability"][p] > 0 for p in PROBLEM_NAMES)


def test_sigmas_include_the_uncertainty_of_upstream_estimates(rng):
    ident = Identifier(MODEL)
    for k in range(200):
        ident.update(forward(rng, k))
    own = ident.problem("inertia").parameter_covariance
    total = ident.covariances["inertia"]
    assert np.all(np.diag(total) >= np.diag(own))
    assert np.any(np.diag(total) > np.diag(own))
    assert ident.sigmas["inertia_z_kgm2"] == pytest.approx(math.sqrt(total[2, 2]))


def test_status_read_at_every_update_equals_status_read_once(rng):
    # covariances and problem_status are computed once per update (the chain reads them at every
    # estimate): read after every update, they must equal those of an identical identifier read
    # only at the end, bit for bit; and a caller changing the returned arrays changes nothing
    inputs = [forward(rng, k) for k in range(260)]
    every, once = Identifier(MODEL), Identifier(MODEL)
    for inp in inputs:
        every.update(inp)
        once.update(inp)
        every.converged, every.sigmas
        every.covariances["mass"][...] = 0.0
    assert every.problem_status == once.problem_status
    assert every.sigmas == once.sigmas
    assert all(np.array_equal(every.covariances[n], once.covariances[n]) for n in PROBLEM_NAMES)
    assert every.converged["mass"] and every.sigmas["mass_kg"] > 0.0
    every.reset("mass")
    assert not every.converged["mass"]


def test_converged_of_answers_as_converged_with_and_without_the_corrected_covariances(rng):
    # the chain's convergence read (converged_of) decides a problem that another cause keeps from
    # converging without the corrected covariances; read after every update, for every problem,
    # it must give converged's answer, and both ways must be taken on this drive
    from vdps_hil.identification.status import cause_without_sigma

    ident = Identifier(MODEL)
    ways = set()
    for k in range(260):
        ident.update(forward(rng, k))
        fresh = Identifier.converged_of(ident, PROBLEM_NAMES)  # before converged fills the cache
        assert fresh == ident.converged, k
        for n in PROBLEM_NAMES:
            ways.add(cause_without_sigma(ident.problem(n), ident._sigma0[n], ident._failed_rows(n),
                                         ident.config) is None)
    assert ways == {True, False}
    assert ident.converged_of(("cornering",)) == {"cornering": ident.converged["cornering"]}


def test_reported_sigmas_are_the_corrected_ones_and_the_raw_ones_travel_beside_them(rng):
    # the reported sigma: the larger of the model-based and the block-jackknife variance
    # (Identifier._honest); sigma_raw: W P W alone (white residuals with the configured noise)
    ident = Identifier(MODEL)
    off = Identifier(MODEL, dataclasses.replace(ident.config, status=dataclasses.replace(
        ident.config.status, sigma_blocks=0)))
    for k in range(600):
        inp = forward(rng, k)
        ident.update(inp)
        off.update(inp)
    assert ident.params == off.params  # only the sigmas change
    sig, raw, model = ident.sigmas, ident.sigmas_raw, off.sigmas
    assert all(sig[p] >= model[p] * (1 - 1e-12) for p in PARAM_NAMES)
    assert ident.problem("mass").jackknife_covariance is not None
    assert off.problem("mass").jackknife_covariance is None
    doc = json.loads(json.dumps(ident.status()))
    assert set(doc["sigmas_raw"]) == set(PARAM_NAMES)
    for name, st in ident.problem_status.items():
        for p in st.params:
            assert p.sigma == sig[p.name] and p.sigma_raw == raw[p.name]
            assert doc["status"][name]["params"][p.name]["sigma_raw"] == pytest.approx(raw[p.name])


def test_the_mass_sigma_reports_the_strut_axis_bias_the_fit_cannot_see(rng):
    # b carries the strut-axis term m_s theta f_x in full (CommonRoad's struts stay normal to the
    # road in pitch): the estimate moves by the least-squares bias, white residuals hide it, and
    # the reported sigma carries it (identifier._structure_bias); with f_x = 0 it adds nothing
    m_s = TRUE.mass_kg - MODEL.unsprung_mass_total_kg

    def drive(fx):
        ident = Identifier(MODEL)
        for k in range(600):
            inp = forward(rng, k)
            theta = 0.01 * fx[k]  # pitch follows the longitudinal specific force (squat, dive)
            s = m_s * theta * fx[k]
            inp = dataclasses.replace(inp, specific_force_b_mps2=(fx[k], 0.0, 9.8),
                                      vehicle_angles_rad=(0.0, theta),
                                      zdd_a_mps2=inp.zdd_a_mps2 - s / m_s)  # struts: m_s A + s
            ident.update(inp)
        return ident
    pulses = np.where(np.arange(600) % 200 < 100, 3.0, -3.0)
    ident = drive(pulses)
    err = ident.params.mass_kg - TRUE.mass_kg
    assert err > 0.005 * TRUE.mass_kg  # biased by ~ s / A: the fit cannot tell the term from m
    assert abs(err) <= 1.2 * ident.sigmas["mass_kg"]  # the bias is inside one sigma
    assert ident.sigmas_raw["mass_kg"] < abs(err) / 2.0  # the noise model alone does not see it
    flat = drive(np.zeros(600))
    assert flat.sigmas["mass_kg"] < 0.2 * ident.sigmas["mass_kg"]


def test_a_value_on_its_bound_is_never_handed_over(rng):
    """``handover_params`` (what ``--save-params`` and a calibration hand on): the estimates, but
    a parameter "at bound" keeps the run's start value. Inputs of a vehicle 3.5x as heavy as the
    model file's prior put the mass on its 3x bound; the other problems keep their estimates."""
    start = dataclasses.replace(MODEL.params, mass_kg=1700.0)
    ident = Identifier(MODEL, start=start)
    heavy = dataclasses.replace(TRUE, mass_kg=3.5 * MODEL.params.mass_kg)
    for k in range(300):
        ident.update(forward(rng, k, true=heavy))
    assert ident.problem_status["mass"].params[0].status == "at bound"
    assert ident.params.mass_kg == pytest.approx(3.0 * MODEL.params.mass_kg)
    values, at_bound = ident.handover_params()
    assert at_bound == ("mass_kg",) and values.mass_kg == 1700.0
    others = [n for n in PARAM_NAMES if n != "mass_kg"]
    assert all(getattr(values, n) == getattr(ident.params, n) for n in others)
    fresh = Identifier(MODEL)
    assert fresh.handover_params() == (fresh.params, ())  # nothing excited: nothing at bound
