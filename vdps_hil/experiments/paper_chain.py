"""One simulated drive through the real chain, for the paper's experiments (Hsu & Chen 2012,
sections 7-8; ``vdps paper``): ``chain_run``.

The chain and the harness
-------------------------
Every experiment simulates a drive (``sim.drive.Drive``: truth simulator + sensor models on the
real wire formats, into an in-memory MCAP recording), decodes only its ``/raw/`` topics
(``record.decode``) and feeds the samples to :class:`~vdps_hil.pipeline.node.VdpsSystem` (EKF,
alpha-beta, identification feeder, the four RLS problems, predictor, warning node) built on a
*model* vehicle file. The harness reads ``/truth/state``, ``/truth/events`` and the truth
vehicle file's parameters only to SCORE what the chain produced (``experiments.scoring``);
nothing from the truth reaches the chain. "Noise-free" always means zero-noise sensors
(``SensorProfile.zero_noise()``), never ``/truth/``. The experiments themselves:
``experiments.paper_tasks``.
"""

from __future__ import annotations

import dataclasses
import io
import time
from typing import Any, Mapping, Sequence

from vdps_hil.experiments.scoring import fusion_error, fusion_std, truth_at

__all__ = ["chain_run", "scale_noise", "system_config", "profile_of"]


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


def profile_of(p):
    """A sensor profile: loaded by name (``configs/profiles``), or ``p`` itself."""
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


def _simulate(scenario, prof, seed: int, duration_s: float | None, truth_vehicle: str | None,
              truth: str | None = None):
    """The drive into an in-memory recording: (reader, /truth/state snapshots, /truth/events);
    ``truth``: a truth backend spec (``sim.truth_backends``, e.g. "commonroad-mb:1")."""
    from vdps_hil.record.reader import RecordingReader
    from vdps_hil.sim.drive import Drive

    buf = io.BytesIO()
    Drive(scenario, profile=prof, seed=seed, duration_s=duration_s, vehicle=truth_vehicle, truth=truth).run(buf)
    buf.seek(0)
    reader = RecordingReader(buf)
    truth = [d["values"] for _, _, d in reader.iter_messages(["/truth/state"])]  # harness only
    events = [d["values"] for _, _, d in reader.iter_messages(["/truth/events"])]
    return reader, truth, events


def _record_feeder_inputs(feeder, inputs: list) -> None:
    """Wrap the identification feeder so every IdentInputs it builds is also kept in ``inputs``."""
    feed = feeder.inputs

    def recording_inputs(est, filt):
        inp = feed(est, filt)
        if inp is not None:
            inputs.append(inp)
        return inp
    feeder.inputs = recording_inputs


def _capture(o, system, captured: dict, cap_ns: list, capture_all: bool) -> None:
    """Keep (predictor initial state from the estimate and filtered signals, identified
    parameters) at ``o`` when it is the first estimate at or after the next of ``cap_ns`` (or
    always, with ``capture_all``)."""
    from vdps_hil.prediction.initial_state import PredictorInitialState

    if capture_all or (cap_ns and o.t_ns >= cap_ns[0]):
        while cap_ns and o.t_ns >= cap_ns[0]:
            cap_ns.pop(0)
        try:
            init = PredictorInitialState.from_estimator(o, system.pipeline.filtered())
        except ValueError:
            init = None
        captured[o.t_ns] = (init, system.params)


def _frame_message(o):
    """A sent CanFrame as the can.Message the warning scoring decodes."""
    import can

    return can.Message(timestamp=o.t_ns / 1e9, arbitration_id=o.arbitration_id, data=o.data,
                       is_extended_id=False)


