"""The paper's experiments (Hsu & Chen 2012, sections 7-8, Tables 2-3) on the simulator, through
the real chain, with the paper's published values next to ours (``vdps paper``).

The chain and the harness
-------------------------
Every experiment simulates a drive (``sim.drive.Drive``: truth simulator + sensor models on the
real wire formats, into an in-memory MCAP recording), decodes only its ``/raw/`` topics
(``record.decode``) and feeds the samples to :class:`~vdps_hil.pipeline.node.VdpsSystem` (EKF,
alpha-beta, identification feeder, the four RLS problems, predictor, warning node) built on a
*model* vehicle file. The harness here reads ``/truth/state``, ``/truth/events`` and the truth
vehicle file's parameters only to SCORE what the chain produced; nothing from the truth reaches
the chain. "Noise-free" always means zero-noise sensors (``SensorProfile.zero_noise()``), never
``/truth/``.

Experiments (one row of the printed table each)
-----------------------------------------------
* **Fusion (Fig 4)**: scenario ``paper``; per run the standard deviation over 5-10 s of
  (estimate - truth) of the 12 states of eq 7 and the road-relative roll/pitch (eq 4); mean over
  the seeds. The paper prints these only inside Figure 4 (not in its text): no paper column.
* **Identification (section 7.2, Figs 6-7)**: scenario ``paper-left-turn`` (identical to
  ``paper`` until 10.25 s). Relative error e = (identified - true) / true of each of the ten
  ``IdentifiedParams`` at t = 10.25 s, and the mean of the identified value over 5-10.25 s
  (issue 6: the paper's "15th to the 10th second" read as 5-10.25 s) against the truth. Over
  the seeds: median and 90th percentile of |e| [%], and ``within_2_sigma`` = the fraction of
  seeds with |identified - true| <= 2 sigma (the identifier's own sigma at 10.25 s, upstream
  uncertainty included). "True" tire stiffnesses are the truth file's linear slip stiffnesses,
  i.e. the Magic Formula's slopes at zero slip: the paper (section 7.2) and we expect them not to
  converge to those exactly (its truth has no such parameters).
* **Left turn (section 7.3, Fig 8)**: the same drive; the predictor is started at t0 = 10.25 s
  from the chain's estimate and filtered signals at t0 (``PredictorInitialState.from_estimator``,
  held inputs = the last samples before t0) with the parameters identified by then, horizon
  4.75 s, and compared with the truth over 10.25-15 s (``prediction.metrics``: position error
  and yaw error at the horizon's end, paper-style inaccuracy; paper 0.51 %).
* **Warning validity**: a drive that starts from the model file's priors (deliberately wrong:
  C_alpha front x1.5, rear x0.6, an oversteering model) sends its warnings with status "not
  converged" until the cornering problem has converged (the system's default policy:
  ``require_converged`` in ``configs/prediction/default.toml`` ``[warning]``, applied when the
  identifier starts from the priors; sigma/|x| < ``converged_rel_sigma``): from the priors the
  predictor foresaw rollovers in the paper's sine steering (2 of 20 seeds, at 0.8-2.0 s). The
  rollover and test-track drives start, as a car does after its first drive, from the
  parameters the chain identified on a calibration drive of the same vehicle
  (``ROLLOVER_CALIBRATION`` = ``paper``, seed + 1000; ``vdps replay --save-params/--params``)
  and their warnings are valid from the start.
* **Rollover (Fig 9 / the rollover scenario ``fishhook-suv``)**: the SUV fishhook through the
  whole chain (``suv-model``, started from the parameters identified on ``paper`` driven with
  ``suv-truth``). ``predicted``: a prediction of the chain's warning path forecast a
  point of no return before the truth reached it. Its inaccuracy: the first such prediction,
  re-run from the same estimate, parameters and held inputs, compared with the truth from its
  t0 to the end of the prediction (paper 27.3 % for its own Fig 9 over 10.25-11.5 s). That
  first forecast comes before the fishhook's steering reversal, so holding its inputs is a
  poor guess of the future; ``held_inputs`` scores the first prediction after the last change
  of the measured inputs (steering within 0.02 rad, torques within 20 N m until the point of
  no return), the paper's own Fig 9 situation, where the held inputs are the true ones.
  **Warning**: the VDPS_Warning frames the chain sent, decoded with CRC and counter checks
  (``evaluate_warning_frames``): lead time to the truth point of no return and to tip-up.
* **False alarms**: warning episodes (level >= warning, status valid) on ``paper-left-turn`` (every
  identification seed, from the priors) and the test-track scenarios ``lane-change-iso3888``,
  ``sine-sweep`` and ``circle-iso4138`` (sedan, from calibrated parameters), none of which
  rolls over in the truth; with the fraction of frames that were valid.
* **Table 2 (SNR)**: identification of I_x, I_y, I_z at 10.25 s with the sensor noise scaled by k
  (every Table 1 sigma times k; k = 0 is the zero-noise row, the paper's "infinite"). SNR, as the
  paper's section 8 ("the signal is ... the estimated vehicle dynamics from the sensor fusion
  system, while the noise is ... the estimation error"), on the inertia problem's inputs over
  5-10.25 s, with the estimation error *due to the sensors' noise*: the same drive (same seed,
  same truth) through the chain with zero-noise sensors is the reference::

      SNR_dB = -10 log10( (1/6) sum_c var(s_k,c - s_0,c) / var(s_k,c) )
      s = (omega_dot_x, omega_dot_y, omega_dot_z, M_x, M_y, M_z)

  (alpha-beta angular accelerations [rad/s^2] and eq 23's moments [N m] from the chain's
  identifier inputs, computed with the model file's priors so every run uses the same
  parameters). Against the truth instead, the alpha-beta's own lag sets a floor of ~19 dB even
  with perfect sensors, which would hide the noise. The k for the paper's 30/20/10 dB rows come
  from the runs at k = 1 (``snr_noise_scale``: the noise error is linear in k, and the noise is
  in var(s_k) too, so each channel's ratio saturates; median over the seeds); each row prints
  the SNR it measured.
* **Table 3 (weighting)**: noise-free sensors, scenario ``paper`` for ``table3_duration_s``; the
  inertia problem re-run on the chain's recorded identifier inputs (the identifier is downstream
  of the estimator, so this is the chain's computation) with Q_4 = diag(q, q, q), W_4 = I and
  P(0) = I (``p0_scaled = 1``, ``problems`` misprint note 13) for the paper's four q. Reported:
  the minimum eigenvalue of sum A^T Q^T Q A at the end, and the convergence time (Table 3
  footnote a: "the time when the estimated value reaches 90 % of the real value"; we take the
  first time from which |e| <= 10 % holds to the end of the run; NaN: never).

Symbols: e relative error [-] (printed in %), sigma identifier standard deviation (same unit as
the parameter), k noise scale [-], SNR [dB], q weighting [1/(N m)], times [s].
"""

from __future__ import annotations

import dataclasses
import io
import math
import os
import time
from dataclasses import dataclass, replace
from typing import Any, Callable, Iterable, Mapping, Sequence

import numpy as np

