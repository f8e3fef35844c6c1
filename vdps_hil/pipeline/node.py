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
a fresh system and reproduces the outputs bit for bit (``pipeline.outputs.outputs_digest``).
The system reads only a *model* vehicle file (the truth file is refused) and never a
``/truth`` source (the pipeline ignores and counts them).

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

Suspension conditioning (``estimation.suspension``, its module docstring): window means of a
fast suspension sensor (``suspension_rate_hz``, ``suspension_stamp``) and the tire-compliance
correction (``tire_compliance``) before the EKF; the identifier's eq 14 forces get the
*measured* deflections.

Alpha-beta bandwidths: the system's default ``PipelineConfig`` uses 20 Hz for the body rates,
wheel speeds and suspension (the pipeline's own defaults are 5/5/2 Hz). The inertia problem
(eq 23) relates the angular accelerations to moments from H, Hd; at 2-5 Hz the derivatives lag
the 1 Hz excitation of the paper's scenario by tens of degrees and I_x came out 3x too high on
a zero-noise drive (+215 %; 20 Hz: +33 %).

Warning status sent with each frame: 1 "not converged" until the EKF is initialised and, when
the identifier started from the model file's priors (no ``start_params``, i.e. no ``--params``),
until the problems named in the warning policy's ``require_converged`` (``["cornering"]``) have
stayed converged ``converged_hold_s`` (1 s; ``configs/prediction/default.toml``) without a break (the
chain re-reads ``Identifier.converged_of`` those problems every ``convergence_period_s`` of filter time,
0.02 s, the frames' period; a period not read breaks the hold); 2 "sensor missing" when
the held inputs (steering, wheel torques) or a rate/wheel speed are missing, else 0; the node
itself sends 3 "fault" for a stale prediction. Started from ``start_params`` (``--params``), the rule
gates those of the policy's problems that the start did not settle (``SystemConfig.start_unsettled``:
a parameter file's problems not "converged" when saved, or every problem when the file does not
say; ``identification.persistence.unsettled_problems``), so a file from a drive that never
identified the cornering stiffnesses waits for them like the priors, and one that did is valid at
once. ``SystemConfig.require_converged`` set to a tuple overrides that rule (``()``: never gate). Fault tolerance: 2 also while the IMU is missing or
within ``ImuChecks.settle_s`` of an IMU fault, 3 while the aiding innovations say the estimate is
inconsistent (``estimation.aiding_monitor.health``), counted per reason in
``counters["unhealthy"]``; these two outrank 1 "not converged" (a disconnected IMU shows as 2
also while the identification is still converging); the identifier is not fed on the estimates of an IMU fault.

The predictor's parameters (``predict_from``): per parameter the last value the identifier called
"identified", else the start value (``identification.trusted``, re-read at the predictor's cadence).

Predictions off the sample path (``prediction.offpath``): the chain's prediction at t0 runs on
a snapshot (parameters, initial state) in ``prediction_worker`` ("inline" by default; "process"
live) and is used from t0 + ``prediction_latency_s``; ``prediction_deadline`` "wait" (replay:
no miss by construction) or "drop" (live, ``LIVE_PREDICTIONS``: a late one is dropped, counted
in ``status()["prediction"]``, and the frames say 3 "fault" until the next is used); a replay
given the live run's ``prediction_drops_t0_ns`` reproduces it bit for bit. ``finish`` stops
the worker.

File replay (``vdps replay``, the batch tasks) is the application around this node:
``vdps_hil.app.replay.replay_file``.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Iterable

from vdps_hil.bus.samples import Sample
from vdps_hil.estimation.aiding_monitor import health
from vdps_hil.estimation.estimates import Estimate
from vdps_hil.estimation.pipeline import EstimatorPipeline
from vdps_hil.estimation.suspension import SuspensionConditioner
from vdps_hil.identification.feeder import IdentFeeder
from vdps_hil.identification.identifier import Identifier
from vdps_hil.identification.trusted import TrustedParams
from vdps_hil.model.params import IdentifiedParams, Vehicle
from vdps_hil.pipeline.outputs import CanFrame, IdentReport, PredictionReport
from vdps_hil.pipeline.system_config import (LIVE_PREDICTIONS, SystemConfig,  # noqa: F401 (re-exported)
                                             default_pipeline_config)

__all__ = ["LIVE_PREDICTIONS", "SystemConfig", "VdpsSystem", "default_pipeline_config"]

# --------------------------------------------------------------------------------- the node
WARNING_HISTORY = 100
"""Sent warning frames and assessments the system's warning chain keeps (the most recent; 2 s of
frames at 50 Hz): its outputs carry every frame and prediction as they happen, so the chain
keeps only counts and a recent window and memory does not grow with the drive."""


class VdpsSystem:
    """Figure 2 as one pure node (module docstring). ``runner``: the prediction worker
    (``prediction.offpath.PredictionRunner``; None: one of ``config.prediction_worker``)."""

    def __init__(self, model_vehicle: Vehicle, config: SystemConfig | None = None, origin=None, runner=None):
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
        self._conv_ns = int(round(cfg.convergence_period_s * 1e9))
        self._next_conv: int | None = None
        self._conv_ok, self._conv_since, self.converged_hold_ns = False, None, 0  # validity hold (docstring)
        self.feeder = IdentFeeder(model_vehicle, cfg.feeder) if cfg.identify else None
        self.identifier = Identifier(model_vehicle, cfg.ident, start=cfg.start_params) if cfg.identify else None
        self._chain = None
        self._chain_params = None
        self._trusted = None
        self.require_converged: tuple[str, ...] = ()
        """Problems whose convergence makes a warning valid (module docstring); () = no gate."""
        if cfg.predict:
            from vdps_hil.prediction.config import load_predictor_config
            from vdps_hil.prediction.predictor import Predictor, predictor_effects
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
            from vdps_hil.prediction.offpath import PredictionRunner

            pred = Predictor(model_vehicle.with_params(**params.as_dict()), pcfg, peff)
            runner = runner if runner is not None else PredictionRunner(pred, cfg.prediction_worker)
            self._chain = WarningChain(pred, pol, node, keep=WARNING_HISTORY, runner=runner,
                                       deadline=cfg.prediction_deadline, drop_t0_ns=cfg.prediction_drops_t0_ns)
            self._chain_params = params
            if self.identifier is not None and cfg.predict_from == "identified":  # what the identifier vouches for
                self._trusted = TrustedParams(self.identifier, params, 1.0 / pcfg.cadence_hz)
            rc = cfg.require_converged
            if rc is None:  # the policy's rule: gate a chain started from the priors, or the start's unsettled
                rc = tuple(n for n in getattr(pol, "require_converged", ())
                           if cfg.start_params is None or n in cfg.start_unsettled)
            self.require_converged = tuple(rc)
            self.converged_hold_ns = int(round(getattr(pol, "converged_hold_s", 0.0) * 1e9))
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
                         "status": {"valid": 0, "not_converged": 0, "sensor_missing": 0, "fault": 0},
                         "unhealthy": {"imu_missing": 0, "imu_fault": 0, "inconsistent": 0}}

    # ------------------------------------------------------------------ public
    def handle(self, sample: Sample) -> list:
        """Consume one bus sample; returns the outputs it caused (module docstring)."""
        if self.config.keep_input_log:
            self._log.append(sample)
        elif not self.counters["samples"] & 4095:
            self.pipeline.clear_input_log()  # the estimator's own log, every 4096 samples
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
                    if self.feeder is not None:  # the sample times (the strut-force rows' gate)
                        self.feeder.observe(sample)
                    for s in ready:
                        self._step(s, out)
                    return out
        if self.feeder is not None:
            self.feeder.observe(sample)
        self._after(self.pipeline.handle(sample), sample.t_ns, out)  # _step, inline: once per sample
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
        self.close()
        return out

    def ready(self, timeout_s: float | None = None) -> bool:
        """Wait, at set-up, until the prediction worker has started (``PredictionRunner.ready``)."""
        return self._chain is None or self._chain.runner.ready(timeout_s)

    def close(self) -> None:
        """Stop the prediction worker (``finish`` does; predictions still pending are never used)."""
        if self._chain is not None:
            self._chain.close()

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
        self.pipeline.clear_input_log()

    @property
    def last_estimate(self) -> Estimate | None:
        return self._last_estimate

    @property
    def params(self) -> IdentifiedParams:
        """The current identified parameters (the priors or ``start_params`` without identifier)."""
        return self._params()

    @property
    def predictor(self):
        """The warning chain's predictor (``prediction.predictor.Predictor``; None with
        ``predict`` off)."""
        return None if self._chain is None else self._chain.predictor

    def _params(self) -> IdentifiedParams:
        if self.identifier is not None:
            return self.identifier.params
        return self.config.start_params or self.vehicle.params

    def ident_report(self, t_ns: int) -> IdentReport | None:
        idf = self.identifier
        if idf is None:
            return None
        ps = idf.problem_status
        return IdentReport(int(t_ns), idf.params.as_dict(), idf.sigmas, idf.identifiability,
                           {n: st.converged for n, st in ps.items()}, {n: c.updates for n, c in idf.counters.items()},
                           {p.name: p.status for st in ps.values() for p in st.params})

    def status(self) -> dict:
        d = {"counters": dict(self.counters), "pipeline": self.pipeline.counters,
             "rejected": self.pipeline.rejected()}
        if self._susp is not None:
            d["suspension_windows"] = {"windows": self._susp.windows, "samples": self._susp.merged}
        if self.feeder is not None:
            d["feeder"] = dict(self.feeder.counters)
        if self.identifier is not None:
            d["identification"] = self.identifier.status()
        ch = self._chain
        if ch is not None:
            d["prediction"] = {"worker": ch.runner.worker, "deadline": ch.deadline,
                               "latency_s": ch.node.config.prediction_latency_s, "started": ch.started,
                               "used": ch.assessments_total, "dropped": ch.drops, "failed": ch.prediction_failures,
                               "dropped_t0_ns": list(ch.dropped_t0_ns), "params_from": self.config.predict_from,
                               "param_sources": {} if self._trusted is None else dict(self._trusted.source),
                               "require_converged": list(self.require_converged)}
        return d

    @property
    def prediction_drops_t0_ns(self) -> tuple[int, ...]:
        """The t0 of every prediction dropped at its deadline so far (``SystemConfig.
        prediction_drops_t0_ns`` of a replay that reproduces this run)."""
        return () if self._chain is None else tuple(self._chain.dropped_t0_ns)

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
        why = health(p.imu_monitor, p.aiding_monitor, t)  # fault tolerance (module docstring)
        if why is not None:
            self.counters["unhealthy"][why] += 1
        if self.identifier is not None:
            imu_ok = why is None or not why.startswith("imu")  # no RLS on an IMU outage's estimates
            if imu_ok and (self._next_ident is None or t >= self._next_ident):
                self._next_ident = t - t % self._ident_ns + self._ident_ns
                inp = self.feeder.inputs(est, filt)
                if inp is not None:
                    self.identifier.update(inp)
                    self.counters["ident_updates"] += 1
            if self._next_report is None or t >= self._next_report:
                self._next_report = t - t % self._report_ns + self._report_ns
                out.append(self.ident_report(t))
        self._chain_tick(t, (est, filt_eff), out, why)

    def _converged(self, t_ns: int) -> bool:
        """The identifier's convergence as the chain sees it, held ``converged_hold_s`` and re-read
        at the first estimate of each ``convergence_period_s`` of filter time (module docstring)."""
        if self._next_conv is None or t_ns >= self._next_conv:
            kept = self._next_conv is not None and t_ns < self._next_conv + self._conv_ns  # no period unread
            self._next_conv = t_ns - t_ns % self._conv_ns + self._conv_ns
            view = self.identifier.converged_of(self.require_converged)
            ok = all(view.get(n, False) for n in self.require_converged)
            self._conv_since = (self._conv_since if kept and self._conv_since is not None else t_ns) if ok else None
            self._conv_ok = ok and t_ns - self._conv_since >= self.converged_hold_ns
        return self._conv_ok

    def _chain_tick(self, t_ns: int, ef, out: list, why: str | None = None) -> None:
        chain = self._chain
        if chain is None or (ef is None and self.pipeline.ekf.initialized):
            return  # between estimate instants (before the imports: this runs per sample)
        from vdps_hil.prediction.initial_state import PredictorInitialState
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
                if not self._converged(t_ns):
                    status = WarningStatus.NOT_CONVERGED
            if status in (WarningStatus.VALID, WarningStatus.NOT_CONVERGED) and why is not None:
                # a missing IMU or an inconsistent estimate outranks "not converged"
                status = WarningStatus.SENSOR_MISSING if why.startswith("imu") else WarningStatus.FAULT
        params = self._params() if self._trusted is None else self._trusted.at(t_ns)
        if init is not None and params is not self._chain_params:
            chain.set_params(params.as_dict())
            self._chain_params = params
        n_before = chain.assessments_total
        frames = chain.handle(t_ns, init, status)
        self.counters["status"][chain.status.key] += 1
        if chain.assessments_total > n_before:
            a = chain.last_assessment
            self.counters["predictions"] += 1
            out.append(PredictionReport(a.t0_ns, a.time_to_point_of_no_return_s, a.time_to_tip_up_s, a.peak_ltr,
                                        a.peak_roll_rad, a.horizon_s, a.stop_reason))
        for m in frames:
            self.counters["frames"] += 1
            out.append(CanFrame(int(t_ns), self.config.warning_bus, int(m.arbitration_id), bytes(m.data)))

