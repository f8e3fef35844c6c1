"""The Foxglove view of a running system: the topics that let Foxglove open a recording (or a live
run) as a dashboard, beside the ``/est/`` layout of ``app.est_topics``.

=============================  ===========================  =====================================
topic                          schema                       from
=============================  ===========================  =====================================
``/decoded/<source>/<kind>``   ``vdps.Sample.v1``           every decoded input sample (the
                                                            signals the system received, SI)
``/gnss/fix``                  ``foxglove.LocationFix``     each ``gnss_pos`` input sample
``/est/fix``                   ``foxglove.LocationFix``     each ``Estimate``: the CG position
                                                            (ENU about the pipeline's origin ->
                                                            WGS-84), 1-sigma per ENU axis
``/est/tf``                    ``foxglove.FrameTransform``  each ``Estimate``: frame ``vehicle``
                                                            in frame ``enu``
``/est/pose``                  ``foxglove.PoseInFrame``     the same pose (3D panel path)
``/est/warning``               ``vdps.Sample.v1``           each VDPS_Warning frame the system
                                                            sent, decoded (level, status, time to
                                                            rollover, peak roll, LTR)
=============================  ===========================  =====================================

Orientation. The paper's C_g^v (eq 1, ``model.frames``) maps ENU coordinates to vehicle
coordinates; the vehicle's orientation in ENU is its transpose, C_v^g = Rz(psi) Ry(-theta) Rx(phi)
as active rotations (pitch nose-up positive is a negative rotation about the left-pointing y
axis; roll right-side-down positive a positive one about x), so the quaternion is
q = q_z(psi) q_y(-theta) q_x(phi) (:func:`vehicle_quaternion`; tested against eq 1's matrix).

Time stamps. Each Foxglove ``timestamp`` is the message's MCAP ``log_time``: ``epoch_ns + t_ns``
for a replay (the epoch of its input recording, as its output writer keeps it) or the wall clock
at the write for a live run (``epoch_ns=None``).
"""

from __future__ import annotations

import math
import time
from typing import Callable

from vdps_hil.bus.samples import Sample
from vdps_hil.estimation.estimates import Estimate
from vdps_hil.pipeline.outputs import CanFrame
from vdps_hil.record import schemas as S
from vdps_hil.record.payloads import sample_payload as _sample_payload

__all__ = ["FoxgloveView", "WARNING_TOPIC", "sample_payload", "vehicle_quaternion"]

WARNING_TOPIC = "/est/warning"