__all__ = ["PAPER", "PaperOptions", "PROFILES", "run_paper", "format_report", "chain_run", "scale_noise",
           "identification_task", "rollover_task", "false_alarm_task", "snr_task", "snr_db", "snr_noise_scale",
           "table3_task",
           "aggregate_identification", "relative_errors"]

PROFILES = ("table1-susp1k", "table1")
"""Sensor profiles of the paper's Table 1 (``configs/profiles``)."""

T0_S = 10.25
"""The paper's identification instant and prediction start (section 7.2-7.3) [s]."""
FUSION_WINDOW_S = (5.0, 10.0)
IDENT_WINDOW_S = (5.0, T0_S)
LEFT_TURN_END_S = 15.0
FALSE_ALARM_SCENARIOS = ("lane-change-iso3888", "sine-sweep", "circle-iso4138")
ROLLOVER_CALIBRATION = "paper"
"""The drive (same vehicle) whose identified parameters the rollover drive starts from."""

PAPER: dict[str, Any] = {
    "identification_rel_err_pct": {"mass_kg": 5.17e-3, "inertia_x_kgm2": 0.12, "inertia_y_kgm2": 5.05,
                                   "inertia_z_kgm2": 4.37},
    "left_turn_inaccuracy_pct": 0.51,
    "rollover_inaccuracy_pct": 27.3,
    # Table 2: relative inaccuracy of I_x, I_y, I_z [%] per SNR [dB] (None = "infinite")
    "snr_table": {None: (1.94, 2.68, 0.33), 30.0: (2.50, 14.62, 1.52), 20.0: (14.91, 60.28, 10.41),
                  10.0: (69.05, 93.63, 54.11)},
    # Table 3: time to 90 % of the real value of I_x, I_y, I_z [s] per Q4 = diag(q, q, q) (nan = "Nan")
    "weighting_table": {0.625: (0.08, 1.63, 0.24), 0.125: (6.19, 18.2, 3.32), 0.025: (36.0, math.nan, 25.0),
                        0.005: (math.nan, math.nan, math.nan)},
}
"""The paper's published figures (section 7.2-7.3, section 8 Tables 2-3)."""

INERTIA = ("inertia_x_kgm2", "inertia_y_kgm2", "inertia_z_kgm2")
SNR_TARGETS_DB = (30.0, 20.0, 10.0)


@dataclass(frozen=True)
class PaperOptions:
    """What ``run_paper`` runs. ``quick``: 3 seeds and shortened long runs (stated in the output)."""

    profiles: tuple[str, ...] = PROFILES
    seeds: int = 20
    seed0: int = 1
    fusion: bool = True
    identification: bool = True
    rollover: bool = True
    false_alarms: bool = True
    false_alarm_scenarios: tuple[str, ...] = FALSE_ALARM_SCENARIOS
    false_alarm_max_s: float | None = None  # cut long test-track runs (quick mode)
    snr_table: bool = True
    snr_seeds: int = 3
    weighting_table: bool = True
    table3_duration_s: float = 40.0
    workers: int = 2

    @classmethod
    def quick(cls, **kw) -> "PaperOptions":
        d = dict(seeds=3, snr_seeds=1, table3_duration_s=12.0, false_alarm_max_s=10.0)
        d.update(kw)
        return cls(**d)


# --------------------------------------------------------------------------------- the chain
def scale_noise(profile, k: float):
    """``profile`` with every noise sigma times ``k`` (rates and error switches unchanged);
    k = 0 is ``profile.zero_noise()``."""
    if k == 0.0:
        return profile.zero_noise()
    r = dataclasses.replace
    g, s, i, ta, w, st = (profile.gnss, profile.suspension, profile.imu, profile.tachometer,
                          profile.wheel_torque, profile.steering)
    return r(profile, name=f"{profile.name}-noise-x{k:g}",
             gnss=r(g, attitude_sigma_rad=k * g.attitude_sigma_rad, pos_sigma_h_m=k * g.pos_sigma_h_m,
                    pos_sigma_v_m=k * g.pos_sigma_v_m),
             suspension=r(s, sigma_m=k * s.sigma_m),
             imu=r(i, accel_sigma_mps2=k * i.accel_sigma_mps2, gyro_sigma_radps=k * i.gyro_sigma_radps),
             tachometer=r(ta, sigma_radps=k * ta.sigma_radps), wheel_torque=r(w, sigma_nm=k * w.sigma_nm),
             steering=r(st, sigma_rad=k * st.sigma_rad))


def _profile(p):
    from vdps_hil.sim.profiles import load_profile

    return load_profile(p) if isinstance(p, str) else p


def system_config(profile, *, identify: bool = True, predict: bool = True, ident=None, **kw):
    """The chain as ``vdps replay`` sizes it from a sensor data sheet: the suspension window
    averaging from the profile's suspension rate and sigma (1 mm when the profile is noise-free:
    the EKF keeps the data sheet's figure, it is not told the sensors are perfect)."""
    from vdps_hil.pipeline.node import SystemConfig

    sigma = profile.suspension.sigma_m if profile.suspension.sigma_m > 0 else 0.001
    return SystemConfig.for_profile(profile.suspension.rate_hz, sigma, identify=identify, predict=predict,
                                    ident=ident, **kw)


