"""``vdps log --pipeline``'s consumer: :class:`PipelineTap`, the paper's Figure 2 node fed with
the decoded samples a live recording takes (run in a process of its own by
``app.tap_process``)."""

from __future__ import annotations

__all__ = ["PipelineTap"]


class PipelineTap:
    """``vdps log --pipeline``: feeds every decoded sample the recording took, in arrival order,
    to the paper's Figure 2 node (:class:`vdps_hil.pipeline.node.VdpsSystem`, the same node ``vdps
    replay`` runs), records its estimates on ``/est/state`` (10 Hz) and its VDPS_Warning frames
    on ``/est/can/<bus>`` in the layout of ``vdps replay``, and reports the latest warning for
    the status line. It never sends on the bus (the bench does).

    Configuration as ``vdps replay`` derives it (``app.replay.replay_config``): the samples of the
    first ``probe_s`` (``PROBE_SECONDS``, 3 s) of data are held (longer when the IMU starts
    late: ``pipeline.configure.ProbeWindow``), the sensor set is inferred from
    their fields and the suspension averaging sized from their rate (suspension sigma
    ``DEFAULT_SUSP_SIGMA_M``), then they go to the system at once -- so the first estimates and
    warnings come out after those seconds. ``record_order``: every sample fed is noted
    (``record.input_order``) and :meth:`finish` writes the input order with the settings the
    system was sized from, so ``vdps replay FILE --input-order recorded`` (same ``--vehicle``
    and ``--params``) reproduces the run's ``/est/`` messages. ``vdps log`` records no order when
    it rotates (``--rotate-mb/-s``): a replay of one file starts a fresh system where the live one
    had run through the files before it, so only the first file could be reproduced."""

    def __init__(self, model_vehicle, writer, start_params=None, *, record_order: bool = True,
                 params_file: str | None = None, probe_s: float | None = None, start_unsettled: tuple = ()):
        from vdps_hil.bus.samples import Sample
        from vdps_hil.codecs.can_decode import VdpsCanDecoder
        from vdps_hil.estimation.estimates import Estimate
        from vdps_hil.record.input_order import InputOrder
        from vdps_hil.app.replay import PROBE_SECONDS
        from vdps_hil.pipeline.configure import ProbeWindow
        from vdps_hil.pipeline.outputs import CanFrame

        self._sample_type, self._frame_type, self._est_type = Sample, CanFrame, Estimate
        self.model, self.start, self.params_file = model_vehicle, start_params, params_file
        self.start_unsettled = tuple(start_unsettled)  # the file's problems not settled: pipeline.node's rule
        self.writer = writer
        self.probe_s = PROBE_SECONDS if probe_s is None else probe_s
        self.system = None
        self.settings: dict | None = None  # what the system was sized from (recorded with the order)
        self.kind_map = None  # a KindMap once the system is configured, if it maps anything
        self.error: str | None = None  # the system could not be configured (no IMU): not running
        self.order = InputOrder() if record_order else None
        self.order_written = False
        self._pending: list = []
        self._window = ProbeWindow(self.probe_s)  # sample_stats' window (longer when the IMU starts late)
        self._fed_since_clear = 0
        self._decoder = VdpsCanDecoder(source="pipeline")
        self.samples = self.estimates = self.frames = 0
        self.last_warning: dict | None = None
        self.input_dropped = 0  # samples the session could not queue for us (we were behind)
        self.est_skipped = 0  # outputs not written: the disk reserve was reached
        self.recording_allowed = lambda: True

    def input_lost(self, n: int) -> None:
        """The session dropped ``n`` samples (this tap was behind): the run is no longer the
        recording's input order, so none is recorded."""
        self.input_dropped += n
        self.order = None

    def __call__(self, events) -> None:
        for ev in events:
            if not isinstance(ev, self._sample_type):
                continue
            if self.system is not None:
                self._feed(ev)
            elif self.error is None:
                self._pending.append(ev)
                if self._window.past(ev):  # sample_stats' end of the window
                    self._configure()

    def _configure(self) -> None:
        """Size the system from the held samples as ``replay_file`` does, then feed them."""
        from dataclasses import replace

        from vdps_hil.app.replay import DEFAULT_SUSP_SIGMA_M, ReplayError, replay_config, sample_stats
        from vdps_hil.estimation.sensorsets import KindMap
        from vdps_hil.pipeline.node import VdpsSystem

        pending, self._pending = self._pending, []
        _, rates, fields = sample_stats(iter(pending), self.probe_s)
        try:
            cfg, _, _, desc = replay_config(rates, fields, self.model, DEFAULT_SUSP_SIGMA_M, None,
                                            identify=True, predict=True)
        except ReplayError as e:
            self.error = str(e)
            return
        km = KindMap.of(desc)
        self.kind_map = km if km else None  # None: nothing to map (asked once, not per sample)
        if self.start is not None:
            cfg = replace(cfg, start_params=self.start, start_unsettled=self.start_unsettled)
        # predictions inline (prediction.offpath's wait rule): this tap runs in a process of its own
        # (app.tap_process), off the readers' path, and a daemon process cannot start a worker
        self.system = VdpsSystem(self.model, cfg)
        self.system.clear_input_log()
        self.settings = {"vehicle": self.model.name, "vehicle_sha256": self.model.source_sha256,
                         "start_params": None if self.start is None else self.start.as_dict(),
                         "params_file": self.params_file, "susp_sigma_m": DEFAULT_SUSP_SIGMA_M,
                         "probe_rates_hz": rates, "probe_fields": {k: sorted(v) for k, v in fields.items()}}
        for s in pending:
            self._feed(s)

    def _feed(self, s) -> None:
        if self.order is not None:
            self.order.note(s)
        self.samples += 1
        if self.kind_map is not None:  # as replay_file
            s = self.kind_map(s)
            if s is None:  # a sensor the set does not name
                return
        self._outputs(self.system.handle(s))
        self._fed_since_clear += 1
        if self._fed_since_clear >= 4096:  # a live run keeps the file, not a copy in memory
            self.system.clear_input_log()
            self._fed_since_clear = 0

    def _outputs(self, outs) -> None:
        from vdps_hil.app.est_topics import write_output

        if not self.recording_allowed():
            self.est_skipped += len(outs)
            return
        for out in outs:
            if isinstance(out, self._est_type):
                self.estimates += 1
                if self.estimates % 10 == 0:  # 10 Hz into the recording
                    write_output(out, self.writer)
            elif isinstance(out, self._frame_type):
                self.frames += 1
                write_output(out, self.writer)
                for s in self._decoder.decode(out.t_ns, out.arbitration_id, out.data):
                    if s.kind == "warning":
                        self.last_warning = dict(s.fields, t_s=out.t_ns / 1e9)

    def finish(self) -> None:
        """End of the run (before the writer closes): a system still waiting for its probe
        window is sized from what came, its last outputs are written (as a replay's end) and,
        with ``record_order``, the input order with the settings (metadata
        ``hil.input_order``)."""
        if self.system is None and self._pending and self.error is None:
            self._configure()
        if self.system is None:
            return
        self._outputs(self.system.finish())
        if self.order is not None:
            from vdps_hil.record.input_order import INPUT_ORDER_METADATA

            self.writer.add_metadata(INPUT_ORDER_METADATA, self.order.metadata(
                system=self.settings, prediction=self.system.status()["prediction"]))
            self.order_written = True

    def status_line(self) -> str:
        if self.system is None:
            if self.error is not None:
                return f"pipeline: not running ({self.error})"
            wait = ", no IMU sample yet" if self._pending and self._window.t_imu is None else ""
            return (f"pipeline: sizing from the first {self.probe_s:g} s of data ({len(self._pending)} samples held"
                    f"{wait})")
        w = self.last_warning
        if w is None:
            return f"pipeline: {self.samples} samples, {self.estimates} estimates, no warning frame yet"
        ttr = w.get("warning_time_to_rollover_s")
        st = int(w["warning_status"])
        words = {0: "valid", 1: "not valid: not converged", 2: "not valid: sensor missing", 3: "not valid: fault"}
        return (f"pipeline: {self.samples} samples, {self.estimates} estimates; warning level "
                f"{int(w['warning_level'])} ({words.get(st, f'status {st}')})"
                + (f", time to rollover {ttr:.2f} s" if ttr is not None and ttr == ttr and ttr != float("inf") else ""))

    def summary(self) -> dict:
        return {"samples": self.samples, "estimates": self.estimates, "warning_frames": self.frames,
                "last_warning": self.last_warning, "error": self.error,
                "input_dropped": self.input_dropped, "outputs_skipped_disk": self.est_skipped,
                "input_order_recorded": self.order_written}
