"""Rollover warning: rollover measures of a prediction, the warning policy, and the pure node that
sends ``VDPS_Warning`` on CAN (paper section 7.3 "the dynamic prediction system can predict the
rollover event"; the message layout is ``dbc/vdps.dbc`` / :mod:`vdps_hil.codecs.can_dbc`).

Rollover measures of one prediction (definitions of :mod:`vdps_hil.model.rollover`, applied to the
predicted trajectory; never redefined here)
-----------------------------------------------------------------------------------------------
::

    phi_v(t)      roll relative to the road (eq 3-4; right side down +)
    LTR(t)      = (F_z,right - F_z,left) / (F_z,right + F_z,left),  right = wheels 2, 3
                  (predicted eq 14 wheel loads; +1: the left wheels carry nothing)
    PLTR        = LTR(t*) with t* = argmax_t |LTR(t)| over the horizon  (predictive LTR)
    TTR         = t_PONR - t_now     (predicted point of no return: |phi_v| > atan(t_half / h_cg)
                                      while still rising; the prediction starts at t0 <= t_now)
    TTT         = t_tip - t_now      (predicted tip-up: one side below 1 % of its static load for
                                      0.2 s; t_tip is the start of that interval)

Policy (``[warning]`` of ``configs/prediction/default.toml``)
------------------------------------------------------------
With T_w = reaction_time_s + margin_s::

    level 3 imminent   TTR <= imminent_time_s
    level 2 warning    TTR <= T_w
    level 1 caution    a PONR is predicted within the horizon (caution_on_predicted_rollover),
                       or |PLTR| >= caution_ltr
    level 0 none       otherwise

A level may rise at once; it may fall only after it has been held ``hold_s`` without the
raw level reaching it again (no chatter while the steering crosses zero in a fishhook).

The node (``WarningNode.handle(t_ns, assessment_or_prediction, status) -> [can.Message]``)
-------------------------------------------------------------------------------------------
Pure (time only from ``t_ns``): sends VDPS_Warning every ``period_s`` (50 Hz) and at once when the
level changes; fields: ``warning_level``, ``warning_time_to_rollover_s`` (TTR, None when no
rollover is predicted), ``warning_peak_roll_rad`` (the predicted road-relative roll of largest
magnitude, signed), ``warning_ltr`` (PLTR, signed), ``warning_status`` (0 valid, 1 not converged,
2 sensor missing, 3 fault), rolling counter and CRC-8 via :class:`VdpsCanEncoder`. Status: the
caller's (estimator/identifier not converged, a sensor missing); 3 (fault) when the latest
prediction is older than ``max_prediction_age_s``; 1 until the first prediction arrives. The
level is sent whatever the status: a receiver acts on it only when the status is 0.

Validity (``require_converged``)
--------------------------------
The predictor runs with the parameters identified so far. When the identifier started from the
model file's priors (a first drive: no ``--params`` / ``SystemConfig.start_params``), the system
(:class:`vdps_hil.pipeline.node.VdpsSystem`) sends status 1 "not converged" until every identification
problem named in ``require_converged`` (default ``["cornering"]``: the cornering stiffnesses, the
predictor's most sensitive parameters) has converged (``Identifier.converged``: every sigma/|x|
below ``converged_rel_sigma``); started from identified parameters, frames are valid at once.
From the sedan-model priors (C_alpha front x1.5, rear x0.6: an oversteering model) the predictor
foresaw rollovers in the paper's sine steering before the cornering problem converged.

Lead time and false alarms
--------------------------
Scored against the simulator's truth events outside the pipeline:
``vdps_hil.experiments.scoring.evaluate_warning_frames`` decodes the sent frames and gives the lead
time to the truth point of no return and the false alarms (this module never reads truth).

Symbols: t_half mean half track [m], h_cg CG height [m], F_z normal load [N], times [s].
"""

from __future__ import annotations

import enum
import math
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Mapping, MutableSequence, Sequence