def chain_run(scenario, profile, seed: int, *, model: str = "sedan-model", duration_s: float | None = None,
              identify: bool = True, predict: bool = True, ident_config=None, sheet_profile=None,
              ident_report_period_s: float = 0.05, capture_t_s: Sequence[float] = (),
              capture_all: bool = False, record_inputs: bool = False, fusion_window_s=None,
              truth_vehicle: str | None = None, system_kw: Mapping[str, Any] | None = None) -> dict:
    """One drive through the real chain (module docstring). Returns a dict:

    ``truth`` (the /truth/state snapshots, harness only), ``events`` (/truth/events),
    ``ident`` [(t_s, params dict, sigmas dict, identifiability dict)], ``captured``
    {t_ns: (PredictorInitialState | None, IdentifiedParams)} at the first estimate at or after
    each of ``capture_t_s`` (or every estimate with ``capture_all``), ``frames`` (sent VDPS_Warning as can.Message),
    ``predictions`` (PredictionReport), ``inputs`` (IdentInputs, with ``record_inputs``),
    ``fusion_std`` (per state over ``fusion_window_s``),
    ``status`` (system counters) and ``wall_s``.
    ``sheet_profile``: the data sheet the chain is configured from (default: ``profile``);
    ``truth_vehicle``: the simulated vehicle instead of the scenario's; ``system_kw``: further
    ``SystemConfig`` fields (``require_converged``, ``start_params``)."""
    import can

    from vdps_hil.estimation.estimates import Estimate
    from vdps_hil.geodesy import DEFAULT_ORIGIN
    from vdps_hil.model.params import load_vehicle
    from vdps_hil.prediction.initial_state import PredictorInitialState
    from vdps_hil.record.decode import decode_recording
    from vdps_hil.record.reader import RecordingReader
    from vdps_hil.sim.drive import Drive
    from vdps_hil.pipeline.node import VdpsSystem
    from vdps_hil.pipeline.outputs import CanFrame, IdentReport, PredictionReport

    wall0 = time.perf_counter()
    prof = _profile(profile)
    buf = io.BytesIO()
    Drive(scenario, profile=prof, seed=seed, duration_s=duration_s, vehicle=truth_vehicle).run(buf)
    buf.seek(0)
    reader = RecordingReader(buf)
    truth = [d["values"] for _, _, d in reader.iter_messages(["/truth/state"])]  # harness only
    events = [d["values"] for _, _, d in reader.iter_messages(["/truth/events"])]
    by_t = {int(s["t_ns"]): s for s in truth}
    sheet = _profile(sheet_profile) if sheet_profile is not None else prof
    cfg = system_config(sheet, identify=identify, predict=predict, ident=ident_config,
                        ident_report_period_s=ident_report_period_s, **dict(system_kw or {}))
    veh = load_vehicle(model, "model")
    system = VdpsSystem(veh, cfg, origin=DEFAULT_ORIGIN)
    cap_ns = sorted(int(round(t * 1e9)) for t in capture_t_s)  # first estimate at or after each
    out: dict = {"truth": truth, "events": events, "ident": [], "captured": {}, "frames": [], "predictions": [],
                 "inputs": [], "model": veh}
    inputs = out["inputs"]
    if record_inputs and system.feeder is not None:
        feed = system.feeder.inputs

        def recording_inputs(est, filt):
            inp = feed(est, filt)
            if inp is not None:
                inputs.append(inp)
            return inp
        system.feeder.inputs = recording_inputs
    fus_rows = []
    ekf = system.pipeline.ekf
    for s in decode_recording(reader):
        outs = system.handle(s)
        system.clear_input_log()
        for o in outs:
            if isinstance(o, Estimate):
                if capture_all or (cap_ns and o.t_ns >= cap_ns[0]):
                    while cap_ns and o.t_ns >= cap_ns[0]:
                        cap_ns.pop(0)
                    try:
                        init = PredictorInitialState.from_estimator(o, system.pipeline.filtered())
                    except ValueError:
                        init = None
                    out["captured"][o.t_ns] = (init, system.params)
                tv = truth_at(by_t, o.t_ns) if fusion_window_s else None
                if tv is not None and ekf.initialized:
                    if fusion_window_s and fusion_window_s[0] <= tv["t_s"] <= fusion_window_s[1]:
                        fus_rows.append(_fusion_error(o, tv))
            elif isinstance(o, IdentReport):
                out["ident"].append((o.t_ns / 1e9, dict(o.params), dict(o.sigmas), dict(o.identifiability)))
            elif isinstance(o, PredictionReport):
                out["predictions"].append(o)
            elif isinstance(o, CanFrame):
                out["frames"].append(can.Message(timestamp=o.t_ns / 1e9, arbitration_id=o.arbitration_id,
                                                 data=o.data, is_extended_id=False))
    for o in system.finish():
        if isinstance(o, CanFrame):
            out["frames"].append(can.Message(timestamp=o.t_ns / 1e9, arbitration_id=o.arbitration_id,
                                             data=o.data, is_extended_id=False))
    reader.close()
    if fus_rows:
        out["fusion_std"] = _fusion_std(fus_rows)
    out["status"] = system.status()["counters"]
    out["identifier"] = system.identifier
    out["wall_s"] = time.perf_counter() - wall0
    return out


TRUTH_GRID_NS = 10_000_000
_ANGLES = {"roll_g_rad", "pitch_g_rad", "yaw_g_rad", "roll_v_rad", "pitch_v_rad", "yaw_v_rad", "road_bank_rad",
           "road_grade_rad"}


def truth_at(by_t: Mapping[int, Mapping], t_ns: int, grid_ns: int = TRUTH_GRID_NS) -> dict | None:
    """The truth snapshot at ``t_ns``: exact on the 100 Hz grid, else linear between the two
    neighbouring snapshots (angles along their wrapped difference) with ``t_ns`` set; None
    outside. For scoring harnesses (this module, tools/nees_study.py, tests) only: the chain
    never reads truth."""
    if t_ns in by_t:
        return by_t[t_ns]
    t0 = t_ns - t_ns % grid_ns
    a, b = by_t.get(t0), by_t.get(t0 + grid_ns)
    if a is None or b is None:
        return None
    w = (t_ns - t0) / grid_ns
    out = {}
    for k, va in a.items():
        vb = b.get(k)
        if isinstance(va, bool) or not isinstance(va, (int, float)) or not isinstance(vb, (int, float)):
            continue
        d = math.remainder(vb - va, 2 * math.pi) if k in _ANGLES else vb - va
        out[k] = va + w * d
    out["t_ns"] = t_ns
    return out


_FUSION_TRUTH = ("pos_e_m", "pos_n_m", "pos_u_m", "vel_g_mps_e", "vel_g_mps_n", "vel_g_mps_u", "roll_g_rad",
                 "pitch_g_rad", "yaw_g_rad", "road_bank_rad", "road_grade_rad", "yaw_v_rad")
FUSION_NAMES = ("x_g_m", "y_g_m", "z_g_m", "vx_g_mps", "vy_g_mps", "vz_g_mps", "phi_g_deg", "theta_g_deg",
                "psi_g_deg", "phi_r_deg", "theta_r_deg", "psi_v_deg", "phi_v_deg", "theta_v_deg")
"""Fig 4's states: eq 7 (ENU position, velocity, absolute attitude, road bank and grade, psi_v)
and the road-relative roll and pitch of eq 4."""


def _fusion_error(est, tv) -> np.ndarray:
    e = np.array(est.x[:12], dtype=float) - np.array([tv[k] for k in _FUSION_TRUTH])
    for i in (8, 11):
        e[i] = math.remainder(e[i], 2 * math.pi)
    ev = np.array(est.vehicle_angles_rad[:2], dtype=float) - np.array([tv["roll_v_rad"], tv["pitch_v_rad"]])
    return np.concatenate([e, ev])


def _fusion_std(rows) -> dict:
    std = np.std(np.array(rows), axis=0)
    return {n: float(math.degrees(v) if n.endswith("_deg") else v) for n, v in zip(FUSION_NAMES, std)}


# --------------------------------------------------------------------------------- scoring
def truth_params(model: str = "sedan-model") -> dict[str, float]:
    """The truth vehicle file's ten parameters (harness only: the scores' reference)."""
    from vdps_hil.model.params import load_vehicle

    truth = {"sedan-model": "sedan-truth", "suv-model": "suv-truth"}[model]
    return load_vehicle(truth, "truth").params.as_dict()


def relative_errors(params: Mapping[str, float], truth: Mapping[str, float]) -> dict[str, float]:
    """(identified - true) / true per parameter [-]."""
    return {k: (float(params[k]) - truth[k]) / truth[k] for k in truth}


def _report_at(ident: list, t_s: float, tol_s: float = 0.005):
    """The last identifier report at or before ``t_s`` (+ ``tol_s``: report instants follow the
    filter's clock, which may pass a multiple of the period by a sample)."""
    best = None
    for r in ident:
        if r[0] <= t_s + tol_s:
            best = r
    return best


