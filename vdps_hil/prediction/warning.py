"""Rollover warning: rollover measures of a prediction, the warning policy, and the pure node that
sends ``VDPS_Warning`` on CAN (paper section 7.3 "the dynamic prediction system can predict the
rollover event"; the message layout is ``dbc/vdps.dbc`` / :mod:`vdps_hil.codecs.can_dbc`).

Rollover measures of one prediction (definitions of :mod:`vdps_hil.model.rollover`, applied to the
predicted trajectory; never redefined here; computed in :mod:`vdps_hil.prediction.assessment`)
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

The node (``WarningNode.handle(t_ns, assessment_or_prediction, status) -> [Frame]``)
------------------------------------------------------------------------------------
Pure (time only from ``t_ns``): sends VDPS_Warning every ``period_s`` (50 Hz) and at once when the
level changes; fields: ``warning_level``, ``warning_time_to_rollover_s`` (TTR, None when no
rollover is predicted), ``warning_peak_roll_rad`` (the predicted road-relative roll of largest
magnitude, signed), ``warning_ltr`` (PLTR, signed), ``warning_status`` (0 valid, 1 not converged,
2 sensor missing, 3 fault), rolling counter and CRC-8 via :class:`VdpsCanEncoder`, as
``codecs.can_encode.Frame`` (python-can's attribute names, ``to_message()``). Status: the
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
below ``converged_rel_sigma``) and has stayed converged ``converged_hold_s`` of filter time
without a break; started from identified parameters, frames are valid at once. From the
sedan-model priors (C_alpha front x1.5, rear x0.6: an oversteering model) the predictor foresaw
rollovers in the paper's sine steering before the cornering problem converged.

The hold: in the first seconds of a drive the cornering problem's sigma/|x| crosses the 10 %
threshold and back (the estimate still moving), so its status flickers; one such flicker on a
held-out drive (``paper-left-turn`` seed 34, 2026-12-06) made 40 ms of frames valid with the
front stiffness 13.6 % high and sent a false alarm (level 2). On the tuning drives
(:data:`TUNING_SEEDS`, hold 0) the converged runs that fell back lasted 0 to 0.39 s, all before
1.8 s; the hold is twice the longest, rounded up to a quarter second: 1.0 s.

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
from typing import TYPE_CHECKING, Iterable, Mapping, MutableSequence, Sequence

from vdps_hil.codecs.can_dbc import WARNING
from vdps_hil.codecs.can_decode import VdpsCanDecoder
from vdps_hil.codecs.can_encode import VdpsCanEncoder
from vdps_hil.units import NS_PER_S

from .config import DEFAULT_CONFIG_PATH, PredictionConfigError, load_prediction_document
from .initial_state import PredictorInitialState
from .assessment import RolloverAssessment, load_transfer_ratio, predictive_ltr, roll_relative_to_road
from .offpath import DEADLINES, PredictionRunner
from .predictor import Cadence, Predictor
from .result import PredictionResult

if TYPE_CHECKING:
    from vdps_hil.codecs.can_encode import Frame


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

    @property
    def key(self) -> str:
        """The name counters and JSON use: "valid", "not_converged", "sensor_missing", "fault"."""
        return self.name.lower()


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
    converged_hold_s: float = 1.0
    """Validity: how long [s] of filter time those problems must have stayed converged, without a
    break, before a frame is valid (module docstring, "Validity")."""

    def __post_init__(self):
        for n in ("reaction_time_s", "margin_s", "imminent_time_s", "caution_ltr", "hold_s", "converged_hold_s"):
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


TUNING_SEEDS = tuple(range(200, 210))
"""The drives ``converged_hold_s`` was chosen on (module docstring, "Validity"):
``paper-left-turn``, profile table1-susp1k, these seeds. Declared here once; no study or test uses
them (``experiments.seeds``)."""

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
    """Pure node: ``handle(t_ns, prediction, status) -> list[Frame]`` (module docstring).

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
               status: int = WarningStatus.VALID) -> list[Frame]:
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
        msg = self._enc.warning_frame(int(self._level), ttr, roll, ltr, int(st), t_ns=t_ns)
        self._last_sent_ns = t_ns
        self.frames_sent += 1
        return [msg]