import can
import numpy as np

from vdps_hil.codecs.can_dbc import WARNING
from vdps_hil.codecs.can_decode import VdpsCanDecoder
from vdps_hil.codecs.can_encode import VdpsCanEncoder
from vdps_hil.units import NS_PER_S

from .config import DEFAULT_CONFIG_PATH, PredictionConfigError, load_prediction_document
from .initial_state import PredictorInitialState
from .predictor import Cadence, Predictor
from .result import PredictionResult


class WarningLevel(enum.IntEnum):
    NONE = 0
    CAUTION = 1
    WARNING = 2
    IMMINENT = 3


class WarningStatus(enum.IntEnum):
    """``warning_status`` of VDPS_Warning (dbc/vdps.dbc)."""

    VALID = 0
    NOT_CONVERGED = 1
    SENSOR_MISSING = 2
    FAULT = 3


# ---------------------------------------------------------------------------------------------
# rollover measures of a prediction
# ---------------------------------------------------------------------------------------------
def load_transfer_ratio(normal_load_n) -> np.ndarray:
    """LTR = (F_right - F_left) / (F_right + F_left) per sample of (N, 4) wheel loads (FL FR RR
    RL; right = 2, 3), 0 where the total is 0. Same sign as the simulator's ``ltr``."""
    fz = np.atleast_2d(np.asarray(normal_load_n, dtype=float))
    left = fz[:, 0] + fz[:, 3]
    right = fz[:, 1] + fz[:, 2]
    tot = left + right
    return np.divide(right - left, tot, out=np.zeros_like(tot), where=tot > 0)


def roll_relative_to_road(result: PredictionResult) -> np.ndarray:
    """phi_v(t) of the prediction [rad] (eq 4)."""
    return result.euler_v_rad[:, 0]


def predictive_ltr(result: PredictionResult) -> tuple[float, float]:
    """(PLTR, t*): the predicted LTR of largest magnitude (signed) and its time after t0 [s]."""
    ltr = load_transfer_ratio(result.normal_load_n)
    k = int(np.argmax(np.abs(ltr)))
    return float(ltr[k]), float(result.t_s[k])


@dataclass(frozen=True)
class RolloverAssessment:
    """What the policy needs from one prediction (times after t0 [s]; None = not predicted)."""

    t0_ns: int
    time_to_point_of_no_return_s: float | None
    time_to_tip_up_s: float | None
    peak_ltr: float
    peak_ltr_t_s: float
    peak_roll_rad: float
    horizon_s: float
    stop_reason: str

    @classmethod
    def from_prediction(cls, result: PredictionResult) -> "RolloverAssessment":
        pltr, tpk = predictive_ltr(result)
        roll = roll_relative_to_road(result)
        k = int(np.argmax(np.abs(roll)))
        return cls(int(result.t0_ns), result.point_of_no_return_t_s, result.tip_up_t_s, pltr, tpk,
                   float(roll[k]), float(result.t_s[-1]), result.stop_reason)

    def ttr_at(self, t_ns: int) -> float | None:
        """Time from ``t_ns`` to the predicted point of no return [s] (>= 0), or None."""
        if self.time_to_point_of_no_return_s is None:
            return None
        return max(0.0, self.time_to_point_of_no_return_s - (t_ns - self.t0_ns) / NS_PER_S)

    def to_json(self) -> dict:
        return dict(self.__dict__)