def chain_run(scenario, profile, seed: int, *, model: str = "sedan-model", duration_s: float | None = None,
              identify: bool = True, predict: bool = True, ident_config=None, sheet_profile=None,
              ident_report_period_s: float = 0.05, capture_t_s: Sequence[float] = (),
              capture_all: bool = False, record_inputs: bool = False, fusion_window_s=None,
              truth_vehicle: str | None = None, system_kw: Mapping[str, Any] | None = None,
              truth_backend: str | None = None) -> dict:
    """One drive through the real chain (module docstring). Returns a dict:

    ``truth`` (the /truth/state snapshots, harness only), ``events`` (/truth/events),
    ``ident`` [(t_s, params dict, sigmas dict, identifiability dict)], ``captured``
    {t_ns: (PredictorInitialState | None, IdentifiedParams)} at the first estimate at or after
    each of ``capture_t_s`` (or every estimate with ``capture_all``), ``frames`` (sent VDPS_Warning as can.Message),
    ``predictions`` (PredictionReport), ``inputs`` (IdentInputs, with ``record_inputs``),
    ``fusion_std`` (per state over ``fusion_window_s``),
    ``status`` (system counters) and ``wall_s``.
    ``sheet_profile``: the data sheet the chain is configured from (default: ``profile``);
    ``truth_vehicle``: the simulated vehicle instead of the scenario's; ``truth_backend``: a truth
    backend spec instead of our simulator (``sim.truth_backends``); ``system_kw``: further
    ``SystemConfig`` fields (``require_converged``, ``start_params``)."""
    from vdps_hil.estimation.estimates import Estimate
    from vdps_hil.geodesy import DEFAULT_ORIGIN
    from vdps_hil.model.params import load_vehicle
    from vdps_hil.record.decode import decode_recording
    from vdps_hil.pipeline.node import VdpsSystem
    from vdps_hil.pipeline.outputs import CanFrame, IdentReport, PredictionReport

    wall0 = time.perf_counter()
    prof = profile_of(profile)
    reader, truth, events = _simulate(scenario, prof, seed, duration_s, truth_vehicle, truth_backend)
    by_t = {int(s["t_ns"]): s for s in truth}
    sheet = profile_of(sheet_profile) if sheet_profile is not None else prof
    cfg = system_config(sheet, identify=identify, predict=predict, ident=ident_config,
                        ident_report_period_s=ident_report_period_s, **dict(system_kw or {}))
    veh = load_vehicle(model, "model")
    system = VdpsSystem(veh, cfg, origin=DEFAULT_ORIGIN)
    cap_ns = sorted(int(round(t * 1e9)) for t in capture_t_s)  # first estimate at or after each
    out: dict = {"truth": truth, "events": events, "ident": [], "captured": {}, "frames": [], "predictions": [],
                 "inputs": [], "model": veh}
    if record_inputs and system.feeder is not None:
        _record_feeder_inputs(system.feeder, out["inputs"])
    fus_rows = []
    ekf = system.pipeline.ekf
    for s in decode_recording(reader):
        outs = system.handle(s)
        system.clear_input_log()
        for o in outs:
            if isinstance(o, Estimate):
                _capture(o, system, out["captured"], cap_ns, capture_all)
                tv = truth_at(by_t, o.t_ns) if fusion_window_s else None
                if tv is not None and ekf.initialized:
                    if fusion_window_s and fusion_window_s[0] <= tv["t_s"] <= fusion_window_s[1]:
                        fus_rows.append(fusion_error(o, tv))
            elif isinstance(o, IdentReport):
                out["ident"].append((o.t_ns / 1e9, dict(o.params), dict(o.sigmas), dict(o.identifiability)))
            elif isinstance(o, PredictionReport):
                out["predictions"].append(o)
            elif isinstance(o, CanFrame):
                out["frames"].append(_frame_message(o))
    out["frames"].extend(_frame_message(o) for o in system.finish() if isinstance(o, CanFrame))
    reader.close()
    if fus_rows:
        out["fusion_std"] = fusion_std(fus_rows)
    out["status"] = system.status()["counters"]
    out["identifier"] = system.identifier
    out["wall_s"] = time.perf_counter() - wall0
    return out