def _truth_from(truth: list, t0_s: float, t_end_s: float):
    """The truth pose trajectory from exactly ``t0_s`` (interpolated) to ``t_end_s``."""
    from vdps_hil.prediction.metrics import PoseTrajectory

    tr = PoseTrajectory.from_snapshots(truth, t0_s - 0.02, t_end_s)
    t = tr.t_s[tr.t_s > t0_s + 1e-9]
    return tr.at(np.concatenate([[t0_s], t]))


# ------------------------------------------------------------------------------------ tasks
def identification_task(profile: str, seed: int, *, predict: bool = True, zero_noise: bool = False,
                        scenario: str = "paper-left-turn", effects_override=None) -> dict:
    """Identification at 10.25 s and over 5-10.25 s, fusion errors over 5-10 s, the left-turn
    prediction from 10.25 s and the warning frames of the whole drive (false alarms)."""
    from vdps_hil.prediction.metrics import PoseTrajectory, compare_trajectories
    from vdps_hil.prediction.config import load_predictor_config
    from vdps_hil.prediction.predictor import Predictor
    from vdps_hil.prediction.warning import evaluate_warning_frames

    prof = _profile(profile)
    sheet = prof
    if zero_noise:
        prof = prof.zero_noise()
    sc = scenario
    if effects_override is not None:
        from vdps_hil.sim.scenarios import load_scenario

        sc = replace(load_scenario(scenario), effect_names=tuple(effects_override))
    r = chain_run(sc, prof, seed, predict=predict, sheet_profile=sheet, capture_t_s=(T0_S,),
                  fusion_window_s=FUSION_WINDOW_S)
    tp = truth_params()
    rep = _report_at(r["ident"], T0_S)
    doc: dict = {"profile": profile, "seed": seed, "zero_noise": zero_noise, "wall_s": r["wall_s"]}
    doc["fusion_std"] = r.get("fusion_std")
    prior = r["model"].params.as_dict()
    doc["prior_rel_err"] = relative_errors(prior, tp)
    if rep is not None:
        doc["t_ident_s"] = rep[0]
        doc["rel_err"] = relative_errors(rep[1], tp)
        doc["sigma_ratio"] = {k: abs(rep[1][k] - tp[k]) / rep[2][k] if rep[2][k] > 0 else math.inf for k in tp}
        doc["identifiability"] = rep[3]
        win = [x for x in r["ident"] if IDENT_WINDOW_S[0] - 1e-9 <= x[0] <= IDENT_WINDOW_S[1] + 1e-9]
        mean = {k: float(np.mean([x[1][k] for x in win])) for k in tp}
        doc["rel_err_mean_window"] = relative_errors(mean, tp)
    cap_t = min(r["captured"], default=None)
    cap = r["captured"].get(cap_t)
    if cap is not None and cap[0] is not None:
        init, params = cap
        t0 = cap_t / 1e9
        pcfg = replace(load_predictor_config(), horizon_s=LEFT_TURN_END_S - t0)
        pred = Predictor(r["model"].with_params(**params.as_dict()), pcfg).predict(init)
        true = _truth_from(r["truth"], t0, LEFT_TURN_END_S)
        m = compare_trajectories(PoseTrajectory.from_prediction(pred), true)
        doc["left_turn"] = {"t0_s": t0}
        doc["left_turn"].update({k: m[k] for k in ("position_err_m", "yaw_err_deg", "pitch_err_deg", "roll_err_deg",
                                               "position_rms_m", "yaw_rms_deg", "inaccuracy_pct", "t_end_s")})
        doc["left_turn"]["inaccuracy_channels_pct"] = m["inaccuracy_channels_pct"]
    if predict:
        o = evaluate_warning_frames(r["frames"], r["events"])
        doc["warning"] = _warning_summary(o, r)
    return doc


def rollover_task(profile: str, seed: int, scenario: str = "fishhook-suv", model: str = "suv-model",
                  truth_vehicle: str = "suv-truth", calibration: str | None = ROLLOVER_CALIBRATION) -> dict:
    """The rollover scenario through the whole chain: lead time of the sent warning frames and
    the inaccuracy of the first prediction that forecast the point of no return. With
    ``calibration`` the chain starts from the parameters it identified on an earlier drive of
    the same vehicle (that scenario, another seed), as a car keeps them between drives
    (``vdps replay --save-params`` / ``--params``), and its warnings are valid from the start;
    without, it starts from the priors and waits for the cornering stiffnesses to converge."""
    from vdps_hil.prediction.metrics import PoseTrajectory, compare_trajectories
    from vdps_hil.prediction.config import load_predictor_config
    from vdps_hil.prediction.predictor import Predictor
    from vdps_hil.prediction.warning import evaluate_warning_frames

    kw, cal_doc = _start_kw(profile, seed, model, truth_vehicle, calibration)
    r = chain_run(scenario, profile, seed, model=model, capture_all=True, system_kw=kw)
    o = evaluate_warning_frames(r["frames"], r["events"])
    t_pn = o.truth_point_of_no_return_t_s
    doc: dict = {"profile": str(profile), "seed": seed, "wall_s": r["wall_s"],
                 "lead_time_s": o.lead_time_s, "lead_to_tipup_s": o.lead_to_tip_up_s,
                 "lead_time_matched_side_s": o.lead_time_matched_side_s,
                 "first_warning_t_s": o.first_warning_t_s, "truth_point_of_no_return_t_s": t_pn,
                 "truth_tip_up_t_s": o.truth_tip_up_t_s, "false_alarms": o.false_alarms,
                 "frames_rejected": o.frames_rejected, "calibration": cal_doc,
                 "valid_fraction": _warning_summary(o, r)["valid_fraction"]}
    first = next((p for p in r["predictions"] if p.time_to_point_of_no_return_s is not None
                  and (math.isnan(t_pn) or p.t0_ns / 1e9 < t_pn)), None)
    doc["predicted"] = bool(first is not None and not math.isnan(t_pn))

    def score(t0_ns: int) -> dict:
        init, params = r["captured"][t0_ns]
        pred = Predictor(r["model"].with_params(**params.as_dict()), load_predictor_config()).predict(init)
        t0 = t0_ns / 1e9
        end = min(t0 + pred.horizon_reached_s, r["truth"][-1]["t_s"])
        m = compare_trajectories(PoseTrajectory.from_prediction(pred), _truth_from(r["truth"], t0, end))
        return {"prediction_t0_s": t0, "prediction_end_s": m["t_end_s"],
                "predicted_point_of_no_return_t_s": None if pred.point_of_no_return_t_s is None
                else t0 + pred.point_of_no_return_t_s,
                "inaccuracy_pct": m["inaccuracy_pct"], "position_err_m": m["position_err_m"],
                "roll_err_deg": m["roll_err_deg"]}

    if first is not None and first.t0_ns in r["captured"] and r["captured"][first.t0_ns][0] is not None:
        doc.update(score(first.t0_ns))
    held = _first_held_inputs_t0(r["captured"], t_pn)
    if held is not None:
        doc["held_inputs"] = score(held)
    return doc


HELD_STEER_TOL_RAD = 0.02
HELD_TORQUE_TOL_NM = 20.0
"""Inputs count as held from a prediction's t0 on when the measured steering-wheel angle and
wheel torques stay within these of their t0 values until the truth's point of no return."""