# ---------------------------------------------------------------------------------------------
# policy
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class WarningPolicy:
    """Level from a rollover assessment (module docstring). Times [s], LTR [-]."""

    reaction_time_s: float = 1.0
    margin_s: float = 0.5
    imminent_time_s: float = 0.5
    caution_ltr: float = 0.9
    caution_on_predicted_rollover: bool = True
    hold_s: float = 0.5
    require_converged: tuple[str, ...] = ("cornering",)
    """Validity (module docstring, "Validity"): identification problems that must have converged
    before a frame is sent with status 0 when the identifier started from the priors."""

    def __post_init__(self):
        for n in ("reaction_time_s", "margin_s", "imminent_time_s", "caution_ltr", "hold_s"):
            v = getattr(self, n)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
                raise PredictionConfigError(f"warning.{n} must be a finite number >= 0, got {v!r}")
        from vdps_hil.identification.config import PROBLEM_NAMES

        rc = self.require_converged
        if isinstance(rc, str) or not all(isinstance(n, str) for n in rc):
            raise PredictionConfigError(f"warning.require_converged must be a list of problem names, got {rc!r}")
        unknown = sorted(set(rc) - set(PROBLEM_NAMES))
        if unknown:
            raise PredictionConfigError(f"warning.require_converged: unknown identification problem {unknown[0]!r} "
                                        f"(known: {', '.join(PROBLEM_NAMES)})")
        object.__setattr__(self, "require_converged", tuple(rc))
        if self.imminent_time_s > self.warning_time_s:
            raise PredictionConfigError("warning.imminent_time_s must not exceed reaction_time_s + margin_s")

    @property
    def warning_time_s(self) -> float:
        """T_w = reaction time + margin [s]."""
        return self.reaction_time_s + self.margin_s

    def level(self, assessment: RolloverAssessment | None, t_ns: int) -> WarningLevel:
        """The raw (un-held) level at ``t_ns`` from the latest assessment."""
        if assessment is None:
            return WarningLevel.NONE
        ttr = assessment.ttr_at(t_ns)
        if ttr is not None:
            if ttr <= self.imminent_time_s:
                return WarningLevel.IMMINENT
            if ttr <= self.warning_time_s:
                return WarningLevel.WARNING
            if self.caution_on_predicted_rollover:
                return WarningLevel.CAUTION
        if abs(assessment.peak_ltr) >= self.caution_ltr:
            return WarningLevel.CAUTION
        return WarningLevel.NONE


@dataclass(frozen=True)
class WarningNodeConfig:
    period_s: float = 0.02
    max_prediction_age_s: float = 0.5
    prediction_latency_s: float = 0.02

    def __post_init__(self):
        for n in ("period_s", "max_prediction_age_s"):
            v = getattr(self, n)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
                raise PredictionConfigError(f"warning.{n} must be a positive finite number, got {v!r}")
        v = self.prediction_latency_s
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
            raise PredictionConfigError(f"warning.prediction_latency_s must be >= 0, got {v!r}")


_POLICY_KEYS = set(WarningPolicy.__dataclass_fields__)
_NODE_KEYS = set(WarningNodeConfig.__dataclass_fields__)


def warning_config_from_table(t: Mapping, where: str = "[warning]") -> tuple[WarningPolicy, WarningNodeConfig]:
    if not isinstance(t, Mapping):
        raise PredictionConfigError(f"{where}: expected a table")
    unknown = sorted(set(t) - _POLICY_KEYS - _NODE_KEYS)
    if unknown:
        raise PredictionConfigError(f"{where}: unknown key {unknown[0]!r}")
    if "caution_on_predicted_rollover" in t and not isinstance(t["caution_on_predicted_rollover"], bool):
        raise PredictionConfigError(f"{where}.caution_on_predicted_rollover: expected true or false")
    if "require_converged" in t and not isinstance(t["require_converged"], list):
        raise PredictionConfigError(f"{where}.require_converged: expected a list of problem names")
    pol = WarningPolicy(**{k: v for k, v in t.items() if k in _POLICY_KEYS})
    node = WarningNodeConfig(**{k: v for k, v in t.items() if k in _NODE_KEYS})
    return pol, node


def load_warning_config(path: str | Path | None = None) -> tuple[WarningPolicy, WarningNodeConfig]:
    """The ``[warning]`` table of a prediction config file."""
    doc = load_prediction_document(path)
    return warning_config_from_table(doc.get("warning", {}), f"{path or DEFAULT_CONFIG_PATH}[warning]")