def vehicle_quaternion(phi_rad: float, theta_rad: float, psi_rad: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of the vehicle's orientation in ENU from the paper's absolute roll, pitch and
    yaw (module docstring): q = q_z(psi) q_y(-theta) q_x(phi)."""
    cx, sx = math.cos(0.5 * phi_rad), math.sin(0.5 * phi_rad)
    cy, sy = math.cos(-0.5 * theta_rad), math.sin(-0.5 * theta_rad)
    cz, sz = math.cos(0.5 * psi_rad), math.sin(0.5 * psi_rad)
    # q_z q_y = (-sz sy, cz sy, sz cy, cz cy) as (x, y, z, w); then times q_x = (sx, 0, 0, cx)
    ax, ay, az, aw = -sz * sy, cz * sy, sz * cy, cz * cy
    return (aw * sx + ax * cx, ay * cx + az * sx, az * cx - ay * sx, aw * cx - ax * sx)


def sample_payload(s: Sample) -> bytes:
    """The bytes ``RecordingWriter.write_sample`` writes for ``s`` (``json.dumps`` of
    ``Sample.to_json``, compact; non-finite values as null; ``record.payloads.sample_payload``)."""
    return _sample_payload(s)


class FoxgloveView:
    """Writes the Foxglove topics of the module docstring into a writer (``write_encoded`` and
    ``write_json`` of a ``RecordingWriter`` or of the replay's second-process forwarder).

    ``origin()``: the pipeline's ENU origin or None (no ``/est/fix`` until there is one);
    ``epoch_ns``: log-time epoch of a replay's output, None live. ``samples`` and ``outputs``
    take the system's inputs and outputs; both never raise on content (a document the writer
    refuses is counted in ``refused``)."""

    def __init__(self, origin: Callable[[], object] | None = None, *, epoch_ns: int | None = None):
        self.origin = origin or (lambda: None)
        self.epoch_ns = epoch_ns
        self._sample_topics: dict[tuple[str, str], tuple[str, dict]] = {}
        self._warning_decoder = None
        self.refused = 0

    def stamp(self, t_ns: int) -> int:
        """The log time (and Foxglove timestamp) of a message measured at ``t_ns``."""
        return self.epoch_ns + t_ns if self.epoch_ns is not None else time.time_ns()

    def tap(self, source, side, batch: int = 256):
        """The samples of ``source`` unchanged, each also written (in batches of ``batch``) to
        ``side.writer`` (read at each batch: a replay's output opens at its first raw record)."""
        held: list = []
        for s in source:
            held.append(s)
            if len(held) >= batch:
                if side.writer is not None:
                    self.samples(held, side.writer)
                held = []
            yield s
        if held and side.writer is not None:
            self.samples(held, side.writer)

    def summary(self):
        """A replay summary (``app.replay_summary``) that also writes these topics of each output."""
        from vdps_hil.app.replay_summary import ReplaySummary

        view = self

        class ViewedSummary(ReplaySummary):
            def outputs(self, outs, writer) -> None:
                super().outputs(outs, writer)
                if writer is not None:
                    view.outputs(outs, writer)

        return ViewedSummary()

    def samples(self, samples, writer) -> None:
        """``/decoded/<source>/<kind>`` and ``/gnss/fix`` of input samples; into a writer with
        ``write_encoded_run`` (a ``RecordingWriter``) one run per topic of the batch (the same
        messages per topic)."""
        run = getattr(writer, "write_encoded_run", None)
        if run is None:
            for s in samples:
                self._sample(s, writer)
            return
        runs: dict[str, tuple[dict, list, list, list]] = {}
        check, top = S.check_time_ns, S.MAX_TIME_NS
        for s in samples:
            how = self._topic(s)
            t = s.t_ns
            stamp = self.stamp(t)
            try:
                if not (type(t) is int and 0 <= t <= top and 0 <= stamp <= top):
                    check("t_ns", t)
                    if stamp:
                        check("wall_time_ns", stamp)
                payload = sample_payload(s)
            except (ValueError, TypeError, KeyError, OverflowError):
                self.refused += 1
                continue
            r = runs.get(how[0])
            if r is None:
                r = runs[how[0]] = (how[1], [], [], [])
            r[1].append(s.t_ns)
            r[2].append(payload)
            r[3].append(stamp)
            if s.kind == "gnss_pos":
                self._fix(s, stamp, writer)
        for topic, (md, t, p, w) in runs.items():
            try:
                run(topic, S.SAMPLE, t, p, w, md)
            except (ValueError, TypeError, KeyError, OverflowError):
                self.refused += len(p)

    def _topic(self, s: Sample) -> tuple[str, dict]:
        """(topic, channel metadata) of a sample's ``/decoded/`` channel."""
        key = (s.source, s.kind)
        how = self._sample_topics.get(key)
        if how is None:
            how = self._sample_topics[key] = (S.sample_topic(s.source, s.kind), {"source": s.source, "kind": s.kind})
        return how

    def _sample(self, s: Sample, writer) -> None:
        how = self._topic(s)
        stamp = self.stamp(s.t_ns)
        try:
            writer.write_encoded(how[0], S.SAMPLE, s.t_ns, sample_payload(s), wall_time_ns=stamp,
                                 channel_metadata=how[1])
        except (ValueError, TypeError, KeyError, OverflowError):
            self.refused += 1
            return
        if s.kind == "gnss_pos":
            self._fix(s, stamp, writer)

    def _fix(self, s: Sample, stamp: int, writer) -> None:
        try:
            doc = S.location_fix_doc(s, stamp_ns=stamp)
            if doc is not None:
                writer.write_json(S.GNSS_FIX_TOPIC, S.LOCATION_FIX, s.t_ns, doc, wall_time_ns=stamp)
        except (ValueError, TypeError, KeyError, OverflowError):
            self.refused += 1

    def outputs(self, outs, writer) -> None:
        """``/est/fix``, ``/est/tf``, ``/est/pose`` of estimates, ``/est/warning`` of sent frames."""
        for o in outs:
            try:
                if isinstance(o, Estimate):
                    self._estimate(o, writer)
                elif isinstance(o, CanFrame):
                    self._warning(o, writer)
            except (ValueError, TypeError, KeyError, OverflowError):
                self.refused += 1

    def _estimate(self, e: Estimate, writer) -> None:
        x = e.x
        if not all(math.isfinite(v) for v in x[:3] + x[6:9]):
            return
        stamp = self.stamp(e.t_ns)
        q = vehicle_quaternion(x[6], x[7], x[8])
        writer.write_json(S.EST_TF_TOPIC, S.FRAME_TRANSFORM, e.t_ns,
                          S.frame_transform_doc(stamp, S.ENU_FRAME, S.VEHICLE_FRAME, x[:3], q), wall_time_ns=stamp)
        writer.write_json(S.EST_POSE_TOPIC, S.POSE_IN_FRAME, e.t_ns,
                          S.pose_in_frame_doc(stamp, S.ENU_FRAME, x[:3], q), wall_time_ns=stamp)
        origin = self.origin()
        if origin is not None:
            lat, lon, h = origin.to_geodetic(x[:3])
            doc = S.geodetic_fix_doc(stamp, lat, lon, h, tuple(e.sigma[:3]))
            if doc is not None:
                writer.write_json(S.EST_FIX_TOPIC, S.LOCATION_FIX, e.t_ns, doc, wall_time_ns=stamp)

    def _warning(self, f: CanFrame, writer) -> None:
        if self._warning_decoder is None:
            from vdps_hil.codecs.can_decode import VdpsCanDecoder

            self._warning_decoder = VdpsCanDecoder(source="vdps")
        for s in self._warning_decoder.decode(f.t_ns, f.arbitration_id, f.data):
            if s.kind == "warning":
                stamp = self.stamp(f.t_ns)
                writer.write_encoded(WARNING_TOPIC, S.SAMPLE, f.t_ns, sample_payload(s), wall_time_ns=stamp,
                                     channel_metadata={"source": s.source, "kind": s.kind})