def _first_held_inputs_t0(captured: dict, t_end_s: float) -> int | None:
    """t0 [ns] of the first captured prediction after which the chain's measured inputs
    (steering, wheel torques; what the predictor holds) no longer change before ``t_end_s``: the
    paper's Fig 9 case, where the prediction starts after the last input change and the held
    inputs are the true ones. None when there is no such prediction."""
    rows = sorted((t, v[0].inputs) for t, v in captured.items() if v[0] is not None
                  and (math.isnan(t_end_s) or t / 1e9 < t_end_s))
    for i, (t0, u0) in enumerate(rows):
        if all(abs(u.steer_wheel_angle_rad - u0.steer_wheel_angle_rad) <= HELD_STEER_TOL_RAD
               and max(abs(a - b) for a, b in zip(u.wheel_torque_nm, u0.wheel_torque_nm)) <= HELD_TORQUE_TOL_NM
               for _, u in rows[i:]):
            return t0 if i + 1 < len(rows) else None
    return None


def _warning_summary(o, r) -> dict:
    """False alarms and how much of the run the warning was valid (status 0)."""
    valid = [d["t_s"] for d in o.decoded if d["valid"]]
    n = len(o.decoded)
    return {"false_alarms": o.false_alarms, "episodes": o.warning_episodes, "frames_accepted": o.frames_accepted,
            "frames_rejected": o.frames_rejected, "truth_events": len(r["events"]),
            "valid_fraction": len(valid) / n if n else 0.0, "first_valid_t_s": valid[0] if valid else None,
            "max_level": max((d["level"] for d in o.decoded), default=0)}


def _start_kw(profile, seed: int, model: str, truth_vehicle: str | None, calibration: str | None):
    """SystemConfig fields of a drive: from the parameters identified on a calibration drive of
    the same vehicle (valid warnings from the start), or from the priors (warnings valid once the
    warning policy's ``require_converged`` problems have converged: the system's default rule);
    and a summary of the calibration."""
    if not calibration:
        return {}, None
    cal = chain_run(calibration, profile, seed + 1000, model=model, truth_vehicle=truth_vehicle, predict=False,
                    ident_report_period_s=1.0)
    start = cal["identifier"].params
    return ({"start_params": start},
            {"scenario": calibration, "seed": seed + 1000, "rel_err": relative_errors(start.as_dict(),
                                                                                       truth_params(model))})


def false_alarm_task(scenario: str, profile: str, seed: int, max_s: float | None = None,
                     calibration: str | None = ROLLOVER_CALIBRATION) -> dict:
    """A drive that does not roll over, through the chain: warning episodes sent. By default the
    chain starts from parameters identified on a calibration drive (as ``rollover_task``), so
    its warnings are valid for the whole run."""
    from vdps_hil.prediction.warning import evaluate_warning_frames
    from vdps_hil.sim.scenarios import load_scenario

    dur = load_scenario(scenario).duration_s
    if max_s is not None:
        dur = min(dur, max_s)
    kw, cal_doc = _start_kw(profile, seed, "sedan-model", None, calibration)
    r = chain_run(scenario, profile, seed, duration_s=dur, ident_report_period_s=1.0, system_kw=kw)
    o = evaluate_warning_frames(r["frames"], r["events"])
    doc = {"scenario": scenario, "profile": str(profile), "seed": seed, "duration_s": dur, "wall_s": r["wall_s"],
           "calibration": cal_doc}
    doc.update(_warning_summary(o, r))
    return doc


def snr_task(profile: str, k: float, seed: int) -> dict:
    """Inertia identification at 10.25 s with every sensor sigma times k, and the SNR series
    (omega_dot, eq 23 moments at the estimate instants of 5-10.25 s; module docstring)."""
    from vdps_hil.identification.config import load_ident_config
    from vdps_hil.identification.forces import moments_from_inputs

    sheet = _profile(profile)
    r = chain_run("paper", scale_noise(sheet, k), seed, predict=False, sheet_profile=sheet,
                  duration_s=T0_S + 0.1, ident_report_period_s=0.25, record_inputs=True)
    tp = truth_params()
    rep = _report_at(r["ident"], T0_S)
    veh, form = r["model"], load_ident_config().moment_form
    t_ns, rows = [], []
    for inp in r["inputs"]:
        if IDENT_WINDOW_S[0] <= inp.t_ns / 1e9 <= IDENT_WINDOW_S[1]:
            t_ns.append(inp.t_ns)
            rows.append((*inp.omega_dot_radps2, *moments_from_inputs(veh, veh.params, inp, form)))
    return {"profile": profile, "k": k, "seed": seed, "t_ns": t_ns, "series": np.array(rows),
            "rel_err": {n: relative_errors(rep[1], tp)[n] for n in INERTIA} if rep else None, "wall_s": r["wall_s"]}


def snr_db(run: dict, reference: dict) -> float:
    """SNR [dB] of a run against the zero-noise run of the same seed (module docstring)."""
    a, b = _aligned_series(run, reference)
    if len(a) < 10:
        return math.nan
    ratio = np.var(a - b, axis=0) / np.var(a, axis=0)
    m = float(np.mean(ratio))
    return -10.0 * math.log10(m) if m > 0 else math.inf


def _aligned_series(run: dict, reference: dict) -> tuple[np.ndarray, np.ndarray]:
    """(s_k, s_0): the rows of a run and of its zero-noise reference at their common instants,
    finite in both."""
    ref = {t: i for i, t in enumerate(reference["t_ns"])}
    idx = [(i, ref[t]) for i, t in enumerate(run["t_ns"]) if t in ref]
    if not idx:
        return np.empty((0, 1)), np.empty((0, 1))
    a = np.asarray(run["series"], dtype=float)[[i for i, _ in idx]]
    b = np.asarray(reference["series"], dtype=float)[[j for _, j in idx]]
    ok = np.all(np.isfinite(a), axis=1) & np.all(np.isfinite(b), axis=1)
    return a[ok], b[ok]