# ---------------------------------------------------------------------------------------------
# the node
# ---------------------------------------------------------------------------------------------
class WarningNode:
    """Pure node: ``handle(t_ns, prediction, status) -> list[can.Message]`` (module docstring).

    ``prediction``: a new :class:`PredictionResult` or :class:`RolloverAssessment` that is
    usable from ``t_ns`` on, or None (nothing new). Call it at least every ``period_s``."""

    def __init__(self, policy: WarningPolicy | None = None, config: WarningNodeConfig | None = None,
                 encoder: VdpsCanEncoder | None = None):
        self.policy = policy or WarningPolicy()
        self.config = config or WarningNodeConfig()
        self._enc = encoder or VdpsCanEncoder()
        self._period_ns = int(round(self.config.period_s * NS_PER_S))
        self._max_age_ns = int(round(self.config.max_prediction_age_s * NS_PER_S))
        self._hold_ns = int(round(self.policy.hold_s * NS_PER_S))
        self._assessment: RolloverAssessment | None = None
        self._level = WarningLevel.NONE
        self._confirmed_ns: int | None = None
        self._last_sent_ns: int | None = None
        self.frames_sent = 0

    @property
    def level(self) -> WarningLevel:
        return self._level

    @property
    def assessment(self) -> RolloverAssessment | None:
        return self._assessment

    def _update_level(self, t_ns: int) -> bool:
        raw = self.policy.level(self._assessment, t_ns)
        if raw >= self._level:
            changed = raw != self._level
            self._level = raw
            self._confirmed_ns = t_ns
            return changed
        if self._confirmed_ns is None or t_ns - self._confirmed_ns >= self._hold_ns:
            self._level = raw
            self._confirmed_ns = t_ns
            return True
        return False

    def handle(self, t_ns: int, prediction: PredictionResult | RolloverAssessment | None = None,
               status: int = WarningStatus.VALID) -> list[can.Message]:
        t_ns = int(t_ns)
        if prediction is not None:
            self._assessment = (prediction if isinstance(prediction, RolloverAssessment)
                                else RolloverAssessment.from_prediction(prediction))
        changed = self._update_level(t_ns)
        due = self._last_sent_ns is None or t_ns - self._last_sent_ns >= self._period_ns
        if not (changed or due):
            return []
        a = self._assessment
        st = WarningStatus(int(status))
        if a is None:
            if st == WarningStatus.VALID:
                st = WarningStatus.NOT_CONVERGED
            ttr, roll, ltr = None, 0.0, 0.0
        else:
            if st == WarningStatus.VALID and t_ns - a.t0_ns > self._max_age_ns:
                st = WarningStatus.FAULT
            ttr, roll, ltr = a.ttr_at(t_ns), a.peak_roll_rad, a.peak_ltr
            if not (math.isfinite(roll) and math.isfinite(ltr)):  # a prediction gone NaN: a fault
                st, roll, ltr = WarningStatus.FAULT, 0.0, 0.0
        msg = self._enc.warning(int(self._level), ttr, roll, ltr, int(st), t_ns=t_ns)
        self._last_sent_ns = t_ns
        self.frames_sent += 1
        return [msg]


