"""The summary of a replay (the ``--json`` document of ``vdps replay``): counted as the system's
outputs pass (estimates, innovations per kind with their mean NIS per degree of freedom,
predictions, sent frames), each output also written to the output recording
(``app.est_topics.write_output``); ``document`` adds the samples read, what the decoders and
the pipeline rejected, observability (per window and computed), identification and prediction."""

from __future__ import annotations

import math
from typing import Mapping

import numpy as np

from vdps_hil.app.est_topics import write_output
from vdps_hil.estimation.estimates import Estimate, Innovation
from vdps_hil.model.params import Vehicle
from vdps_hil.pipeline.node import VdpsSystem
from vdps_hil.pipeline.outputs import CanFrame, PredictionReport

__all__ = ["ReplaySummary"]


class ReplaySummary:
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
        self.frames = {"sent": 0, "max_level": 0, "by_status": [0, 0, 0, 0], "max_level_valid": None,
                       "first_valid_ns": None}

    def take_counts(self, counts: Mapping) -> None:
        """The samples the replay fed (``app.replay_io.SampleCounter``)."""
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
                c = self.innov.setdefault(o.kind, [0, 0, 0.0, 0, {}])
                c[0] += 1
                c[4][o.status] = c[4].get(o.status, 0) + 1
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
                f = self.frames  # VDPS_Warning: level in bits 12-13, status in bits 14-15 (dbc/vdps.dbc)
                level, status = (o.data[1] >> 4) & 0x3, (o.data[1] >> 6) & 0x3
                f["sent"] += 1
                f["max_level"] = max(f["max_level"], level)
                f["by_status"][status] += 1
                if status == 0:
                    f["max_level_valid"] = max(f["max_level_valid"] or 0, level)
                    if f["first_valid_ns"] is None:
                        f["first_valid_ns"] = o.t_ns
            if writer is not None:
                write_output(o, writer)

    def document(self, system: VdpsSystem, side, veh: Vehicle) -> dict:
        """The ``--json`` document; ``side``: the replay's recording side (``app.replay_io``)."""
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
        sys_status = system.status()
        obs = [{"t_start_s": a / 1e9, "t_end_s": b / 1e9, "rank": r.rank, "n_states": r.n_states,
                "unobservable": list(r.unobservable)} for a, b, r in system.pipeline.observability_reports]
        now = system.pipeline.observability_now()
        reader_c = side.counters["reader"]
        doc = {
            "duration_s": dur,
            "messages_read": {"raw_records": reader_c["raw_records"], "samples": sum(self.samples.values()),
                              "per_source_kind": dict(sorted(self.samples.items()))},
            "estimates_summary": es,
            # per status too: a kind the configuration switches off (rtklib-car's GNSS velocity)
            # counts its measurements as "disabled", not as refused
            "innovations": {k: {"updates": c[0], "accepted": c[1], "by_status": dict(sorted(c[4].items())),
                                "mean_nis_per_dof": (c[2] / c[3]) if c[3] else None}
                            for k, c in sorted(self.innov.items())},
            "rejected": rejected,
            "observability": {"windows": obs, "in_progress": None if now is None else
                              {"rank": now.rank, "n_states": now.n_states, "unobservable": list(now.unobservable)}},
            "decode": {k: v for k, v in side.counters.items()},
            "decoding": dict(side.decoding),
            "system": sys_status["counters"],
        }
        # computed observability (issue 11): structural rank of the sensor set, each window's null
        # space explained, and each identification problem's information with its cause
        from vdps_hil.identification.observability_report import observability_report
        try:
            doc["observability"].update(observability_report(system.pipeline, system.identifier).to_json())
        except (ValueError, np.linalg.LinAlgError) as e:  # a degenerate window must not lose the run
            doc["observability"]["report_error"] = f"{e.__class__.__name__}: {e}"
        if system.identifier is not None:
            st = system.identifier.status()
            st["prior"] = veh.params.as_dict()
            doc["identification"] = st
        if system.config.predict:
            from vdps_hil.prediction.warning import WarningStatus

            f = self.frames
            first = None if f["first_valid_ns"] is None or self.t_first is None else (f["first_valid_ns"] - self.t_first) / 1e9
            doc["prediction"] = dict(
                self.pred, frames_sent=f["sent"], max_level=f["max_level"], max_level_valid=f["max_level_valid"],
                frames_by_status={st.key: n for st, n in zip(WarningStatus, f["by_status"])},
                first_valid_s=first, require_converged=list(system.require_converged),
                converged_hold_s=system.converged_hold_ns / 1e9,
                param_sources=sys_status.get("prediction", {}).get("param_sources", {}))
        return doc