# ---------------------------------------------------------------------------------------------
# predictor + cadence + node
# ---------------------------------------------------------------------------------------------
class WarningChain:
    """The warning path as one pure object: ``handle(t_ns, initial_state, status)`` starts a
    prediction at the configured cadence (held inputs) and feeds the node; a prediction started
    at t0 is used from t0 + ``prediction_latency_s`` on (its compute time on the target), never
    earlier. ``initial_state`` None: no estimate now (status should then say why).

    Off the sample path (:mod:`vdps_hil.prediction.offpath`): ``runner`` (a
    :class:`~vdps_hil.prediction.offpath.PredictionRunner`; None: inline) computes the job;
    ``deadline`` "wait" (replay: no miss by construction) or "drop" (live: a job not done at
    its deadline is dropped, counted in ``drops`` / ``dropped_t0_ns``, and frames carry status 3
    "fault" until the next prediction is used); ``drop_t0_ns``: the t0s a live run dropped,
    dropped again here (a replay reproducing it). ``params``: the identified parameters the next
    jobs use (:meth:`set_params`; None: the predictor's own).

    Storage: ``frames`` (the sent frames) and ``assessments`` (one per prediction used, t0
    inside) keep the most recent ``keep`` of each (``keep`` None: all of them, for a study of one
    drive that evaluates the frames afterwards, e.g.
    ``vdps_hil.experiments.scoring.evaluate_warning_frames``); a
    long-running system passes a bound so memory does not grow with the drive (50 frames per
    second otherwise). Counts over the whole run: ``frames_total``, ``assessments_total``,
    ``started``, ``drops``, ``prediction_failures``; the latest assessment: ``last_assessment``."""

    def __init__(self, predictor: Predictor, policy: WarningPolicy | None = None,
                 node_config: WarningNodeConfig | None = None, keep: int | None = None, *,
                 runner=None, deadline: str = "wait", drop_t0_ns: Iterable[int] = ()):
        if keep is not None and (isinstance(keep, bool) or not isinstance(keep, int) or keep < 0):
            raise ValueError(f"keep must be None or an integer >= 0, got {keep!r}")
        if deadline not in DEADLINES:
            raise ValueError(f"deadline must be one of {', '.join(DEADLINES)}, got {deadline!r}")
        self.runner = runner if runner is not None else PredictionRunner(predictor)
        self.deadline = deadline
        self._drop_set = frozenset(int(t) for t in drop_t0_ns)
        self.params: Mapping[str, float] | None = None
        self.node = WarningNode(policy, node_config)
        self.cadence = Cadence(predictor.config.cadence_hz)
        self._latency_ns = int(round(self.node.config.prediction_latency_s * NS_PER_S))
        self._pending: deque = deque()  # (deadline_ns, t0_ns, future or None: dropped as recorded)
        self._missed = False
        self.status = WarningStatus.NOT_CONVERGED
        """The status of the last ``handle`` after the chain's own rule (a drop or a failure:
        "fault"); the node may still send "fault" for an old prediction."""
        self.keep = keep
        self.frames: MutableSequence[Frame] = [] if keep is None else deque(maxlen=keep)
        self.assessments: MutableSequence[RolloverAssessment] = [] if keep is None else deque(maxlen=keep)
        self.frames_total = 0
        self.assessments_total = 0
        self.started = 0
        self.drops = 0
        self.dropped_t0_ns: list[int] = []
        self.last_assessment: RolloverAssessment | None = None
        self.prediction_failures = 0
        self.last_failure: str | None = None

    @property
    def predictor(self) -> Predictor:
        """The predictor of the latest parameters."""
        return self.runner.predictor

    def set_params(self, params: Mapping[str, float] | None) -> None:
        self.params = None if params is None else dict(params)

    def handle(self, t_ns: int, initial_state: PredictorInitialState | None,
               status: int = WarningStatus.VALID) -> list[Frame]:
        t_ns = int(t_ns)
        if initial_state is not None and self.cadence.due(t_ns):
            self.started += 1
            fut = None if t_ns in self._drop_set else self.runner.submit(self.params, initial_state)
            self._pending.append((t_ns + self._latency_ns, t_ns, fut))
        ready, failed = self._collect(t_ns)
        if status == WarningStatus.VALID and (failed or self._missed):
            status = WarningStatus.FAULT
        self.status = WarningStatus(int(status))
        out = self.node.handle(t_ns, ready, status)
        self.frames.extend(out)
        self.frames_total += len(out)
        return out

    def _collect(self, t_ns: int) -> tuple[RolloverAssessment | None, bool]:
        """The jobs whose deadline has come: used, dropped (``deadline`` "drop" and not done, or
        dropped as recorded) or failed; (the newest assessment used, whether a job failed)."""
        ready, failed = None, False
        while self._pending and self._pending[0][0] <= t_ns:
            _, t0, fut = self._pending.popleft()
            if fut is None or (self.deadline == "drop" and not fut.done()):
                if fut is not None:
                    fut.cancel()
                self.drops += 1
                self.dropped_t0_ns.append(t0)
                self._missed = True
                continue
            try:
                a, err = fut.result()
            except Exception as e:  # the worker itself failed (e.g. its process died): a counted failure
                a, err = None, f"prediction worker: {type(e).__name__}: {e}"
            if a is None:
                self.prediction_failures += 1
                self.last_failure = err
                failed = True
                continue
            self.assessments.append(a)
            self.assessments_total += 1
            self.last_assessment = ready = a
            self._missed = False
        return ready, failed

    def close(self) -> None:
        """Stop the worker; jobs still pending are never used."""
        self.runner.close()


def replay_assessments(assessments: Sequence[RolloverAssessment], times_ns: Iterable[int],
                       policy: WarningPolicy, node_config: WarningNodeConfig | None = None) -> list[Frame]:
    """Re-run a node with another policy over stored assessments (each usable from its t0 +
    ``prediction_latency_s``), called at ``times_ns``: the frames it would have sent. Used for
    lead-time vs false-alarm curves without re-predicting."""
    node = WarningNode(policy, node_config)
    lat = int(round(node.config.prediction_latency_s * NS_PER_S))
    queue = sorted(assessments, key=lambda a: a.t0_ns)
    k = 0
    frames: list[Frame] = []
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