# ---------------------------------------------------------------------------------------------
# predictor + cadence + node
# ---------------------------------------------------------------------------------------------
class WarningChain:
    """The warning path as one pure object: ``handle(t_ns, initial_state, status)`` predicts at
    the configured cadence (held inputs) and feeds the node; a prediction started at t0 is used
    from t0 + ``prediction_latency_s`` on (its compute time on the target). ``initial_state``
    None: no estimate now (status should then say why).

    Storage: ``frames`` (the sent frames) and ``assessments`` (one per prediction, t0 inside)
    keep the most recent ``keep`` of each (``keep`` None: all of them, for a study of one
    drive that evaluates the frames afterwards, e.g.
    ``vdps_hil.experiments.scoring.evaluate_warning_frames``); a
    long-running system passes a bound so memory does not grow with the drive (50 frames per
    second otherwise). Counts over the whole run: ``frames_total``, ``assessments_total``; the
    latest assessment: ``last_assessment``."""

    def __init__(self, predictor: Predictor, policy: WarningPolicy | None = None,
                 node_config: WarningNodeConfig | None = None, keep: int | None = None):
        if keep is not None and (isinstance(keep, bool) or not isinstance(keep, int) or keep < 0):
            raise ValueError(f"keep must be None or an integer >= 0, got {keep!r}")
        self.predictor = predictor
        self.node = WarningNode(policy, node_config)
        self.cadence = Cadence(predictor.config.cadence_hz)
        self._latency_ns = int(round(self.node.config.prediction_latency_s * NS_PER_S))
        self._pending: deque[tuple[int, RolloverAssessment]] = deque()
        self.keep = keep
        self.frames: MutableSequence[can.Message] = [] if keep is None else deque(maxlen=keep)
        self.assessments: MutableSequence[RolloverAssessment] = [] if keep is None else deque(maxlen=keep)
        self.frames_total = 0
        self.assessments_total = 0
        self.last_assessment: RolloverAssessment | None = None
        self.prediction_failures = 0
        self.last_failure: str | None = None

    def handle(self, t_ns: int, initial_state: PredictorInitialState | None,
               status: int = WarningStatus.VALID) -> list[can.Message]:
        t_ns = int(t_ns)
        if initial_state is not None and self.cadence.due(t_ns):
            try:
                r = self.predictor.predict(initial_state)
                if r.stop_reason == "non_finite":  # the compiled core overflows to inf, not OverflowError
                    raise FloatingPointError(f"the prediction diverged (non-finite state after {r.n_steps} steps)")
                a = RolloverAssessment.from_prediction(r)
            except (OverflowError, ZeroDivisionError, FloatingPointError, ValueError) as e:
                # a diverging or absurd prediction (e.g. an estimate far outside the model's
                # range) must not stop the warning path: count it and say "fault" on the bus
                self.prediction_failures += 1
                self.last_failure = f"{type(e).__name__}: {e}"
                status = WarningStatus.FAULT
            else:
                self.assessments.append(a)
                self.assessments_total += 1
                self.last_assessment = a
                self._pending.append((t_ns + self._latency_ns, a))
        ready = None
        while self._pending and self._pending[0][0] <= t_ns:
            ready = self._pending.popleft()[1]
        out = self.node.handle(t_ns, ready, status)
        self.frames.extend(out)
        self.frames_total += len(out)
        return out


def replay_assessments(assessments: Sequence[RolloverAssessment], times_ns: Iterable[int],
                       policy: WarningPolicy, node_config: WarningNodeConfig | None = None) -> list[can.Message]:
    """Re-run a node with another policy over stored assessments (each usable from its t0 +
    ``prediction_latency_s``), called at ``times_ns``: the frames it would have sent. Used for
    lead-time vs false-alarm curves without re-predicting."""
    node = WarningNode(policy, node_config)
    lat = int(round(node.config.prediction_latency_s * NS_PER_S))
    queue = sorted(assessments, key=lambda a: a.t0_ns)
    k = 0
    frames: list[can.Message] = []
    for t in times_ns:
        ready = None
        while k < len(queue) and queue[k].t0_ns + lat <= t:
            ready = queue[k]
            k += 1
        frames.extend(node.handle(int(t), ready, WarningStatus.VALID))
    return frames


__all__ = ["RolloverAssessment", "WarningChain", "WarningLevel", "WarningNode", "WarningNodeConfig",
           "WarningPolicy", "WarningStatus",
           "load_transfer_ratio", "load_warning_config", "predictive_ltr", "replay_assessments",
           "roll_relative_to_road", "warning_config_from_table"]