def snr_noise_scale(run: dict, reference: dict, target_db: float, run_k: float = 1.0) -> float:
    """Noise scale k at which :func:`snr_db` of the same drive is ``target_db`` [dB], from one
    run at noise scale ``run_k`` and the zero-noise run of the same seed (NaN: too few common
    samples, or the target is below the SNR the definition can reach).

    The estimation error due to the sensors' noise is linear in k (e_k = (k / run_k) e, e =
    s_run - s_0; measured on the paper drive: var(e_k) / k^2 constant within 2 % over
    k = 0.06-1), so per channel c, with x = k / run_k::

        var(s_k,c) = var(s_0,c) + 2 x cov(s_0,c, e_c) + x^2 var(e_c)
        r_c(k)     = x^2 var(e_c) / var(s_k,c),      SNR(k) = -10 log10( (1/6) sum_c r_c(k) )

    solved for k (the smallest k on a log grid where SNR(k) <= target, refined by bisection).
    The noise sits in the denominator too (var(s_k) = signal + noise), so r_c saturates at 1
    and SNR is not 20 log10 of 1/k: at the Table 1 sigmas (k = 1) the moments M_x, M_y already
    have r ~ 0.8-0.9 (SNR(1) ~ 5 dB), and the rule k = 10^((SNR(1) - target) / 20) gave rows
    measuring 21 / 12 / 6 dB for the 30 / 20 / 10 dB targets."""
    a, b = _aligned_series(run, reference)
    if len(a) < 10 or not (run_k > 0):
        return math.nan
    e = a - b
    ve = np.var(e, axis=0)
    v0 = np.var(b, axis=0)
    cov = np.mean((b - b.mean(axis=0)) * (e - e.mean(axis=0)), axis=0)

    def snr(x: float) -> float:
        den = v0 + 2.0 * x * cov + x * x * ve
        r = np.divide(x * x * ve, den, out=np.ones_like(ve), where=den > 0)
        m = float(np.mean(r))
        return -10.0 * math.log10(m) if m > 0 else math.inf

    xs = np.logspace(-6, 6, 481)
    vals = [snr(float(x)) for x in xs]
    hit = next((i for i, v in enumerate(vals) if v <= target_db), None)
    if hit is None:
        return math.nan
    if hit == 0:
        return float(xs[0]) * run_k
    lo, hi = math.log(xs[hit - 1]), math.log(xs[hit])
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if snr(math.exp(mid)) > target_db:
            lo = mid
        else:
            hi = mid
    return math.exp(0.5 * (lo + hi)) * run_k


def table3_task(profile: str, duration_s: float, seed: int = 1, qs: Iterable[float] = (0.625, 0.125, 0.025, 0.005)
                ) -> dict:
    """Table 3: the inertia problem with Q4 = diag(q,q,q), W4 = I, P(0) = I on the chain's
    recorded identifier inputs of one noise-free drive (module docstring)."""
    from vdps_hil.identification.config import load_ident_config
    from vdps_hil.identification.identifier import Identifier

    sheet = _profile(profile)
    r = chain_run("paper", sheet.zero_noise(), seed, predict=False, sheet_profile=sheet, duration_s=duration_s,
                  record_inputs=True, ident_report_period_s=1.0)
    tp = truth_params()
    base = load_ident_config()
    rows = {}
    for q in qs:
        cfg = replace(base, inertia=replace(base.inertia, q=(q, q, q), w=(1.0, 1.0, 1.0), p0_scaled=1.0))
        idf = Identifier(r["model"], cfg)
        ts, xs = [], []
        for inp in r["inputs"]:
            idf.update(inp)
            ts.append(inp.t_ns / 1e9)
            p = idf.params
            xs.append([getattr(p, n) for n in INERTIA])
        ts_a, xs_a = np.array(ts), np.array(xs)
        conv = []
        for j, n in enumerate(INERTIA):
            ok = np.abs(xs_a[:, j] - tp[n]) <= 0.1 * tp[n]
            bad = np.nonzero(~ok)[0]
            if ok[-1]:
                conv.append(float(ts_a[bad[-1] + 1] - ts_a[0]) if len(bad) else 0.0)
            else:
                conv.append(math.nan)
        rows[q] = {"min_eigenvalue": float(idf.identifiability["inertia"]), "convergence_s": conv,
                   "final_rel_err": [float((xs_a[-1, j] - tp[n]) / tp[n]) for j, n in enumerate(INERTIA)]}
    return {"profile": profile, "duration_s": duration_s, "rows": rows, "wall_s": r["wall_s"],
            "t_first_input_s": (r["inputs"][0].t_ns / 1e9) if r["inputs"] else math.nan}


# ------------------------------------------------------------------------------ aggregation
def aggregate_identification(docs: Sequence[dict]) -> dict:
    """Per parameter over the seeds: median and 90th percentile of |e| at 10.25 s and of the
    window mean, the prior error, the worst seed's |e| / |prior e|, within_2_sigma."""
    docs = [d for d in docs if "rel_err" in d]
    out = {}
    if not docs:
        return out
    for k in docs[0]["rel_err"]:
        e = np.abs([d["rel_err"][k] for d in docs]) * 100.0
        em = np.abs([d["rel_err_mean_window"][k] for d in docs]) * 100.0
        prior = abs(docs[0]["prior_rel_err"][k]) * 100.0
        out[k] = {"median_rel_err_pct": float(np.median(e)), "p90_rel_err_pct": float(np.percentile(e, 90)),
                  "median_rel_err_mean_5_10_pct": float(np.median(em)),
                  "p90_rel_err_mean_5_10_pct": float(np.percentile(em, 90)),
                  "signed_median_rel_err_pct": float(np.median([d["rel_err"][k] for d in docs]) * 100.0),
                  "prior_rel_err_pct": prior, "max_over_prior": float(np.max(e) / prior) if prior else math.nan,
                  "within_2_sigma": float(np.mean([d["sigma_ratio"][k] <= 2.0 for d in docs])),
                  "paper_rel_err_pct": PAPER["identification_rel_err_pct"].get(k)}
    return out


def _median(vals):
    v = [x for x in vals if x is not None and not (isinstance(x, float) and math.isnan(x))]
    return float(np.median(v)) if v else math.nan


def _run_tasks(tasks: list[tuple[Callable, tuple, dict]], workers: int, progress=None) -> list:
    """Run (fn, args, kwargs) tasks, in a process pool when workers > 1 (results in order)."""
    results: list = [None] * len(tasks)
    if workers <= 1 or len(tasks) <= 1:
        for i, (fn, a, kw) in enumerate(tasks):
            results[i] = fn(*a, **kw)
            if progress:
                progress(i + 1, len(tasks))
        return results
    import concurrent.futures as cf
    import multiprocessing as mp

    ctx = mp.get_context("spawn" if os.name == "nt" else "fork")
    with cf.ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as ex:
        futs = {ex.submit(fn, *a, **kw): i for i, (fn, a, kw) in enumerate(tasks)}
        done = 0
        for f in cf.as_completed(futs):
            results[futs[f]] = f.result()
            done += 1
            if progress:
                progress(done, len(tasks))
    return results


