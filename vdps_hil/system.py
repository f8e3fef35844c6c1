"""The vehicle dynamic prediction system of the paper's Figure 2 as one pure node.

``VdpsSystem(model_vehicle, config).handle(sample) -> outputs`` runs, for every bus sample::

    sample --> [suspension conditioning] --> EstimatorPipeline (multi-rate EKF eq 7-11,
               alpha-beta eq 12) --> Estimate every estimate_period_s
           --> IdentFeeder (aux frame, eq 13 quantities) --> Identifier (RLS eq 19-23)
               every ident_period_s
           --> at the predictor cadence: Predictor (eq 13-16, held inputs) from the current
               estimate with the identified parameters --> WarningNode --> VDPS_Warning on CAN

No threads, devices or clocks inside: time comes only from ``sample.t_ns``. Every input is
recorded in order (``input_log``); ``VdpsSystem.replay(vehicle, config, samples)`` feeds them to
a fresh system and reproduces the outputs bit for bit (``outputs_digest``). The system reads
only a *model* vehicle file (the truth file is refused) and never a ``/truth`` source (the
pipeline ignores and counts them).

Outputs (in the order they arise)
---------------------------------
==================  ==========================================================================
``Innovation``      one per EKF update (pipeline), with NIS and gate status
``Estimate``        the EKF state of eq 7 with 1-sigma, and the road-relative angles (eq 4),
                    at most one per ``estimate_period_s`` of filter time (pipeline.estimate())
``FilteredSignals`` the alpha-beta outputs at the same instants (``emit_filtered``)
``IdentReport``     identified parameters, sigmas, identifiability, converged flags every
                    ``ident_report_period_s``
``PredictionReport`` each new prediction's rollover assessment (TTR, peak LTR, peak roll)
``CanFrame``        VDPS_Warning frames (50 Hz and on a level change), ready for a bus
==================  ==========================================================================

Why the system takes the estimates itself: the pipeline emits an ``Estimate`` when an IMU
sample finds the filter one predict period behind; an update of another kind (suspension at
1 kHz) also advances the filter, so with a 1 kHz suspension the pipeline would emit none. The
system therefore asks ``pipeline.estimate()`` whenever the filter time has passed the next
multiple of ``estimate_period_s``.

Suspension conditioning
-----------------------
*Window means* (``suspension_rate_hz``, default 100 Hz; None: off). A 1 kHz suspension (profile
``table1-susp1k``) would make the EKF update eq 5's rows at 1 kHz (about 0.5 ms of filter work
per sample). The system averages the deflections over windows [k T, (k + 1) T),
T = 1 / suspension_rate_hz, and hands the pipeline one sample per window::

    H_bar_i = (1/n) sum_j H_i,j,   t_bar = (1/n) sum_j t_j,   sigma(H_bar) = sigma_H / sqrt(n)

(the mean of n samples is a sufficient statistic of a signal that is linear over T; the body's
heave/pitch/roll modes are 1-2 Hz, T = 10 ms). The window is released when the first sample at
or after its end arrives. Its time stamp (``suspension_stamp``):

* ``"mean"`` (default): t_bar, exact for a signal linear over T. The sample is then in the
  filter's past (the IMU has moved it on), and the EKF re-propagates from its history: about
  1.5x the estimator's CPU time at 1 kHz suspension.
* ``"end"``: t_end = (k + 1) T with H_i(t_end) = H_bar_i + Hd_i (t_end - t_bar), Hd_i an
  alpha-beta rate (``susp_rate_bandwidth_hz``, 10 Hz) of the window means; never in the past,
  cheaper, but the lagging rate makes the extrapolation wrong in roll transients: the averaged
  NEES rose to 1.4 n during the ISO 3888 lane change (1.1 n with ``"mean"``), and the sigma
  needs ``CONDITIONING_SIGMA_FACTOR``.

The EKF's sigma for the conditioned sample is ``PipelineConfig.susp_sigma_m``;
``SystemConfig.for_profile`` sets sigma_H / sqrt(n) from the sensor's rate and sigma (times the
factor for ``"end"``). Slower sensors (1 Hz) pass one sample per window unchanged, without rate
terms.

*Tire compliance* (``tire_compliance``, default on): eq 5 takes the body's attitude over the
road from the suspension deflections alone (rigid tires). The tires deflect too, by their load
change over the radial stiffness k_t (model file ``tire.vertical_stiffness_npm``), so eq 5 sees
only about 80 % of the road-relative roll (measured on ``lane-change-iso3888``: 3.6 mrad RMS
roll error, 42 % of the y1_sus updates gated). The EKF therefore gets::

    H_eff,i = H_i + (F_z,i(H_i, Hd_i) - F_z,i(0, 0)) / k_t
    F_z,i   = K_s,i H_s,i + D_s,i Hd_i + m_u,i g            (eq 14, ``suspension_forces_n``)

(residual roll error 10 urad RMS on the same drive with true H, Hd). The identifier's eq 14
forces use the *measured* H_i (alpha-beta of the window means at the pipeline's suspension
bandwidth): the ``FilteredSignals`` the system emits and feeds to the identifier carry those;
the predictor (rigid tires, eq 13-16) gets the pipeline's, i.e. H_eff.

Alpha-beta bandwidths: the system's default ``PipelineConfig`` uses 20 Hz for the body rates,
wheel speeds and suspension (the pipeline's own defaults are 5/5/2 Hz). The inertia problem
(eq 23) relates the angular accelerations to moments from H, Hd; at 2-5 Hz the derivatives lag
the 1 Hz excitation of the paper's scenario by tens of degrees and I_x came out 3x too high on
a zero-noise drive (+215 %; 20 Hz: +33 %).

Warning status sent with each frame: 1 "not converged" until the EKF is initialised and, when
the identifier started from the model file's priors (no ``start_params``, i.e. no ``--params``),
until the identification problems named in the warning policy's ``require_converged``
(``configs/prediction/default.toml``: ``["cornering"]``) have converged; 2 "sensor missing" when
the held inputs (steering, wheel torques) or a rate/wheel speed are missing, else 0; the node
itself sends 3 "fault" for a stale prediction. ``SystemConfig.require_converged`` set to a tuple
overrides that rule (``()``: never gate).

File replay (``replay_file``, the library function of ``vdps replay`` and of the batch tasks):
``record.decode`` (only ``/raw/``) -> optional sensor-set kind map and calibration nodes ->
``VdpsSystem`` -> ``/est/state`` (values + sigmas), ``/est/innovation/<kind>``, ``/est/filtered``,
``/est/ident``, ``/est/prediction``, ``/est/can/<bus>`` (the sent frames, vdps.RawCan.v1, tx) in
an output MCAP that also holds the raw topics copied byte for byte; the summary dict is the
``--json`` document. The sensor set is named (``configs/sensorsets``) or inferred from the
fields the recording carries, the suspension averaging sized from its measured rate.

Symbols: t [ns], T window [s], H deflection [m] (compression +), sigma [m], n samples per window.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
from dataclasses import dataclass, field, replace
from typing import Any, Iterable, Iterator, Mapping

import numpy as np

from vdps_hil.bus.samples import Sample, wheel_fields
from vdps_hil.estimation.pipeline import Estimate, EstimatorPipeline, FilteredSignals, Innovation, PipelineConfig
from vdps_hil.estimation.states import STATE_NAMES
from vdps_hil.identification.feeder import FeederConfig, IdentFeeder
from vdps_hil.identification.problems import IdentConfig, Identifier
from vdps_hil.model.params import IdentifiedParams, Vehicle

__all__ = ["CanFrame", "IdentReport", "PredictionReport", "ReplayError", "SuspensionConditioner", "SystemConfig",
           "VdpsSystem", "default_pipeline_config", "output_to_json", "outputs_digest", "recorded_config",
           "replay_file", "sample_stats", "write_output"]

_SUSP = wheel_fields("susp_deflection_m")
_NEVER = 1 << 62
_MAX_SUSP_LEAD_NS = 50_000_000
"""The identifier's H, H_dot are carried forward / led only over at most 50 ms (five 100 Hz
windows); a slower suspension sensor (table1's 1 Hz) gets the filter's values unchanged."""


# ------------------------------------------------------------------------------------- outputs
@dataclass(frozen=True)
class CanFrame:
    """A classic CAN frame the system sends (VDPS_Warning), time-stamped at ``t_ns``."""

    t_ns: int
    bus: str
    arbitration_id: int
    data: bytes

    def to_json(self) -> dict:
        return {"t_ns": self.t_ns, "bus": self.bus, "arbitration_id": self.arbitration_id,
                "data_hex": self.data.hex()}


@dataclass(frozen=True)
class IdentReport:
    """Identifier state at ``t_ns``: parameter values and sigmas (field names of
    ``IdentifiedParams``, SI), minimum eigenvalue of A^T Q^T Q A per problem, converged flags,
    updates per problem."""

    t_ns: int
    params: Mapping[str, float]
    sigmas: Mapping[str, float]
    identifiability: Mapping[str, float]
    converged: Mapping[str, bool]
    updates: Mapping[str, int]

    def to_json(self) -> dict:
        return {"t_ns": self.t_ns, "params": dict(self.params), "sigmas": dict(self.sigmas),
                "identifiability": dict(self.identifiability), "converged": dict(self.converged),
                "updates": dict(self.updates)}


@dataclass(frozen=True)
class PredictionReport:
    """A new prediction started at ``t0_ns`` and its rollover assessment (times after t0 [s])."""

    t0_ns: int
    time_to_point_of_no_return_s: float | None
    time_to_tip_up_s: float | None
    peak_ltr: float
    peak_roll_rad: float
    horizon_s: float
    stop_reason: str

    def to_json(self) -> dict:
        return dict(self.__dict__)


def output_to_json(o) -> dict:
    """A JSON-ready document of any system output, with its type under ``"type"``."""
    if isinstance(o, FilteredSignals):
        d = {k: (list(v) if isinstance(v, tuple) else v) for k, v in o.__dict__.items()}
    else:
        d = o.to_json()
    d["type"] = type(o).__name__
    return d


def outputs_digest(outputs: Iterable) -> str:
    """SHA-256 over the canonical JSON of the outputs (NaN written as null): equal digests mean
    bit-identical outputs (floats are printed with their shortest exact repr)."""
    h = hashlib.sha256()
    for o in outputs:
        h.update(json.dumps(_clean(output_to_json(o)), sort_keys=True, separators=(",", ":")).encode())
        h.update(b"\n")
    return h.hexdigest()


def _clean(o):
    if isinstance(o, float):
        return o if math.isfinite(o) else None
    if isinstance(o, dict):
        return {str(k): _clean(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_clean(v) for v in o]
    return o


# ---------------------------------------------------------------------------- configuration
SUSPENSION_STAMPS = ("mean", "end")
CONDITIONING_SIGMA_FACTOR = 1.5
"""``suspension_stamp = "end"`` only: sigma of a window mean extrapolated to the window's end
over sigma_H / sqrt(n) (the alpha-beta rate of the extrapolation adds its noise and lag; without
it the y1_sus NIS per degree of freedom was 2.2 on the ISO 3888 lane change)."""


def default_pipeline_config(**kw) -> PipelineConfig:
    """The system's pipeline settings: no pipeline Estimates (the system takes its own), 20 Hz
    alpha-beta bandwidths (module docstring) and a GNSS speed sigma of 0.05 m/s (Doppler
    velocity, about 1/20 of the code position sigma; Table 1 gives none; the pipeline's default
    0.1 m/s made the velocity NIS 0.26 on simulated drives); ``kw`` overrides PipelineConfig."""
    from vdps_hil.estimation.pipeline import Bandwidths

    d = {"emit_estimates": False, "bandwidths": Bandwidths(20.0, 20.0, 20.0), "gnss_speed_sigma_mps": 0.05}
    d.update(kw)
    return PipelineConfig(**d)


@dataclass(frozen=True)
class SystemConfig:
    """Configuration of the node (module docstring). ``ident``/``predictor``/``warning_*`` None:
    the project's config files (``configs/identification``, ``configs/prediction``)."""

    pipeline: PipelineConfig = field(default_factory=lambda: default_pipeline_config())
    estimate_period_s: float = 0.01
    emit_filtered: bool = True
    suspension_rate_hz: float | None = 100.0
    suspension_stamp: str = "mean"
    tire_compliance: bool = True
    susp_rate_bandwidth_hz: float = 10.0
    identify: bool = True
    ident_period_s: float = 0.01
    ident_report_period_s: float = 1.0
    ident: IdentConfig | None = None
    feeder: FeederConfig = field(default_factory=FeederConfig)
    start_params: IdentifiedParams | None = None
    predict: bool = True
    predictor: Any = None  # PredictorConfig
    warning_policy: Any = None  # WarningPolicy
    warning_node: Any = None  # WarningNodeConfig
    warning_bus: str = "vdps"
    require_converged: tuple[str, ...] | None = None  # None: the warning policy's, if started from the priors
    model_effects: Any = None  # EffectSet of a saved workbench model: dynamics join the predictor,
    # IMU measurement effects are removed from the readings (estimation.imu_correction)

    def __post_init__(self):
        for name in ("estimate_period_s", "ident_period_s", "ident_report_period_s"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"SystemConfig.{name} must be a positive finite number, got {v!r}")
        r = self.suspension_rate_hz
        if r is not None and not (math.isfinite(r) and r > 0):
            raise ValueError(f"SystemConfig.suspension_rate_hz must be positive or None, got {r!r}")
        if self.suspension_stamp not in SUSPENSION_STAMPS:
            raise ValueError(f"SystemConfig.suspension_stamp must be one of {SUSPENSION_STAMPS}, "
                             f"got {self.suspension_stamp!r}")

    @classmethod
    def for_profile(cls, susp_rate_hz: float, susp_sigma_m: float, **kw) -> "SystemConfig":
        """A config whose EKF suspension sigma is that of the conditioned sample:
        k sigma_H / sqrt(n), n = max(1, round(sensor rate / suspension_rate_hz)), k =
        ``CONDITIONING_SIGMA_FACTOR`` when windows are averaged (n > 1) and stamped at their
        end, else 1."""
        rate = kw.get("suspension_rate_hz", cls.__dataclass_fields__["suspension_rate_hz"].default)
        stamp = kw.get("suspension_stamp", cls.__dataclass_fields__["suspension_stamp"].default)
        n = 1 if rate is None else max(1, int(round(susp_rate_hz / rate)))
        k = CONDITIONING_SIGMA_FACTOR if n > 1 and stamp == "end" else 1.0
        pc = kw.pop("pipeline", default_pipeline_config())
        pc = replace(pc, susp_sigma_m=k * susp_sigma_m / math.sqrt(n))
        return cls(pipeline=pc, **kw)


# ------------------------------------------------------------------- suspension conditioning
class SuspensionConditioner:
    """Window means and the tire-compliance correction of suspension samples (module
    docstring). ``due(t_ns)`` returns the conditioned sample of a window that has ended by
    ``t_ns`` (call it with every sample's time, in order); ``add(sample)`` absorbs a suspension
    sample. ``raw_filtered()`` is the alpha-beta (H, H_dot) of the *measured* deflections (the
    identifier's eq 14 forces need them; the EKF gets H_eff)."""

    def __init__(self, vehicle: Vehicle, rate_hz: float | None, tire_compliance: bool, raw_bandwidth_hz: float,
                 rate_bandwidth_hz: float, max_gap_s: float, rate_lead: bool = True, stamp: str = "end"):
        from vdps_hil.estimation.alpha_beta import TimedAlphaBetaBank
        from vdps_hil.identification.problems import suspension_forces_n

        self.vehicle = vehicle
        self.period_ns = int(round(1e9 / rate_hz)) if rate_hz else 0
        if stamp not in SUSPENSION_STAMPS:
            raise ValueError(f"stamp must be one of {SUSPENSION_STAMPS}, got {stamp!r}")
        self.stamp = stamp
        self.tire_compliance = bool(tire_compliance)
        self._forces = suspension_forces_n
        self._f0 = suspension_forces_n(vehicle, (0.0,) * 4, (0.0,) * 4)
        self._kt = vehicle.tire.vertical_stiffness_npm
        self._ab_raw = TimedAlphaBetaBank(4, raw_bandwidth_hz, max_gap_s)
        self.rate_lead = bool(rate_lead)
        self._v_prev: list[float] = [math.nan] * 4
        self._t_prev: list[int | None] = [None] * 4
        self._ab_rate = TimedAlphaBetaBank(4, rate_bandwidth_hz, max_gap_s)
        self._k: int | None = None
        self.due_ns = _NEVER  # end of the open window (``due`` has nothing before it)
        self._sum = [0.0, 0.0, 0.0, 0.0]
        self._t = 0
        self._n = 0
        self._src = ""
        self.windows = 0
        self.merged = 0

    def raw_filtered(self, t_ns: int | None = None) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """(H, H_dot) of the measured deflections; with ``t_ns`` H is carried from the filter's
        last update (a window mean stamped at the window's mean sample time, about half a
        window earlier) to ``t_ns``: H(t) = H + H_dot (t - t_update), and with ``rate_lead``
        H_dot is led by the filter's derivative lag plus that age (code comment). Without them
        the identifier's eq 14 forces lagged the simulator's by 5.5 ms (H) and 18.3 ms (H_dot)
        at 100 Hz windows and 20 Hz bandwidth, which biased the roll and pitch moment balances of
        eq 23 (damper forces D_s H_dot are about half the strut roll moment at 1 Hz)."""
        ab = self._ab_raw
        if t_ns is None:
            return tuple(ab.x), tuple(ab.v)
        lim = _MAX_SUSP_LEAD_NS  # a slow sensor (table1: 1 Hz) is not extrapolated
        h = tuple(x + v * (t_ns - t) * 1e-9 if t is not None and 0 <= t_ns - t <= lim and math.isfinite(v) else x
                  for x, v, t in zip(ab.x, ab.v, ab.t))
        if not self.rate_lead:
            return h, tuple(ab.v)
        # H_dot: the alpha-beta derivative lags by tau_d = T (alpha/beta - 1/2) behind its last
        # update, itself (t - t_update) old; lead it by the change of H_dot between the last two
        # updates:  H_dot(t) = v + (v - v_prev) / (t_u - t_prev) (tau_d + t - t_u)
        tau_d = ab.lag_s
        hd = []
        for i, (v, t) in enumerate(zip(ab.v, ab.t)):
            vp, tp = self._v_prev[i], self._t_prev[i]
            if (t is None or tp is None or t <= tp or not 0 <= t_ns - t <= lim or t - tp > lim
                    or not math.isfinite(tau_d)
                    or not math.isfinite(v + vp)):
                hd.append(v)
                continue
            hd.append(v + (v - vp) / ((t - tp) * 1e-9) * (tau_d + (t_ns - t) * 1e-9))
        return h, tuple(hd)

    def _condition(self, t_ns: int, source: str, h, t_out: int) -> Sample:
        """H at t_ns -> the EKF's sample at t_out >= t_ns: H_eff(t_out) (module docstring)."""
        ab = self._ab_raw
        self._v_prev, self._t_prev = list(ab.v), list(ab.t)
        t_last = ab.t[0]
        ab.update(t_ns, h)
        self._ab_rate.update(t_ns, h)
        if t_last is None or t_ns - t_last > _MAX_SUSP_LEAD_NS:
            hd = [0.0] * 4  # sparse samples (a 1 Hz sensor): no usable rate for the damper term
        else:
            hd = [v if math.isfinite(v) else 0.0 for v in self._ab_rate.v]
        if t_out != t_ns:
            dt = (t_out - t_ns) * 1e-9
            h = [h[i] + hd[i] * dt for i in range(4)]
        if self.tire_compliance:
            fz = self._forces(self.vehicle, h, hd)
            h = [h[i] + (float(fz[i]) - float(self._f0[i])) / self._kt for i in range(4)]
        return Sample(t_ns=int(t_out), source=source, kind="suspension", fields=dict(zip(_SUSP, h)))

    def _close(self) -> Sample:
        n = self._n
        t, h = int(round(self._t / n)), [v / n for v in self._sum]
        t_end = (self._k + 1) * self.period_ns
        self._k, self._sum, self._t, self._n = None, [0.0, 0.0, 0.0, 0.0], 0, 0
        self.due_ns = _NEVER
        self.windows += 1
        self.merged += n
        return self._condition(t, self._src, h, max(t_end, t) if self.stamp == "end" else t)

    def due(self, t_ns: int) -> list[Sample]:
        if self._k is not None and t_ns >= (self._k + 1) * self.period_ns:
            return [self._close()]
        return []

    def finish(self) -> list[Sample]:
        return [self._close()] if self._k is not None else []

    def add(self, s: Sample) -> list[Sample] | None:
        """Absorb a suspension sample. Returns the samples to hand on now ([] while a window
        fills), or None when it cannot be conditioned (invalid, a field missing): the caller
        passes it on unchanged."""
        g = s.fields.get
        h = [g(n, math.nan) for n in _SUSP]
        if not s.valid or not math.isfinite(h[0] + h[1] + h[2] + h[3]):
            return None
        if not self.period_ns:
            self.windows += 1
            self.merged += 1
            return [self._condition(s.t_ns, s.source, h, s.t_ns)]
        k = s.t_ns // self.period_ns
        if self._k is None:
            self._k, self._src = k, s.source
            self.due_ns = (k + 1) * self.period_ns
        sm = self._sum
        sm[0] += h[0]
        sm[1] += h[1]
        sm[2] += h[2]
        sm[3] += h[3]
        self._t += s.t_ns
        self._n += 1
        return []


# --------------------------------------------------------------------------------- the node
WARNING_HISTORY = 100
"""Sent warning frames and assessments the system's warning chain keeps (the most recent; 2 s of
frames at 50 Hz): its outputs carry every frame and prediction as they happen, so the chain
keeps only counts and a recent window and memory does not grow with the drive."""


class VdpsSystem:
    """Figure 2 as one pure node (module docstring)."""

    def __init__(self, model_vehicle: Vehicle, config: SystemConfig | None = None, origin=None):
        if getattr(model_vehicle, "kind", None) != "model":
            raise ValueError("VdpsSystem reads only a model vehicle file (kind = \"model\"), never truth")
        self.vehicle = model_vehicle
        self.config = cfg = config or SystemConfig()
        self.pipeline = EstimatorPipeline(model_vehicle, cfg.pipeline, origin)
        bw = cfg.pipeline.bandwidths
        self._susp = None
        if cfg.suspension_rate_hz or cfg.tire_compliance:
            self._susp = SuspensionConditioner(model_vehicle, cfg.suspension_rate_hz, cfg.tire_compliance,
                                               bw.susp_deflection_hz, cfg.susp_rate_bandwidth_hz, bw.max_gap_s,
                                               stamp=cfg.suspension_stamp)
        self._est_ns = int(round(cfg.estimate_period_s * 1e9))
        self._ident_ns = int(round(cfg.ident_period_s * 1e9))
        self._report_ns = int(round(cfg.ident_report_period_s * 1e9))
        self._next_est: int | None = None
        self._next_ident: int | None = None
        self._next_report: int | None = None
        self.feeder = IdentFeeder(model_vehicle, cfg.feeder) if cfg.identify else None
        self.identifier = Identifier(model_vehicle, cfg.ident, start=cfg.start_params) if cfg.identify else None
        self._chain = None
        self._chain_params = None
        self.require_converged: tuple[str, ...] = ()
        """Problems whose convergence makes a warning valid (module docstring); () = no gate."""
        if cfg.predict:
            from vdps_hil.prediction.predictor import Predictor, load_predictor_config
            from vdps_hil.prediction.warning import WarningChain, load_warning_config

            pcfg = cfg.predictor if cfg.predictor is not None else load_predictor_config()
            pol, node = (cfg.warning_policy, cfg.warning_node)
            if pol is None or node is None:
                dpol, dnode = load_warning_config()
                pol, node = pol or dpol, node or dnode
            params = self._params()
            peff = None
            if cfg.model_effects is not None:
                from vdps_hil.model.effects import effects_from_names

                peff = predictor_effects(effects_from_names(pcfg.effects, {}, pcfg.effect_params),
                                         cfg.model_effects)
            self._chain = WarningChain(Predictor(model_vehicle.with_params(**params.as_dict()), pcfg, peff),
                                       pol, node, keep=WARNING_HISTORY)
            self._chain_params = params
            rc = cfg.require_converged
            if rc is None:  # the policy's rule: gate only a chain started from the priors
                rc = getattr(pol, "require_converged", ()) if cfg.start_params is None else ()
            self.require_converged = tuple(rc)
            if self.identifier is not None and not set(rc) <= set(self.identifier.converged):
                raise ValueError(f"require_converged: unknown identification problem in {rc!r}")
        self._imu_corr = None
        if cfg.model_effects is not None:
            from vdps_hil.estimation.imu_correction import ImuEffectCorrection
            from vdps_hil.model.effects.base import MeasurementEffect

            meas = [e for e in cfg.model_effects if isinstance(e, MeasurementEffect)]
            self._imu_corr = ImuEffectCorrection(meas) if meas else None
        self._log: list[Sample] = []
        self._last_estimate: Estimate | None = None
        self.counters = {"samples": 0, "estimates": 0, "ident_updates": 0, "predictions": 0, "frames": 0,
                         "status": {"valid": 0, "not_converged": 0, "sensor_missing": 0}}

    # ------------------------------------------------------------------ public
    def handle(self, sample: Sample) -> list:
        """Consume one bus sample; returns the outputs it caused (module docstring)."""
        self._log.append(sample)
        self.counters["samples"] += 1
        if self._imu_corr is not None:  # a saved model's IMU effects taken out (estimation.imu_correction)
            sample = self._imu_corr.process(sample)
        out: list = []
        cond = self._susp
        if cond is not None:
            if sample.t_ns >= cond.due_ns:
                for s in cond.due(sample.t_ns):
                    self._step(s, out)
            if sample.kind == "suspension":
                ready = cond.add(sample)
                if ready is not None:
                    for s in ready:
                        self._step(s, out)
                    return out
        if self.feeder is not None:
            self.feeder.observe(sample)
        self._step(sample, out)
        return out

    def finish(self) -> list:
        """End of the input: release a suspension window still open and the measurements the
        pipeline still holds (replay of a file)."""
        out: list = []
        if self._susp is not None:
            for s in self._susp.finish():
                self._step(s, out)
        res = self.pipeline.finish()
        if res:
            self._after(res, self.pipeline.ekf.t_ns or 0, out)
        return out

    @classmethod
    def replay(cls, model_vehicle: Vehicle, config: SystemConfig | None, samples: Iterable[Sample], origin=None,
               finish: bool = True):
        """A fresh system fed ``samples`` in order: (system, all outputs)."""
        sys_ = cls(model_vehicle, config, origin)
        out: list = []
        for s in samples:
            out.extend(sys_.handle(s))
        if finish:
            out.extend(sys_.finish())
        return sys_, out

    @property
    def input_log(self) -> tuple[Sample, ...]:
        return tuple(self._log)

    def clear_input_log(self) -> None:
        """Forget the recorded inputs (a long replay that does not need them), the system's
        and its estimator pipeline's (otherwise a one-hour replay holds every sample)."""
        self._log.clear()
        self.pipeline._log.clear()

    @property
    def last_estimate(self) -> Estimate | None:
        return self._last_estimate

    @property
    def params(self) -> IdentifiedParams:
        """The current identified parameters (the priors or ``start_params`` without identifier)."""
        return self._params()

    def _params(self) -> IdentifiedParams:
        if self.identifier is not None:
            return self.identifier.params
        return self.config.start_params or self.vehicle.params

    def ident_report(self, t_ns: int) -> IdentReport | None:
        idf = self.identifier
        if idf is None:
            return None
        return IdentReport(int(t_ns), idf.params.as_dict(), idf.sigmas, idf.identifiability, idf.converged,
                           {n: c.updates for n, c in idf.counters.items()})

    def status(self) -> dict:
        d = {"counters": dict(self.counters), "pipeline": self.pipeline.counters,
             "rejected": self.pipeline.rejected()}
        if self._susp is not None:
            d["suspension_windows"] = {"windows": self._susp.windows, "samples": self._susp.merged}
        if self.feeder is not None:
            d["feeder"] = dict(self.feeder.counters)
        if self.identifier is not None:
            d["identification"] = self.identifier.status()
        return d

    # ------------------------------------------------------------------ internals
    def _step(self, s: Sample, out: list) -> None:
        self._after(self.pipeline.handle(s), s.t_ns, out)

    def _after(self, res: list, t_sample: int, out: list) -> None:
        """The pipeline's outputs ``res`` for a sample of time ``t_sample``: pass them on, take
        an estimate when the filter has passed the next estimate instant, identify, predict."""
        p = self.pipeline
        if res:
            out.extend(o for o in res if not isinstance(o, Estimate))  # the system takes its own (docstring)
        ekf = p.ekf
        if not ekf.initialized:
            if self._chain is not None:
                self._chain_tick(t_sample, None, out)
            return
        t = ekf.t_ns
        if self._next_est is None:
            self._next_est = t
        if t < self._next_est:
            if self._chain is not None:
                self._chain_tick(t_sample, None, out)
            return
        self._next_est = t - t % self._est_ns + self._est_ns
        est = p.estimate()
        filt_eff = p.filtered()  # suspension: H_eff (rigid-tire geometry, the predictor's eq 13-16)
        filt = filt_eff
        if self._susp is not None:  # the measured deflections (eq 14 forces: the identifier)
            h, hd = self._susp.raw_filtered(t)
            filt = replace(filt_eff, susp_deflection_m=h, susp_rate_mps=hd)
        self._last_estimate = est
        self.counters["estimates"] += 1
        out.append(est)
        if self.config.emit_filtered:
            out.append(filt)
        if self.identifier is not None:
            if self._next_ident is None or t >= self._next_ident:
                self._next_ident = t - t % self._ident_ns + self._ident_ns
                inp = self.feeder.inputs(est, filt)
                if inp is not None:
                    self.identifier.update(inp)
                    self.counters["ident_updates"] += 1
            if self._next_report is None or t >= self._next_report:
                self._next_report = t - t % self._report_ns + self._report_ns
                out.append(self.ident_report(t))
        self._chain_tick(t, (est, filt_eff), out)

    def _chain_tick(self, t_ns: int, ef, out: list) -> None:
        chain = self._chain
        if chain is None:
            return
        from vdps_hil.prediction.predictor import PredictorInitialState
        from vdps_hil.prediction.warning import WarningStatus

        init = None
        status = WarningStatus.NOT_CONVERGED
        if ef is not None:
            est, filt = ef
            try:
                init = PredictorInitialState.from_estimator(est, filt)
                status = WarningStatus.VALID
            except ValueError:
                status = WarningStatus.SENSOR_MISSING
            if status == WarningStatus.VALID and self.require_converged and self.identifier is not None:
                conv = self.identifier.converged
                if not all(conv.get(n, False) for n in self.require_converged):
                    status = WarningStatus.NOT_CONVERGED
        elif self.pipeline.ekf.initialized:
            return  # between estimate instants: the chain runs at the estimate cadence
        params = self._params()
        if init is not None and params is not self._chain_params:
            chain.predictor = chain.predictor.with_params(params)
            self._chain_params = params
        n_before = chain.assessments_total
        frames = chain.handle(t_ns, init, status)
        key = {WarningStatus.VALID: "valid", WarningStatus.NOT_CONVERGED: "not_converged",
               WarningStatus.SENSOR_MISSING: "sensor_missing"}[status]
        self.counters["status"][key] += 1
        if chain.assessments_total > n_before:
            a = chain.last_assessment
            self.counters["predictions"] += 1
            out.append(PredictionReport(a.t0_ns, a.time_to_point_of_no_return_s, a.time_to_tip_up_s, a.peak_ltr,
                                        a.peak_roll_rad, a.horizon_s, a.stop_reason))
        for m in frames:
            self.counters["frames"] += 1
            out.append(CanFrame(int(t_ns), self.config.warning_bus, int(m.arbitration_id), bytes(m.data)))


# ------------------------------------------------------------------------------- file replay
class ReplayError(ValueError):
    """A replay that cannot run (bad option, unreadable input, wrong vehicle file): one line."""


INNOVATION_STATUS = ("accepted", "gated", "nan", "too_old", "disabled", "not_initialized")
"""``status_code`` of ``/est/innovation/<kind>`` messages: index in this tuple."""


PROBE_SECONDS = 3.0
"""A replay infers its sensor set and suspension rate from this much of the decoded data."""

DEFAULT_SUSP_SIGMA_M = 0.001
"""Suspension deflection sigma of a replay (``--susp-sigma``; Table 1: 1 mm)."""


def sample_stats(samples: Iterator[Sample], seconds: float = PROBE_SECONDS
                 ) -> tuple[list[Sample], dict[str, float], dict[str, set]]:
    """Take the samples of the first ``seconds`` from the iterator ``samples`` (plus the first
    sample after them, which ends the window): (the samples taken, in order; sample rate [Hz]
    per kind; catalogue fields with a finite value per kind). Samples of one instant from one
    kind count once in the rate. ``vdps replay`` feeds the samples taken to the system after
    configuring it from the rest, so the recording is decoded once."""
    taken: list[Sample] = []
    first: dict[str, int] = {}
    last: dict[str, int] = {}
    count: dict[str, int] = {}
    fields: dict[str, set] = {}
    t0 = None
    span_ns = seconds * 1e9
    for s in samples:
        taken.append(s)
        t0 = s.t_ns if t0 is None else t0
        if s.t_ns - t0 > span_ns:
            break
        k = s.kind
        fields.setdefault(k, set()).update(n for n, v in s.fields.items() if math.isfinite(v))
        if last.get(k) == s.t_ns:
            continue
        first.setdefault(k, s.t_ns)
        last[k] = s.t_ns
        count[k] = count.get(k, 0) + 1
    rates = {k: (count[k] - 1) * 1e9 / (last[k] - first[k]) for k in count if count[k] > 1 and last[k] > first[k]}
    return taken, rates, fields


_STATE_KEYS = (*STATE_NAMES, "phi_v_rad", "theta_v_rad", "psi_v_rad")
"""Keys of /est/state: the 12 states of eq 7 and the vehicle angles of eq 4."""
_INNOVATION_KEYS = tuple(f"innovation_{i}" for i in range(8))
_FILTERED_SIZES = (3, 3, 4, 4, 4, 4, 4)
_FILTERED_KEYS = (*(f"{stem}_{a}" for stem in ("angular_rate_radps", "angular_accel_radps2") for a in "xyz"),
                  *(f"{stem}_{i}" for stem in ("wheel_speed_radps", "wheel_accel_radps2", "susp_deflection_m",
                                               "susp_rate_mps", "wheel_torque_nm") for i in range(1, 5)),
                  "steer_wheel_angle_rad")
"""Keys of /est/filtered in the order the general loop of ``_est_docs`` writes them."""


def _est_docs(o) -> list[tuple[str, int, dict, dict | None]]:
    """(topic, t_ns, values, sigmas) documents of one system output for ``/est/``."""
    if isinstance(o, Estimate):
        names = _STATE_KEYS
        vals = dict(zip(names, (*o.x, *o.vehicle_angles_rad)))
        sig = dict(zip(names, (*o.sigma, *o.vehicle_angles_sigma_rad)))
        return [("/est/state", o.t_ns, vals, sig)]
    if isinstance(o, Innovation):
        vals = {"nis": o.nis, "dof": float(o.dof), "gate": o.gate,
                "status_code": float(INNOVATION_STATUS.index(o.status)) if o.status in INNOVATION_STATUS else -1.0,
                "accepted": 1.0 if o.status == "accepted" else 0.0, "delayed": 1.0 if o.delayed else 0.0}
        sig = {}
        for i, (v, s) in enumerate(zip(o.innovation, o.innovation_sigma)):
            k = _INNOVATION_KEYS[i] if i < len(_INNOVATION_KEYS) else f"innovation_{i}"
            vals[k] = v
            sig[k] = s
        return [(f"/est/innovation/{o.kind}", o.t_ns, vals, sig)]
    if isinstance(o, FilteredSignals):
        groups = (o.angular_rate_radps, o.angular_accel_radps2, o.wheel_speed_radps, o.wheel_accel_radps2,
                  o.susp_deflection_m, o.susp_rate_mps, o.wheel_torque_nm)
        if tuple(len(g) for g in groups) == _FILTERED_SIZES:  # the keys below, precomputed
            return [("/est/filtered", o.t_ns, dict(zip(_FILTERED_KEYS, (*groups[0], *groups[1], *groups[2],
                     *groups[3], *groups[4], *groups[5], *groups[6], o.steer_wheel_angle_rad))), None)]
        vals = {}
        for stem, v in (("angular_rate_radps", o.angular_rate_radps), ("angular_accel_radps2", o.angular_accel_radps2)):
            vals.update({f"{stem}_{a}": x for a, x in zip("xyz", v)})
        for stem, v in (("wheel_speed_radps", o.wheel_speed_radps), ("wheel_accel_radps2", o.wheel_accel_radps2),
                        ("susp_deflection_m", o.susp_deflection_m), ("susp_rate_mps", o.susp_rate_mps),
                        ("wheel_torque_nm", o.wheel_torque_nm)):
            vals.update({f"{stem}_{i}": x for i, x in enumerate(v, 1)})
        vals["steer_wheel_angle_rad"] = o.steer_wheel_angle_rad
        return [("/est/filtered", o.t_ns, vals, None)]
    if isinstance(o, IdentReport):
        vals = dict(o.params)
        vals.update({f"identifiability_{k}": v for k, v in o.identifiability.items()})
        vals.update({f"converged_{k}": 1.0 if v else 0.0 for k, v in o.converged.items()})
        vals.update({f"updates_{k}": float(v) for k, v in o.updates.items()})
        return [("/est/ident", o.t_ns, vals, dict(o.sigmas))]
    if isinstance(o, PredictionReport):
        nan = math.nan
        vals = {"time_to_point_of_no_return_s": nan if o.time_to_point_of_no_return_s is None
                else o.time_to_point_of_no_return_s,
                "time_to_tip_up_s": nan if o.time_to_tip_up_s is None else o.time_to_tip_up_s,
                "peak_ltr": o.peak_ltr, "peak_roll_rad": o.peak_roll_rad, "horizon_s": o.horizon_s}
        return [("/est/prediction", o.t0_ns, vals, None)]
    return []


def replay_file(path, *, vehicle: str | Vehicle = "sedan-model", output=None, model=None, dbc=None,
                signalmap=None, bus_map: Mapping[str, str] | None = None, params=None, save_params=None,
                config: SystemConfig | None = None, identify: bool = True, predict: bool = True,
                susp_sigma_m: float = DEFAULT_SUSP_SIGMA_M, paper_faithful=None, copy_raw: bool = True,
                sensorset=None, input_order: str = "time", jobs: int = 1) -> dict:
    """Replay a recording's ``/raw/`` topics through :class:`VdpsSystem` (``vdps replay``).

    Decodes only ``/raw/`` (``record.decode``), runs the system, writes ``output`` (MCAP: the
    raw topics copied unchanged, ``/est/state`` with sigmas, ``/est/innovation/<kind>`` with NIS,
    ``/est/filtered``, ``/est/ident``, ``/est/prediction`` and the sent VDPS_Warning frames on
    ``/est/can/<bus>`` (schema vdps.RawCan.v1, direction tx)) and returns the summary (the
    ``--json`` document). ``vehicle``: a *model* vehicle file or name (a truth file is refused);
    ``params``: a saved parameter file to start the identifier from; ``save_params``: where to
    save the identified parameters; ``model``: a saved workbench model
    (``vdps_hil.workbench.model_file``); ``paper_faithful``: names of the EKF switches set to
    the paper as printed (``"all"`` for all four); ``sensorset``: a named sensor set
    (``configs/sensorsets``; default: inferred from the fields the recording carries, e.g. an
    ESC cluster without suspension -> ``esc3``, no road angles). Without ``config`` the
    suspension window averaging is sized from the measured sample rate and ``susp_sigma_m``
    (Table 1: 1 mm). ``input_order``: ``"time"`` (the decoded ``/raw/`` samples in time order) or
    ``"recorded"`` (the ``/decoded/`` samples in the order a live system received them, metadata
    ``hil.input_order`` of a ``vdps bench -o`` or ``vdps log --pipeline -o`` recording: the replay
    reproduces the live estimates; the ``/raw/`` topics are still decoded for the counters and
    copied; a log's recorded settings (``recorded_config``) must match and size the config). ``jobs``: 2
    decodes the recording and writes the output in a second process (``record.replay_io``)
    while this one runs the system: the same messages, less wall time on two free cores (the
    ``recorded`` order always runs in one). Raises :class:`ReplayError` (one line)."""
    import os
    import time

    from vdps_hil.record.reader import RecordingError, RecordingReader
    from vdps_hil.record.replay_io import LocalRecordingSide, RecordingProcess, ReplayIOError, SampleCounter

    wall0 = time.perf_counter()
    veh = _load_model_vehicle(vehicle)
    start = None
    if params is not None and model is not None:
        raise ReplayError("give --params or --model (a saved model carries its parameters), not both")
    if params is not None:
        from vdps_hil.identification.persistence import ParamsFileError, load_params

        try:
            start = load_params(params, veh).params
        except ParamsFileError as e:
            raise ReplayError(str(e)) from None
    model_effects, model_doc = None, None
    if model is not None:
        start, model_effects, model_doc = _load_workbench_model(model, veh)
    if save_params is not None and not identify:
        raise ReplayError("--save-params needs the identifier (drop --no-identify)")
    if input_order not in ("time", "recorded"):
        raise ReplayError(f"input order must be 'time' or 'recorded', got {input_order!r}")
    if jobs not in (1, 2):
        raise ReplayError(f"jobs must be 1 or 2 (decoding and the system), got {jobs!r}")
    try:
        reader = RecordingReader(path)
    except RecordingError as e:
        raise ReplayError(str(e)) from None
    try:
        recorded, probe = None, None
        if input_order == "recorded":
            from vdps_hil.record.input_order import INPUT_ORDER_METADATA, read_input_order

            if INPUT_ORDER_METADATA not in reader.metadata():
                raise ReplayError(f"{os.fspath(path)}: no recorded input order (metadata {INPUT_ORDER_METADATA}, "
                                  "written by vdps bench -o and vdps log --pipeline -o without rotation); "
                                  "use --input-order time")
            try:
                recorded, settings = read_input_order(reader)
                if config is None:
                    probe = recorded_config(settings, veh, start, susp_sigma_m)
            except ReplayError:
                raise
            except (ValueError, KeyError, IndexError, TypeError, AttributeError) as e:
                raise ReplayError(f"{os.fspath(path)}: recorded input order unreadable: {e}") from None
        if config is not None and sensorset is not None:
            raise ReplayError("give a sensor set or a config, not both")
        # the recording side (decoding, the output) here or in a second process (record.replay_io);
        # raw records read before the configuration is accepted wait, so a refused one writes nothing
        side = None
        try:
            io_kw = dict(dbc=dbc, signalmap=signalmap, bus_map=bus_map, output=output, copy_raw=copy_raw)
            if jobs == 2 and recorded is None:
                side = RecordingProcess(path, **io_kw)
            else:
                side = LocalRecordingSide(reader, **io_kw)
            head: list[Sample] = []
            kind_map, nodes, sensors_desc = {}, [], None
            if config is None:  # the sensor set and suspension rate from the first seconds, decoded once
                head, rates, fields = sample_stats(side) if probe is None else ([], *probe)
                config, kind_map, nodes, sensors_desc = _replay_config(
                    rates, fields, veh, susp_sigma_m, paper_faithful, sensorset, identify=identify, predict=predict)
            side.start_output({"source": "vdps replay", "input": os.path.basename(os.fspath(path)),
                               "vehicle": veh.name, "vehicle_sha256": veh.source_sha256})
            if start is not None:
                config = replace(config, start_params=start)
            if model_effects is not None:
                config = replace(config, model_effects=model_effects)
            system = VdpsSystem(veh, config)
            system.clear_input_log()
            summary = _Summary()
            handle = system.handle
            n = 0
            source = itertools.chain(head, side)
            counter = None  # the decoded samples are counted by the recording side
            count = None
            if recorded is not None:
                for _ in side:  # the decoders' counters, and the raw copy
                    pass
                counter = SampleCounter()
                source, count = recorded, counter.count
            for s in source:
                if count is not None:
                    count(s)
                if kind_map and s.kind in kind_map:
                    s = Sample(s.t_ns, s.source, kind_map[s.kind], s.fields, s.wall_time_ns, s.valid)
                for node in nodes:
                    s = node.process(s)
                outs = handle(s)
                n += 1
                if n >= 4096:  # a file replay keeps the file, not a copy in memory
                    system.clear_input_log()
                    n = 0
                if outs:
                    summary.outputs(outs, side.writer)
            summary.outputs(system.finish(), side.writer)
            side.finish()
            summary.take_counts(side.sample_counts if counter is None else counter.document())
        except ReplayIOError as e:
            raise ReplayError(str(e)) from None
        finally:
            if side is not None:
                side.abort()
    finally:
        reader.close()
    wall = time.perf_counter() - wall0
    doc = summary.document(system, side, veh)
    doc.update({"input": os.fspath(path), "output": None if output is None else os.fspath(output),
                "vehicle": veh.name, "sensor_set": sensors_desc, "wall_time_s": wall,
                "realtime_factor": (doc["duration_s"] / wall) if wall > 0 and doc["duration_s"] else None,
                "jobs": 2 if isinstance(side, RecordingProcess) else 1})
    if model_doc is not None:
        doc["model"] = model_doc
    if save_params is not None:
        from vdps_hil.identification.persistence import ParamsFileError, save_params as _save

        idf = system.identifier
        try:
            _save(save_params, idf.params, veh, sigmas=idf.sigmas,
                  meta={"source": os.path.basename(os.fspath(path)), "updates":
                        {n: c.updates for n, c in idf.counters.items()}})
        except ParamsFileError as e:
            raise ReplayError(str(e)) from None
        doc["saved_params"] = os.fspath(save_params)
    return doc


def recorded_config(settings: Mapping[str, Any], veh: Vehicle, start: IdentifiedParams | None,
                    susp_sigma_m: float) -> tuple[dict[str, float], dict[str, set]] | None:
    """The probe statistics (rates [Hz] per kind, fields per kind) a live ``vdps log --pipeline``
    sized its system from, recorded with its input order (``system`` setting), or None (a bench
    recording: the replay probes the ``/raw/`` topics). The live system's vehicle, starting
    parameters and suspension sigma must be the replay's, else ReplayError names the option:
    ``--input-order recorded`` is for reproducing the live run."""
    sysd = settings.get("system")
    if sysd is None:
        return None
    if sysd["vehicle_sha256"] != veh.source_sha256:
        raise ReplayError(f"the live system ran vehicle {sysd['vehicle']!r} (another file than {veh.name!r}): "
                          f"give --vehicle {sysd['vehicle']} to reproduce it")
    mine = None if start is None else _clean(start.as_dict())
    if sysd["start_params"] != mine:
        raise ReplayError("the live system started from " + (
            "the priors: drop --params/--model" if sysd["start_params"] is None else
            f"the parameters of {sysd.get('params_file')!r}: give them as --params") + " to reproduce it")
    if sysd["susp_sigma_m"] != susp_sigma_m:
        raise ReplayError(f"the live system used --susp-sigma {sysd['susp_sigma_m']!r}: give it to reproduce it")
    rates = {str(k): float(v) for k, v in sysd["probe_rates_hz"].items()}
    fields = {str(k): {str(f) for f in v} for k, v in sysd["probe_fields"].items()}
    return rates, fields


def _load_model_vehicle(vehicle) -> Vehicle:
    if isinstance(vehicle, Vehicle):
        if vehicle.kind != "model":
            raise ReplayError(f"vehicle {vehicle.name} is a {vehicle.kind} file; the replay needs a model file")
        return vehicle
    from vdps_hil.model.params import VehicleFileError, load_vehicle

    try:
        return load_vehicle(vehicle, "model")
    except VehicleFileError as e:
        raise ReplayError(str(e).splitlines()[0]) from None


def predictor_effects(base, model_effects):
    """The predictor's configured effects (``base``, e.g. the paper's ``linear_tire``) with a
    saved workbench model's *dynamics* effects joined: a tire model in the workbench model
    replaces the configured tire, any other effect is added (an effect of the same name is
    taken from the workbench model). Measurement effects are not part of the predictor."""
    from vdps_hil.model.effects import EffectSet
    from vdps_hil.model.effects.base import TireModel

    added = list(EffectSet(model_effects).dynamics)
    names = {e.name for e in added}
    new_tire = any(isinstance(e, TireModel) for e in added)
    keep = [e for e in base if e.name not in names and not (new_tire and isinstance(e, TireModel))]
    return EffectSet(keep + added)


def _load_workbench_model(path, vehicle: Vehicle):
    """A saved workbench model (``vdps diagnose --save-model``; format and checks in
    ``vdps_hil.workbench.model_file``): (identified parameters that start the identifier, the
    model's effects: dynamics for the predictor, IMU measurement effects taken out of the
    readings by ``VdpsSystem``; a summary for the JSON). Errors are one line."""
    from vdps_hil.model.effects.base import MeasurementEffect
    from vdps_hil.workbench.model_file import ModelFileError, load_model

    try:
        veh, effects, mf = load_model(path, vehicle)
    except (ModelFileError, OSError, ValueError) as e:
        msg = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise ReplayError(f"--model: {msg}") from None
    doc = {"file": str(path), "vehicle": mf.vehicle, "source": mf.source,
           "effects": [e.name for e in effects],
           "predictor_effects": [e.name for e in effects.dynamics],
           "imu_corrected": [e.name for e in effects if isinstance(e, MeasurementEffect)]}
    return veh.params, effects, doc


def _replay_config(rates: Mapping[str, float], fields: Mapping[str, set], veh, susp_sigma_m, paper_faithful,
                   sensorset=None, **kw):
    """(SystemConfig, kind_map, sample nodes, sensor-set description) for a replay, from the
    sample ``rates`` and ``fields`` of the recording's first seconds (``sample_stats``): the
    sensor set from ``sensorset`` (``configs/sensorsets``: sensors, noise, latencies, kind map,
    calibration nodes) or inferred from the fields the recording carries
    (``estimation.sensorsets.infer_sensor_set``); the suspension averaging from its measured rate."""
    from vdps_hil.estimation.ekf import PaperFaithful
    from vdps_hil.estimation.sensorsets import SensorSetError, infer_sensor_set, load_sensorset

    pc = default_pipeline_config()
    nodes: list = []
    try:
        if sensorset is not None:
            sset = load_sensorset(sensorset)
            keep = {k: getattr(pc, k) for k in ("gnss_speed_sigma_mps",) if k not in sset.pipeline}  # system defaults
            pc = replace(sset.pipeline_config(**keep), emit_estimates=False, bandwidths=pc.bandwidths)
            kind_map = dict(sset.kind_map)
            nodes = sset.calibration_nodes(veh)
            desc = {"source": sset.name, **sset.sensors.__dict__}
        else:
            sensors, kind_map = infer_sensor_set(fields)
            pc = replace(pc, ekf=replace(pc.ekf, sensors=sensors))
            desc = {"source": "inferred from the recording", **sensors.__dict__}
    except SensorSetError as e:
        raise ReplayError(str(e)) from None
    if paper_faithful:
        names = set(paper_faithful)
        pf = PaperFaithful.all() if "all" in names else PaperFaithful(**{n: True for n in names})
        pc = replace(pc, ekf=replace(pc.ekf, paper_faithful=pf))
    if not (math.isfinite(susp_sigma_m) and susp_sigma_m > 0):
        raise ReplayError(f"suspension sigma must be positive, got {susp_sigma_m!r}")
    desc["kind_map"] = kind_map
    cfg = SystemConfig.for_profile(rates.get("suspension", 1.0), susp_sigma_m, pipeline=pc, **kw)
    return cfg, kind_map, nodes, desc


def write_output(o, writer) -> None:
    """One system output into a RecordingWriter in the ``vdps replay`` layout: a ``CanFrame`` on
    ``/est/can/<bus>`` (vdps.RawCan.v1, tx), the others by ``_est_docs``."""
    from vdps_hil.record import schemas as S

    if isinstance(o, CanFrame):
        doc = S.raw_can_doc(o.t_ns, o.arbitration_id, o.data, direction="tx")
        writer.write_json(f"/est/can/{o.bus}", S.RAW_CAN, o.t_ns, doc, channel_metadata={"bus": o.bus})
        return
    for topic, t, vals, sig in _est_docs(o):
        writer.write_estimate(topic, t, vals, sig)


class _Summary:
    """Running summary of a replay (the ``--json`` document)."""

    def __init__(self):
        self.samples: dict[str, int] = {}
        self.t_first = None
        self.t_last = None
        self.n_est = 0
        self.est_first = None
        self.est_last: Estimate | None = None
        self.sig_sum = None
        self.innov: dict[str, list] = {}
        self.pred = {"predictions": 0, "rollover_predicted": 0, "min_time_to_point_of_no_return_s": None}
        self.frames = {"sent": 0, "max_level": 0}

    def take_counts(self, counts: Mapping) -> None:
        """The samples the replay fed (``record.replay_io.SampleCounter``)."""
        self.samples = dict(counts["per_source_kind"])
        self.t_first, self.t_last = counts["t_first_ns"], counts["t_last_ns"]

    def outputs(self, outs, writer) -> None:
        for o in outs:
            if isinstance(o, Estimate):
                self.n_est += 1
                if self.est_first is None:
                    self.est_first = o.t_ns
                self.est_last = o
                sig = [v * v for v in o.sigma]
                self.sig_sum = sig if self.sig_sum is None else [a + b for a, b in zip(self.sig_sum, sig)]
            elif isinstance(o, Innovation):
                c = self.innov.setdefault(o.kind, [0, 0, 0.0, 0])
                c[0] += 1
                if o.status == "accepted":
                    c[1] += 1
                    if math.isfinite(o.nis) and o.dof:
                        c[2] += o.nis
                        c[3] += o.dof
            elif isinstance(o, PredictionReport):
                p = self.pred
                p["predictions"] += 1
                if o.time_to_point_of_no_return_s is not None:
                    p["rollover_predicted"] += 1
                    m = p["min_time_to_point_of_no_return_s"]
                    p["min_time_to_point_of_no_return_s"] = o.time_to_point_of_no_return_s if m is None else \
                        min(m, o.time_to_point_of_no_return_s)
            elif isinstance(o, CanFrame):
                self.frames["sent"] += 1
                self.frames["max_level"] = max(self.frames["max_level"], (o.data[1] >> 4) & 0x3)
            if writer is not None:
                write_output(o, writer)

    def document(self, system: "VdpsSystem", side, veh: Vehicle) -> dict:
        """The ``--json`` document; ``side``: the replay's recording side (``record.replay_io``)."""
        from vdps_hil.estimation.states import STATE_NAMES

        dur = (self.t_last - self.t_first) / 1e9 if self.t_first is not None else 0.0
        est = self.est_last
        es = {"count": self.n_est,
              "t_first_s": None if self.est_first is None else self.est_first / 1e9,
              "t_last_s": None if est is None else est.t_ns / 1e9}
        if est is not None:
            es["final"] = {"state": dict(zip(STATE_NAMES, est.x)), "sigma": dict(zip(STATE_NAMES, est.sigma)),
                           "vehicle_angles_rad": dict(zip(("phi_v", "theta_v", "psi_v"), est.vehicle_angles_rad))}
            es["rms_sigma"] = {n: math.sqrt(v / self.n_est) for n, v in zip(STATE_NAMES, self.sig_sum)}
        rejected = dict(side.rejected())
        rejected.update(system.pipeline.rejected())
        obs = [{"t_start_s": a / 1e9, "t_end_s": b / 1e9, "rank": r.rank, "n_states": r.n_states,
                "unobservable": list(r.unobservable)} for a, b, r in system.pipeline.observability_reports]
        now = system.pipeline.observability_now()
        reader_c = side.counters["reader"]
        doc = {
            "duration_s": dur,
            "messages_read": {"raw_records": reader_c["raw_records"], "samples": sum(self.samples.values()),
                              "per_source_kind": dict(sorted(self.samples.items()))},
            "estimates_summary": es,
            "innovations": {k: {"updates": c[0], "accepted": c[1],
                                "mean_nis_per_dof": (c[2] / c[3]) if c[3] else None}
                            for k, c in sorted(self.innov.items())},
            "rejected": rejected,
            "observability": {"windows": obs, "in_progress": None if now is None else
                              {"rank": now.rank, "n_states": now.n_states, "unobservable": list(now.unobservable)}},
            "decode": {k: v for k, v in side.counters.items()},
            "decoding": dict(side.decoding),
            "system": system.status()["counters"],
        }
        # computed observability (issue 11): structural rank of the sensor set, each window's null
        # space explained, and each identification problem's information with its cause
        from vdps_hil.estimation.observability_report import observability_report
        try:
            doc["observability"].update(observability_report(system.pipeline, system.identifier).to_json())
        except (ValueError, np.linalg.LinAlgError) as e:  # a degenerate window must not lose the run
            doc["observability"]["report_error"] = f"{e.__class__.__name__}: {e}"
        if system.identifier is not None:
            st = system.identifier.status()
            st["prior"] = veh.params.as_dict()
            doc["identification"] = st
        if system.config.predict:
            doc["prediction"] = dict(self.pred, frames_sent=self.frames["sent"], max_level=self.frames["max_level"])
        return doc
