"""Tests of vdps_hil.pipeline.node: the Figure 2 node, its determinism, the warning path, the
estimator acceptance through the real chain (issue 5), a saved workbench model's effects in the
predictor."""

from __future__ import annotations

import importlib.util
import io
import math
from pathlib import Path

import numpy as np
import pytest
from replayed_drive import drive_samples

from vdps_hil.bus.samples import Sample
from vdps_hil.codecs.can_decode import VdpsCanDecoder
from vdps_hil.estimation.estimates import Estimate, FilteredSignals, Innovation
from vdps_hil.model.spring_law import suspension_forces_n
from vdps_hil.model.params import load_vehicle
from vdps_hil.pipeline.node import SystemConfig, VdpsSystem
from vdps_hil.pipeline.outputs import CanFrame, IdentReport, PredictionReport, outputs_digest
from vdps_hil.record.decode import decode_recording
from vdps_hil.sim.drive import Drive
from vdps_hil.sim.profiles import load_profile

MODEL = load_vehicle("sedan-model")


def _nees_tool():
    spec = importlib.util.spec_from_file_location("nees_study", Path(__file__).parents[1] / "tools" / "nees_study.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _hold(hold_s: float) -> dict:
    """SystemConfig keywords: the shipped warning config with ``converged_hold_s`` = ``hold_s``
    (the shipped 1.0 s outlasts this module's 2.5 s drive, whose cornering problem converges for
    good at ~1.96 s: its status tests use 0 or a shorter hold)."""
    from dataclasses import replace

    from vdps_hil.prediction.warning import load_warning_config

    pol, node = load_warning_config()
    return {"warning_policy": replace(pol, converged_hold_s=hold_s), "warning_node": node}


@pytest.fixture(scope="module")
def paper_samples():
    return drive_samples(7, 2.5)


@pytest.fixture(scope="module")
def paper_run(paper_samples):
    cfg = SystemConfig.for_profile(1000.0, 0.001, **_hold(0.0))
    return VdpsSystem.replay(MODEL, cfg, paper_samples)


def test_outputs_of_every_stage_in_time(paper_run):
    system, out = paper_run
    kinds = {type(o) for o in out}
    assert kinds == {Innovation, Estimate, FilteredSignals, IdentReport, PredictionReport, CanFrame}
    est = [o for o in out if isinstance(o, Estimate)]
    t = [e.t_ns for e in est]
    gaps = np.diff(t)
    assert np.all(gaps > 0) and np.median(gaps) == 10_000_000 and gaps.max() <= 20_000_000  # 100 Hz
    assert len([o for o in out if isinstance(o, IdentReport)]) == 3  # 1 Hz
    preds = [o for o in out if isinstance(o, PredictionReport)]
    assert 20 <= len(preds) <= 26  # 10 Hz cadence over the ~2.4 s after initialisation
    assert system.counters["ident_updates"] == len(est)


def test_warning_frames_decode_with_crc_and_counter_at_50_hz(paper_run):
    """VDPS_Warning leaves the node every 20 ms (and at once on a change) with a valid CRC and a
    running counter; status 0 once the estimator runs (the paper's drive has no rollover: never level 2 "warning")."""
    _, out = paper_run
    frames = [o for o in out if isinstance(o, CanFrame)]
    dec = VdpsCanDecoder()
    got = []
    for f in frames:
        got += dec.decode(f.t_ns, f.arbitration_id, f.data)
    assert len(got) == len(frames) and dec.total_rejected == 0
    gaps = np.diff([s.t_ns for s in got])
    assert np.max(gaps) <= 30_000_000 and np.mean(gaps == 20_000_000) > 0.95  # a change is sent at once
    assert max(int(s.fields["warning_level"]) for s in got) < 2  # no warning (caution allowed)
    status = [int(s.fields["warning_status"]) for s in got]
    # from the priors: "not converged" (1) until the cornering problem converges (~1.2 s here), then valid
    # 3 (fault): the aiding innovations were inconsistent (a fix gated in the start-up transient)
    # measured (seed 7, 2.5 s): 1 to 1.25 s, 0, 3 at 1.42-1.48 s (20 inconsistent frames), 1 again
    # to 1.96 s (the cornering problem's status fell back: identification.status), 0 to the end:
    # 36 of 126 frames valid (was > 30 % before the status and aiding monitors; now > 25 %)
    assert set(status) <= {0, 1, 2, 3} and status[0] == 1 and status[-1] == 0 and status.count(0) > 0.25 * len(status)


def _live_status(cfg, samples):
    """Step a live system; per decoded VDPS_Warning: (t_s, status, cornering converged before and
    after the sample that sent it, EKF initialised)."""
    system = VdpsSystem(MODEL, cfg)
    dec, rows = VdpsCanDecoder(), []
    for smp in samples:
        before = system.identifier.converged["cornering"]
        out = system.handle(smp)
        after = system.identifier.converged["cornering"]
        for o in out:
            if isinstance(o, CanFrame):
                for d in dec.decode(o.t_ns, o.arbitration_id, o.data):
                    rows.append((o.t_ns * 1e-9, int(d.fields["warning_status"]), before, after,
                                 system.pipeline.ekf.initialized))
    return system, rows


def test_warning_from_the_priors_is_valid_only_while_the_cornering_problem_has_converged(paper_samples):
    """The system's default validity rule (configs/prediction/default.toml [warning]
    require_converged = ["cornering"]), here without the hold: started from the model file's
    priors, every frame says "not converged" (1) while the identifier's cornering problem has not
    converged and "valid" (0) while it has (both phases occur in this 2.5 s drive: it converges at
    ~1.2 s); the flag as read at the last ``convergence_period_s`` boundary, which the 50 Hz frames
    fall on."""
    system, rows = _live_status(SystemConfig.for_profile(1000.0, 0.001, **_hold(0.0)), paper_samples)
    assert system.require_converged == ("cornering",)
    # the flag did not flip within the sample; 2 and 3: the fault handling's (aiding_monitor.health)
    eligible = [r for r in rows if r[4] and r[1] not in (2, 3)]
    settled = [r for r in eligible if r[2] == r[3]]
    assert len(settled) > 0.9 * len(eligible)
    assert all(r[1] == (0 if r[3] else 1) for r in settled)
    assert sum(1 for r in settled if r[1] == 1) >= 10 and sum(1 for r in settled if r[1] == 0) >= 10


def test_a_frame_is_valid_only_once_the_cornering_problem_has_stayed_converged_for_the_hold(paper_samples):
    """``converged_hold_s`` (prediction.warning, "Validity"), 0.3 s here: a frame says valid (0)
    only when the cornering problem was converged at every frame of the hold before it (one 20 ms
    convergence period of slack at either end: the chain reads the flag at period boundaries);
    a converged run shorter than the hold is never valid, and a longer one is valid from its start
    plus the hold on. This drive has one of each: 0.22 s from ~1.26 s (valid without the hold, the
    flicker the hold is for) and from ~1.96 s to the end."""
    hold = 0.3
    _, rows = _live_status(SystemConfig.for_profile(1000.0, 0.001, **_hold(hold)), paper_samples)
    t = np.array([r[0] for r in rows])
    conv = np.array([r[3] for r in rows])
    status = np.array([r[1] for r in rows])
    for k in np.flatnonzero(status == 0):
        window = (t >= t[k] - hold + 0.021) & (t <= t[k] - 0.021)
        assert conv[window].all(), t[k]
    edges = np.flatnonzero(np.diff(np.r_[0, conv.astype(int), 0]))
    runs = list(zip(edges[::2], edges[1::2]))  # [start, end) frame indices of converged runs
    short = [(a, b) for a, b in runs if t[b - 1] - t[a] < hold - 0.04]
    long = [(a, b) for a, b in runs if t[b - 1] - t[a] > hold + 0.1]
    assert short and long, runs
    for a, b in short:
        assert not (status[a:b] == 0).any()
    for a, b in long:
        late = (t[a:b] >= t[a] + hold + 0.041) & ~np.isin(status[a:b], (2, 3))
        assert late.any() and (status[a:b][late] == 0).all()
    # without the hold the short run's frames were valid
    _, rows0 = _live_status(SystemConfig.for_profile(1000.0, 0.001, **_hold(0.0)), paper_samples)
    a, b = short[0]
    assert any(r[1] == 0 for r in rows0 if t[a] <= r[0] <= t[b - 1])


def test_the_chain_reads_the_identifiers_convergence_once_per_convergence_period(paper_samples, monkeypatch):
    """Judging convergence may take the problems' corrected covariances (about 0.4 ms), so the
    chain re-reads it (``Identifier.converged_of`` its ``require_converged`` problems) at the
    first estimate of each ``convergence_period_s`` (0.02 s, the warning frames' period) of
    filter time instead of at every 10 ms estimate: at most one read per period (plus the
    first), and at least one per period once the gate is read at all (the frames' status lags
    the identifier by less than one frame). A non-positive period is refused."""
    from vdps_hil.identification.identifier import Identifier

    reads = []
    orig = Identifier.converged_of
    monkeypatch.setattr(Identifier, "converged_of", lambda self, names: reads.append(1) or orig(self, names))
    _, out = VdpsSystem.replay(MODEL, SystemConfig.for_profile(1000.0, 0.001), paper_samples)
    t = [e.t_ns for e in out if isinstance(e, Estimate)]
    periods = (t[-1] - t[0]) / 20e6
    assert 0.8 * periods <= len(reads) <= periods + 2, (len(reads), periods)
    reads.clear()
    VdpsSystem.replay(MODEL, SystemConfig.for_profile(1000.0, 0.001, convergence_period_s=0.01), paper_samples)
    assert len(reads) > 1.6 * periods  # every estimate: twice as many
    with pytest.raises(ValueError, match="convergence_period_s"):
        SystemConfig(convergence_period_s=0.0)


def test_warning_from_identified_parameters_is_valid_at_once(paper_samples):
    """Started from identified parameters (``start_params``, what ``--params`` sets): no gate, the
    frames are valid from the node's first prediction after the EKF initialises, whatever the
    identifier's flags; a start that had not settled the policy's problems keeps those gated; an explicit
    ``require_converged`` overrides the rule either way; unknown problem names are refused."""
    system, rows = _live_status(SystemConfig.for_profile(1000.0, 0.001, start_params=MODEL.params), paper_samples)
    assert system.require_converged == ()
    after_init = [r for r in rows if r[4]]
    first_valid = next(k for k, r in enumerate(after_init) if r[1] == 0)
    # the node says 1 until its first prediction is in (prediction_latency_s 20 ms): one frame here
    assert after_init[first_valid][0] - after_init[0][0] <= 0.021
    assert not any(r[1] == 1 for r in after_init[first_valid:])
    assert any(not r[3] for r in after_init[first_valid:])  # valid although cornering had not converged yet
    # a start that had not settled some problems (a parameter file's meta.status): the policy's
    # problems among them are gated, the others not
    for unsettled, gated in ((("cornering", "inertia"), ("cornering",)), (("inertia", "tracking"), ()),
                             (("mass", "tracking", "cornering", "inertia"), ("cornering",))):
        assert VdpsSystem(MODEL, SystemConfig(start_params=MODEL.params,
                                              start_unsettled=unsettled)).require_converged == gated
    assert VdpsSystem(MODEL, SystemConfig(start_unsettled=("inertia",))).require_converged == ("cornering",)
    # explicit overrides
    assert VdpsSystem(MODEL, SystemConfig(require_converged=())).require_converged == ()
    assert VdpsSystem(MODEL, SystemConfig(start_params=MODEL.params,
                                          require_converged=("mass",))).require_converged == ("mass",)
    with pytest.raises(ValueError, match="unknown identification problem"):
        VdpsSystem(MODEL, SystemConfig(require_converged=("cornering_stiffness",)))


def test_replay_of_the_input_log_is_bit_identical(paper_samples):
    cfg = SystemConfig.for_profile(1000.0, 0.001)
    live = VdpsSystem(MODEL, cfg)
    out = []
    for s in paper_samples:
        out += live.handle(s)
    out += live.finish()
    assert live.input_log == tuple(paper_samples)
    _, again = VdpsSystem.replay(MODEL, cfg, live.input_log)
    assert len(again) == len(out) > 1000
    assert outputs_digest(again) == outputs_digest(out)
    # the digest is sensitive: one sample less changes it
    _, fewer = VdpsSystem.replay(MODEL, cfg, live.input_log[:-500])
    assert outputs_digest(fewer) != outputs_digest(out)


def test_live_system_holds_no_replay_log_and_gives_the_same_outputs(paper_samples, paper_run):
    """keep_input_log=False (the live bench): neither the system nor its estimator keeps more
    than 4096 samples (a long bench's memory stays flat), and the outputs are those of the
    logging system (the log is only a record)."""
    live = VdpsSystem(MODEL, SystemConfig.for_profile(1000.0, 0.001, keep_input_log=False, **_hold(0.0)))
    out, held = [], 0
    for s in paper_samples:
        out += live.handle(s)
        held = max(held, len(live.pipeline.input_log))
    out += live.finish()
    assert len(paper_samples) > 2 * 4096 and live.input_log == () and held <= 4096
    assert outputs_digest(out) == outputs_digest(paper_run[1])


def test_refuses_truth_and_ignores_truth_samples():
    with pytest.raises(ValueError, match="model vehicle"):
        VdpsSystem(load_vehicle("sedan-truth"))
    s = VdpsSystem(MODEL, SystemConfig(predict=False))
    assert s.handle(Sample(0, "/truth/state", "truth", {"gnss_lat_deg": 1.0})) == []
    assert s.pipeline.counters["truth_ignored"] == 1


# ------------------------------------------------------------------ acceptance through the chain
def test_nees_of_five_seeded_runs_through_the_real_chain():
    """Issue 5's NEES check on the real chain (wire formats -> decode -> system), 5 runs of the
    ISO 3888 lane change, table1-susp1k, 12 s each, epochs after 5 s, two-sided 95 % band of the
    averaged NEES ([7.28, 15.48] for 5 runs x 11 states). Measured on these seeds: 99.9 % of the
    epochs inside, mean NEES / n = 0.95. The 25-run version (tools/nees_study.py, band [9.24,
    12.91]) reaches 90.2 % inside, mean NEES / n = 1.01 (above the band only at the end of the
    lane change, 5-6.5 s, up to 1.21 n). Asserted with a margin for changes in the estimator's
    tuning: >= 85 % inside, mean NEES / n in 0.8-1.25."""
    m = _nees_tool()
    runs = [m.run_chain("lane-change-iso3888", 100 + k, duration_s=12.0) for k in range(5)]
    s = m.nees_summary(runs)
    assert s["runs"] == 5 and s["n_states"] == 11 and s["epochs"] >= 690
    assert s["fraction_inside"] >= 0.85
    assert 0.8 <= s["mean_nees_per_state"] <= 1.25


def test_gnss_outage_keeps_the_position_bounded_and_recovers_within_2_s():
    """10 s outage from 5 s on the paper's scenario: the horizontal error stays within 3 sigma of
    the filter's own (growing) sigma and under 2 m (measured max 1.0 m), and is back at its
    pre-outage level within 2 s of GNSS returning."""
    m = _nees_tool()
    d = m.outage_study(1, duration_s=18.0)
    assert d["max_error_over_3sigma_during"] < 1.0
    assert d["max_error_during_m"] < 2.0
    assert d["sigma_at_outage_end_m"] > 2 * d["sigma_before_m"]  # the filter knows it drifts
    assert 0.0 <= d["recovery_s"] <= 2.0
    assert d["error_2s_after_m"] < d["max_error_during_m"]


def test_identification_through_the_chain_finds_the_mass():
    """Paper scenario, table1-susp1k, 10.25 s, seeded: the mass from wrong priors (+15 %) through
    decode -> EKF -> feeder -> RLS; measured +0.07 %, asserted within 0.5 % (issue 6's bar)."""
    buf = io.BytesIO()
    Drive("paper", profile=load_profile("table1-susp1k"), seed=3, duration_s=10.25).run(buf)
    buf.seek(0)
    system, _ = VdpsSystem.replay(MODEL, SystemConfig.for_profile(1000.0, 0.001, predict=False),
                                  decode_recording(buf))
    truth = load_vehicle("sedan-truth").params  # test harness only
    m = system.params.mass_kg
    assert abs(m - truth.mass_kg) / truth.mass_kg < 0.005
    assert abs(MODEL.params.mass_kg - truth.mass_kg) > 30 * abs(m - truth.mass_kg)
    for n in ("tracking_stiffness_1_n", "cornering_stiffness_front_nprad"):  # moved towards the truth
        assert abs(getattr(system.params, n) - getattr(truth, n)) < 0.5 * abs(getattr(MODEL.params, n) - getattr(truth, n))
    assert math.isfinite(system.identifier.sigmas["mass_kg"])


# ---------------------------------------------------------------- saved workbench models (--model)

def test_system_predictor_uses_the_saved_model_drag():
    """Physics: a held-input prediction from 25 m/s with zero torque loses about
    0.5 rho CdA v^2 / m * 5 s more speed with the model's CdA = 2 m^2 (766 N at 25 m/s, about
    0.45 m/s^2 on 1700 kg, falling with v): 1.5-3.0 m/s more, from the same state."""
    from vdps_hil.model.effects import REGISTRY, EffectSet
    from vdps_hil.prediction.initial_state import PredictorInitialState

    veh = load_vehicle("sedan-model", "model").with_params(mass_kg=1700.0)
    r = veh.tire.rolling_radius_m if hasattr(veh, "tire") and hasattr(veh.tire, "rolling_radius_m") else 0.3
    init = PredictorInitialState(t_ns=0, pos_g_m=(0, 0, 0.55), vel_g_mps=(25.0, 0, 0), euler_g_rad=(0, 0, 0),
                                 road_bank_rad=0.0, road_grade_rad=0.0, rate_b_radps=(0, 0, 0),
                                 wheel_speed_radps=(25.0 / r,) * 4)
    end = {}
    for label, eff in (("plain", None), ("drag", EffectSet([REGISTRY["aero_drag"](cda_m2=2.0)]))):
        system = VdpsSystem(veh, SystemConfig(identify=False, model_effects=eff))
        res = system.predictor.predict(init)
        end[label] = float(res.vel_b_mps[-1][0])
    assert 1.5 <= end["plain"] - end["drag"] <= 3.0, end


# ------------------------------------------------------------------ fault tolerance (issue 20)
_ERR_STATES = (0, 1, 3, 4, 6, 7, 8)  # horizontal position, horizontal velocity, roll, pitch, yaw


def _recovered(r, t_back_s: float, t_fault_s: float) -> dict:
    """Per state of _ERR_STATES: the share of epochs within the filter's own 3 sigma, and
    whether from t_back + 2 s on the error stays at its pre-fault level: below max(2 x its 95th
    percentile over the 2 s before the fault, 3 x the mean sigma then)."""
    t, e, s = r["t_s"], np.abs(r["err"]), r["sigma"]
    inside = np.mean([(e[:, i] <= 3.0 * s[:, i]) for i in _ERR_STATES])
    before = (t >= t_fault_s - 2.0) & (t < t_fault_s)
    after = t >= t_back_s + 2.0
    back = all(e[after, i].max() <= max(2.0 * np.percentile(e[before, i], 95), 3.0 * s[before, i].mean())
               for i in _ERR_STATES)
    return {"inside_3sigma": float(inside), "recovered": back}


def test_imu_disconnect_is_bridged_honestly_and_recovered_within_2_s():
    """Issue 20 finding 2: the IMU's serial line is cut for 2 s (3-5 s) on the paper's drive.
    Today's filter predicted on the last input with the IMU's own noise (velocity sigma 0.03 m/s
    while the error grew to 20 m/s) and then gated every fix. Specification: the errors stay
    within the filter's own 3 sigma in >= 99 % of the epochs (position, velocity, attitude), the
    velocity sigma grows with the outage (here > 10 x), and 2 s after the IMU returns every error
    is back at its pre-fault level."""
    m = _nees_tool()
    r = m.run_chain("paper", 11, duration_s=9.0, faults=["serial_disconnect:device=imu,t_s=3,duration_s=2"])
    d = _recovered(r, 5.0, 3.0)
    assert d["inside_3sigma"] >= 0.99
    assert d["recovered"]
    t, s = r["t_s"], r["sigma"]
    assert s[(t > 4.8) & (t < 5.0), 3].max() > 10.0 * s[(t > 2.0) & (t < 3.0), 3].mean()


def test_imu_disconnect_shows_sensor_missing_also_before_the_identification_converged():
    """close/20.md: while the identifier (started from the model file's priors) had not
    converged, an IMU disconnect left the frames at 1 "not converged", hiding 2 "sensor missing".
    Here (seed 7) the identification status is 1 from 1.61 s; the IMU is cut at 1.65 s for 0.25 s.
    Specification: every frame from 30 ms after the cut to its end says 2 (old code: 1)."""
    buf = io.BytesIO()
    Drive("paper", seed=7, duration_s=3.0, faults=["serial_disconnect:device=imu,t_s=1.65,duration_s=0.25"]).run(buf)
    buf.seek(0)
    _, out = VdpsSystem.replay(MODEL, SystemConfig.for_profile(1000.0, 0.001), list(decode_recording(buf)))
    dec = VdpsCanDecoder()
    rows = [(d.t_ns * 1e-9, int(d.fields["warning_status"]))
            for o in out if isinstance(o, CanFrame) for d in dec.decode(o.t_ns, o.arbitration_id, o.data)]
    assert [st for t, st in rows if 1.6 < t < 1.65] and {st for t, st in rows if 1.6 < t < 1.65} == {1}
    during = [st for t, st in rows if 1.68 < t < 1.9]
    assert len(during) >= 8 and set(during) == {2}, sorted(set(during))


def test_gyro_spike_is_rejected_and_no_valid_warning_is_sent():
    """Issue 20 finding 3: a 50 ms, 200 deg/s yaw-rate spike at 5 s on the paper's drive (no
    rollover). Specification: no VDPS_Warning of level >= 2 with status valid; the frames during
    the fault are not valid (status 2, sensor missing) and valid frames return within 2 s; the
    yaw error stays below 1 deg (the spike would integrate to 10 deg)."""
    buf = io.BytesIO()
    Drive("paper", seed=7, duration_s=8.0, faults=["gyro_spike:t_s=5,duration_s=0.05,amplitude_degps=200"]).run(buf)
    buf.seek(0)
    samples = list(decode_recording(buf))
    system, out = VdpsSystem.replay(MODEL, SystemConfig.for_profile(1000.0, 0.001, start_params=MODEL.params),
                                    samples)
    dec = VdpsCanDecoder()
    rows = [(d.t_ns * 1e-9, int(d.fields["warning_level"]), int(d.fields["warning_status"]))
            for o in out if isinstance(o, CanFrame) for d in dec.decode(o.t_ns, o.arbitration_id, o.data)]
    assert not [r for r in rows if r[1] >= 2 and r[2] == 0]
    during = [r for r in rows if 5.0 < r[0] < 5.3]
    assert during and all(r[2] == 2 for r in during)
    assert any(r[2] == 0 for r in rows if 5.3 <= r[0] <= 7.0)
    assert system.pipeline.imu_monitor.counters["spike"] == 50
    m = _nees_tool()
    r = m.run_chain("paper", 7, duration_s=8.0, faults=["gyro_spike:t_s=5,duration_s=0.05,amplitude_degps=200"])
    assert np.degrees(np.abs(r["err"][r["t_s"] > 4.0, 8])).max() < 1.0


def test_a_5_s_imu_outage_in_the_lane_change_is_bridged_and_recovered_within_2_s():
    """Issue 20's campaign: the IMU cut for 5 s (2.5-7.5 s) of the ISO 3888 lane change. With
    the iterated update right after the IMU's return, one y1_sus update moved the yaw by 4.6 deg
    and left a 0.15 deg roll/bank error against a 0.04 deg sigma for 2 s (96.5 % of the epochs
    within 3 sigma on the campaign's seed 21). Specification: >= 99 % of the epochs within the
    filter's own 3 sigma and every error back at its pre-fault level 2 s after the return (seed
    13, not the campaign's)."""
    r = _nees_tool().run_chain("lane-change-iso3888", 13, duration_s=10.0,
                               faults=["serial_disconnect:device=imu,t_s=2.5,duration_s=5"])
    d = _recovered(r, 7.5, 2.5)
    assert d["inside_3sigma"] >= 0.99, d
    assert d["recovered"], d


def test_a_gnss_outage_over_the_fishhook_tip_up_keeps_the_attitude_honest():
    """Issue 20's campaign: the GNSS out for 2 s (0.4-2.4 s) of the SUV fishhook, over its
    two-wheel tip-up. The lifted wheels' suspension deflections were taken as the body's attitude
    over the road: a 1.7 deg yaw error against a 0.25 deg sigma (90.5 % within 3 sigma on seed
    21). Specification: the suspension updates stop while a wheel is unloaded (counted as
    lift_off), >= 99 % of the epochs within 3 sigma and the yaw error below 1 deg (seed 14)."""
    r = _nees_tool().run_chain("fishhook-suv", 14, vehicle="suv-model",
                               faults=["gnss_outage:t_s=0.4,duration_s=2"])
    t, e, s = r["t_s"], np.abs(r["err"]), r["sigma"]
    live = t >= t[0] + 0.8
    inside = np.mean([(e[live, i] <= 3.0 * s[live, i]) for i in _ERR_STATES])
    assert inside >= 0.99, inside
    assert np.degrees(e[live, 8]).max() < 1.0
    assert r["pipeline_counters"]["lift_off"] > 0