def run_paper(options: PaperOptions | None = None, progress=None) -> dict:
    """Run the experiments for each profile; returns the document (``--json``): for one profile
    its keys at the top level, for several ``{"profiles": {name: doc}}`` (module docstring)."""
    opt = options or PaperOptions()
    wall0 = time.perf_counter()
    seeds = list(range(opt.seed0, opt.seed0 + opt.seeds))
    snr_seeds = list(range(opt.seed0, opt.seed0 + opt.snr_seeds))
    tasks: list = []
    index: list = []
    for prof in opt.profiles:
        if opt.identification or opt.fusion:
            for s in seeds:
                tasks.append((identification_task, (prof, s), {"predict": opt.false_alarms}))
                index.append((prof, "ident", s))
        if opt.rollover:
            tasks.append((rollover_task, (prof, opt.seed0), {}))
            index.append((prof, "rollover", opt.seed0))
        if opt.false_alarms:
            for sc in opt.false_alarm_scenarios:
                tasks.append((false_alarm_task, (sc, prof, opt.seed0), {"max_s": opt.false_alarm_max_s}))
                index.append((prof, "false_alarm", sc))
        if opt.weighting_table:
            tasks.append((table3_task, (prof, opt.table3_duration_s), {}))
            index.append((prof, "table3", None))
        if opt.snr_table:
            for s in snr_seeds:
                tasks.append((snr_task, (prof, 1.0, s), {}))
                index.append((prof, "snr1", s))
                tasks.append((snr_task, (prof, 0.0, s), {}))
                index.append((prof, "snr0", s))
    results = _run_tasks(tasks, opt.workers, progress)
    # second stage: the SNR rows need k from the measured SNR at k = 1
    per: dict[str, dict] = {p: {"ident": [], "false_alarm": [], "snr1": [], "snr0": []} for p in opt.profiles}
    for (prof, kind, key), res in zip(index, results):
        if kind in ("ident", "false_alarm", "snr1", "snr0"):
            per[prof][kind].append(res)
        else:
            per[prof][kind] = res
    tasks2, index2 = [], []
    if opt.snr_table:
        for prof in opt.profiles:
            ref = {d["seed"]: d for d in per[prof]["snr0"]}
            for d in per[prof]["snr1"]:
                d["snr_db"] = snr_db(d, ref[d["seed"]]) if d["seed"] in ref else math.nan
            for d in per[prof]["snr0"]:
                d["snr_db"] = math.inf
            per[prof]["snr_k"] = {}
            for target in SNR_TARGETS_DB:
                k = _median([snr_noise_scale(d, ref[d["seed"]], target) for d in per[prof]["snr1"]
                             if d["seed"] in ref])
                per[prof]["snr_k"][target] = k
                if not math.isfinite(k):
                    continue
                for s in snr_seeds:
                    tasks2.append((snr_task, (prof, k, s), {}))
                    index2.append((prof, target))
    res2 = _run_tasks(tasks2, opt.workers, progress)
    for (prof, target), res in zip(index2, res2):
        ref = {d["seed"]: d for d in per[prof]["snr0"]}
        res["snr_db"] = snr_db(res, ref[res["seed"]]) if res["seed"] in ref else math.nan
        per[prof].setdefault("snr_rows", {}).setdefault(target, []).append(res)
    docs = {p: _profile_doc(p, per[p], opt, seeds) for p in opt.profiles}
    wall = time.perf_counter() - wall0
    if len(docs) == 1:
        doc = next(iter(docs.values()))
    else:
        doc = {"profiles": docs}
    doc["options"] = {k: (list(v) if isinstance(v, tuple) else v) for k, v in dataclasses.asdict(opt).items()}
    doc["wall_time_s"] = wall
    doc["definitions"] = DEFINITIONS
    return doc


DEFINITIONS = {
    "rel_err": "(identified - true) / true; true = the truth vehicle file (harness only)",
    "identification": "at t = 10.25 s of paper-left-turn; median / p90 of |rel_err| over the seeds; "
                      "within_2_sigma = fraction of seeds with |identified - true| <= 2 sigma",
    "snr_db": "-10 log10(mean_c var(s_k,c - s_0,c) / var(s_k,c)), s = (omega_dot_x,y,z, M_x,y,z) of the inertia "
              "problem over 5-10.25 s, s_0 the same drive with zero-noise sensors (noise-free = zero-noise sensors, "
              "never /truth/)",
    "inaccuracy_pct": "mean over xa ya za psi_v theta_v phi_v of RMS(pred - true) / max(range(true - true(t0)), "
                      "1 m or 1 deg) (prediction.metrics)",
    "lead_time_s": "t(point of no return, truth) - t(first valid VDPS_Warning frame with level >= warning)",
    "convergence_s": "first time from which |I - I_true| <= 10 % I_true holds to the end (Table 3 footnote a)",
}


def _profile_doc(prof: str, per: dict, opt: PaperOptions, seeds) -> dict:
    doc: dict = {"profile": prof, "seeds": list(seeds)}
    ident = [d for d in per["ident"] if d]
    if ident:
        doc["identification"] = aggregate_identification(ident)
        fs = [d["fusion_std"] for d in ident if d.get("fusion_std")]
        if fs:
            doc["fusion_std"] = {k: float(np.mean([f[k] for f in fs])) for k in fs[0]}
        lt = [d["left_turn"] for d in ident if "left_turn" in d]
        if lt:
            doc["prediction"] = {"left_turn": {
                "position_err_m": _median([x["position_err_m"] for x in lt]),
                "yaw_err_deg": _median([abs(x["yaw_err_deg"]) for x in lt]),
                "inaccuracy_pct": _median([x["inaccuracy_pct"] for x in lt]),
                "p90_position_err_m": float(np.percentile([x["position_err_m"] for x in lt], 90)),
                "p90_yaw_err_deg": float(np.percentile([abs(x["yaw_err_deg"]) for x in lt], 90)),
                "horizon_s": LEFT_TURN_END_S - T0_S, "paper_inaccuracy_pct": PAPER["left_turn_inaccuracy_pct"]}}
        doc["per_seed"] = [{k: d.get(k) for k in ("seed", "rel_err", "sigma_ratio", "left_turn", "warning")}
                           for d in ident]
    fa_total = 0
    fa_rows = {}
    if opt.false_alarms:
        lt_fa = sum(d.get("warning", {}).get("false_alarms", 0) for d in ident)
        fa_rows["paper-left-turn"] = {"runs": len(ident), "false_alarms": lt_fa, "valid_fraction":
                                      _median([d.get("warning", {}).get("valid_fraction") for d in ident])}
        fa_total += lt_fa
        for d in per["false_alarm"]:
            fa_rows[d["scenario"]] = {"runs": 1, "false_alarms": d["false_alarms"], "duration_s": d["duration_s"],
                                      "max_level": d["max_level"], "valid_fraction": d["valid_fraction"]}
            fa_total += d["false_alarms"]
    roll = per.get("rollover")
    if roll:
        doc.setdefault("prediction", {})["rollover"] = {
            "predicted": roll["predicted"], "inaccuracy_pct": roll.get("inaccuracy_pct", math.nan),
            "scenario": "fishhook-suv", "prediction_t0_s": roll.get("prediction_t0_s"),
            "prediction_end_s": roll.get("prediction_end_s"),
            "held_inputs": roll.get("held_inputs"),
            "inaccuracy_held_inputs_pct": (roll.get("held_inputs") or {}).get("inaccuracy_pct", math.nan),
            "paper_inaccuracy_pct": PAPER["rollover_inaccuracy_pct"]}
        doc["warning"] = {"lead_time_s": roll["lead_time_s"], "lead_to_tipup_s": roll["lead_to_tipup_s"],
                          "lead_time_matched_side_s": roll["lead_time_matched_side_s"],
                          "truth_point_of_no_return_t_s": roll["truth_point_of_no_return_t_s"],
                          "first_warning_t_s": roll["first_warning_t_s"]}
    if opt.false_alarms:
        doc.setdefault("warning", {})["false_alarms"] = fa_total
        doc["warning"]["false_alarm_runs"] = fa_rows
    if opt.snr_table and per.get("snr1"):
        rows = []

        def row(label, k, docs):
            errs = [d["rel_err"] for d in docs if d.get("rel_err")]
            return {"label": label, "noise_scale": k, "snr_db": _median([d["snr_db"] for d in docs]),
                    "rel_err_pct": {n: _median([abs(e[n]) * 100 for e in errs]) for n in INERTIA}}
        rows.append(dict(row("zero-noise", 0.0, per["snr0"]), paper_snr_db=None,
                         paper_rel_err_pct=dict(zip(INERTIA, PAPER["snr_table"][None]))))
        rows.append(dict(row("profile (k = 1)", 1.0, per["snr1"]), paper_snr_db=None, paper_rel_err_pct=None))
        for target in SNR_TARGETS_DB:
            rows.append(dict(row(f"{target:g} dB target", per["snr_k"][target],
                                 per.get("snr_rows", {}).get(target, [])),
                             paper_snr_db=target, paper_rel_err_pct=dict(zip(INERTIA, PAPER["snr_table"][target]))))
        doc["snr_table"] = rows
    t3 = per.get("table3")
    if t3:
        doc["weighting_table"] = [
            {"q": q, "min_eigenvalue": v["min_eigenvalue"], "convergence_s": dict(zip(INERTIA, v["convergence_s"])),
             "final_rel_err_pct": dict(zip(INERTIA, (100 * e for e in v["final_rel_err"]))),
             "paper_convergence_s": dict(zip(INERTIA, PAPER["weighting_table"][q])), "duration_s": t3["duration_s"]}
            for q, v in t3["rows"].items()]
    return doc


