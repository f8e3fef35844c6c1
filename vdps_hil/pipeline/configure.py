"""How a recording configures the Figure 2 node: the sensor set and the suspension averaging
from the first seconds of its decoded samples (``vdps replay``, ``vdps log --pipeline``,
``vdps diagnose``: one rule for all three).

``sample_stats(samples)`` takes the samples of the first ``PROBE_SECONDS`` (sample rate per kind,
the catalogue fields with a finite value per kind); ``system_config(rates, fields, vehicle, ...)``
turns them into the node's configuration: the sensor set named (``configs/sensorsets``: sensors,
noise, latencies, kind map, calibration nodes) or inferred from the fields
(``estimation.sensorsets.infer_sensor_set``), the suspension window averaging sized from the
measured rate with the sensor's sigma (``SystemConfig.for_profile``).

An inferred set without GNSS attitude (a single antenna, or none) runs the EKF with the real-car
rows (``EkfConfig.with_real_car_rows``: gyro and accelerometer bias states, the non-holonomic
constraint, the wheel-speed row and its scale state when the car has tachometers), as the named
real-car sets do. Without them nothing measures the heading: the eq 7 filter integrates the
gyro's bias into the yaw, and the body velocity it reports turns with it (the real RAV4 drive,
inferred: the heading drifted 5 deg from the course in 57 s of straight road, the lateral
velocity reached -1.1 m/s). The paper's Table 1 set (three antennas) keeps the eq 7 filter as
printed.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Iterator, Mapping

from vdps_hil.bus.samples import Sample
from vdps_hil.pipeline.node import SystemConfig, default_pipeline_config

__all__ = ["PROBE_SECONDS", "PROBE_MAX_SECONDS", "DEFAULT_SUSP_SIGMA_M", "ProbeWindow", "SystemConfigError",
           "sample_stats", "system_config"]

PROBE_SECONDS = 3.0
"""The sensor set and suspension rate are inferred from this much of the decoded data."""

PROBE_MAX_SECONDS = 30.0
"""The probe waits at most this long after the first sample for the first IMU sample
(:class:`ProbeWindow`)."""

_IMU_FIELDS = ("specific_force_mps2_x", "specific_force_mps2_y", "angular_rate_radps_z")

DEFAULT_SUSP_SIGMA_M = 0.001
"""Suspension deflection sigma (``vdps replay --susp-sigma``; Table 1: 1 mm)."""


class SystemConfigError(ValueError):
    """A sensor set or setting the node cannot run with (one line)."""


class ProbeWindow:
    """Where the probe ends: ``seconds`` after the first sample, or, when no IMU (a kind that has
    carried x/y specific force and yaw rate, finite) has come by then, ``seconds`` after it came,
    at most ``max_seconds`` after the first sample. A real drive may start its IMU stream after its
    GNSS (the rtklibexplorer drive: 3.4 s later), and a probe of its first seconds alone would
    find no IMU and refuse it. ``past(sample)``: True for the first sample beyond the window
    (it ends the window; :func:`sample_stats` and the live tap both use this rule)."""

    def __init__(self, seconds: float = PROBE_SECONDS, max_seconds: float = PROBE_MAX_SECONDS):
        self.span_ns = seconds * 1e9
        self.max_ns = max(max_seconds, seconds) * 1e9
        self.t0: int | None = None
        self.t_imu: int | None = None  # when one kind had carried all of _IMU_FIELDS (the ESC rule)
        self._seen: dict[str, set] = {}

    def past(self, s: Sample) -> bool:
        t = s.t_ns
        if self.t0 is None:
            self.t0 = t
        if self.t_imu is None:
            seen = self._seen.setdefault(s.kind, set())
            seen.update(n for n in _IMU_FIELDS if math.isfinite(s.fields.get(n, math.nan)))
            if len(seen) == len(_IMU_FIELDS):
                self.t_imu = t
        if t - self.t0 > self.max_ns:
            return True
        start = self.t0 if self.t_imu is None or self.t_imu - self.t0 <= self.span_ns else self.t_imu
        return t - start > self.span_ns and self.t_imu is not None


def sample_stats(samples: Iterator[Sample], seconds: float = PROBE_SECONDS
                 ) -> tuple[list[Sample], dict[str, float], dict[str, set]]:
    """Take the samples of the first ``seconds`` from the iterator ``samples`` (plus the first
    sample after them, which ends the window; longer when the IMU starts late,
    :class:`ProbeWindow`): (the samples taken, in order; sample rate [Hz] per kind; catalogue
    fields with a finite value per kind). Samples of one instant from one kind count once in the
    rate. The caller feeds the samples taken to the system after configuring it from the rest,
    so the recording is decoded once."""
    taken: list[Sample] = []
    first: dict[str, int] = {}
    last: dict[str, int] = {}
    count: dict[str, int] = {}
    fields: dict[str, set] = {}
    window = ProbeWindow(seconds)
    for s in samples:
        taken.append(s)
        if window.past(s):
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


def system_config(rates: Mapping[str, float], fields: Mapping[str, set], veh, susp_sigma_m: float = DEFAULT_SUSP_SIGMA_M,
                  paper_faithful=None, sensorset=None, **kw):
    """(SystemConfig, kind_map, sample nodes, sensor-set description) from the sample ``rates``
    and ``fields`` of a recording's first seconds (``sample_stats``; module docstring); ``kw``:
    further ``SystemConfig`` fields. Raises :class:`SystemConfigError` (one line)."""
    from vdps_hil.estimation.ekf_config import PaperFaithful
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
            ekf = replace(pc.ekf, sensors=sensors)
            if sensors.gnss != "multi_antenna":  # no heading measured: the real-car rows (module docstring)
                ekf = ekf.with_real_car_rows()
            pc = replace(pc, ekf=ekf)
            desc = {"source": "inferred from the recording", **sensors.__dict__}
    except SensorSetError as e:
        raise SystemConfigError(str(e)) from None
    if paper_faithful:
        names = set(paper_faithful)
        pf = PaperFaithful.all() if "all" in names else PaperFaithful(**{n: True for n in names})
        pc = replace(pc, ekf=replace(pc.ekf, paper_faithful=pf))
    if not (math.isfinite(susp_sigma_m) and susp_sigma_m > 0):
        raise SystemConfigError(f"suspension sigma must be positive, got {susp_sigma_m!r}")
    desc["kind_map"] = kind_map
    if "gnss_alt" in fields:  # altitude in a frame of its own: joined to the fixes (sensorsets.KindMap)
        desc["gnss_altitude"] = "joined from gnss_alt"
    cfg = SystemConfig.for_profile(rates.get("suspension", 1.0), susp_sigma_m, pipeline=pc, **kw)
    return cfg, kind_map, nodes, desc