# ------------------------------------------------------------------------------- formatting
def _f(v, fmt="{:.3g}") -> str:
    if v is None:
        return "-"
    if isinstance(v, float) and math.isnan(v):
        return "NaN"
    return fmt.format(v)


def format_report(doc: dict) -> str:
    """The side-by-side table (paper vs ours) of a ``run_paper`` document."""
    docs = doc["profiles"] if "profiles" in doc else {doc["profile"]: doc}
    lines = []
    for prof, d in docs.items():
        lines.append(f"== profile {prof}: {len(d.get('seeds', []))} seeds ==")
        if "fusion_std" in d:
            lines.append("Fusion (Fig 4): std of estimate - truth over 5-10 s, mean over seeds "
                         "(the paper gives these only in its figure)")
            lines.append("  " + "  ".join(f"{k} {_f(v)}" for k, v in d["fusion_std"].items()))
        if "identification" in d:
            lines.append("Identification at 10.25 s, |rel err| % over seeds (paper: section 7.2)")
            lines.append(f"  {'parameter':32s} {'prior':>7s} {'median':>8s} {'p90':>8s} {'mean5-10':>9s} "
                         f"{'<=2sig':>7s} {'paper':>8s}")
            for k, v in d["identification"].items():
                lines.append(f"  {k:32s} {_f(v['prior_rel_err_pct'], '{:7.1f}')} "
                             f"{_f(v['median_rel_err_pct'], '{:8.3f}')} {_f(v['p90_rel_err_pct'], '{:8.3f}')} "
                             f"{_f(v['median_rel_err_mean_5_10_pct'], '{:9.3f}')} "
                             f"{_f(v['within_2_sigma'], '{:7.2f}')} {_f(v['paper_rel_err_pct'], '{:8.4g}')}")
        pr = d.get("prediction", {})
        if "left_turn" in pr:
            lt = pr["left_turn"]
            lines.append(f"Left turn (Fig 8), predicted from 10.25 s for {lt['horizon_s']:.2f} s, median over seeds: "
                         f"position {_f(lt['position_err_m'], '{:.2f}')} m (p90 {_f(lt['p90_position_err_m'], '{:.2f}')})"
                         f", yaw {_f(lt['yaw_err_deg'], '{:.2f}')} deg (p90 {_f(lt['p90_yaw_err_deg'], '{:.2f}')}), "
                         f"inaccuracy {_f(lt['inaccuracy_pct'], '{:.2f}')} %   (paper: 0.51 %)")
        if "rollover" in pr:
            ro = pr["rollover"]
            lines.append(f"Rollover ({ro['scenario']}): predicted {ro['predicted']}, first forecasting prediction "
                         f"t0 {_f(ro['prediction_t0_s'], '{:.2f}')} s, inaccuracy {_f(ro['inaccuracy_pct'], '{:.1f}')} %"
                         f"   (paper Fig 9: 27.3 %)")
            hi = ro.get("held_inputs") or {}
            lines.append(f"  first prediction after the last input change (inputs truly held, as the paper's Fig 9): "
                         f"t0 {_f(hi.get('prediction_t0_s'), '{:.2f}')} s, inaccuracy "
                         f"{_f(hi.get('inaccuracy_pct'), '{:.1f}')} %   (paper Fig 9: 27.3 %)")
        w = d.get("warning")
        if w:
            if "lead_time_s" in w:
                lines.append(f"Warning: lead time to point of no return {_f(w['lead_time_s'], '{:.2f}')} s "
                             f"(first warning {_f(w['first_warning_t_s'], '{:.2f}')} s, PONR "
                             f"{_f(w['truth_point_of_no_return_t_s'], '{:.2f}')} s), to tip-up "
                             f"{_f(w['lead_to_tipup_s'], '{:.2f}')} s, same-side {_f(w['lead_time_matched_side_s'], '{:.2f}')} s")
            if "false_alarms" in w:
                runs = ", ".join(f"{k} {v['false_alarms']} in {v['runs']} run(s), valid "
                                 f"{100 * v['valid_fraction']:.0f} %" for k, v in w["false_alarm_runs"].items())
                lines.append(f"False alarms: {w['false_alarms']} ({runs})")
        if "snr_table" in d:
            lines.append("Table 2: |rel err| % of Ix Iy Iz at 10.25 s vs SNR (SNR = -10 log10 mean over wdot_xyz, "
                         "M_xyz of var(noise error) / var(signal), 5-10.25 s; noise error = vs the same drive on "
                         "zero-noise sensors)")
            for r in d["snr_table"]:
                ours = " ".join(_f(r["rel_err_pct"][n], "{:7.2f}") for n in INERTIA)
                pap = " ".join(_f(v, "{:6.2f}") for v in r["paper_rel_err_pct"].values()) if r["paper_rel_err_pct"] \
                    else "  (no paper row)"
                lines.append(f"  {r['label']:18s} k {_f(r['noise_scale'], '{:6.3g}')} SNR {_f(r['snr_db'], '{:5.1f}')} dB"
                             f"  ours {ours}   paper {pap}")
        if "weighting_table" in d:
            lines.append("Table 3: Q4 = diag(q,q,q), W4 = I, P(0) = I, noise-free; time to within 10 % [s], "
                         "min eigenvalue of sum A^T Q^T Q A")
            for r in d["weighting_table"]:
                ours = " ".join(_f(v, "{:6.2f}") for v in r["convergence_s"].values())
                pap = " ".join(_f(v, "{:6.2f}") for v in r["paper_convergence_s"].values())
                lines.append(f"  q {r['q']:<6g} lambda_min {_f(r['min_eigenvalue'], '{:9.3g}')}  ours {ours}   "
                             f"paper {pap}")
        lines.append("")
    if "wall_time_s" in doc:
        lines.append(f"wall time {doc['wall_time_s']:.0f} s")
    return "\n".join(lines)
