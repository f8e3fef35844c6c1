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

__all__ = ["PROBE_SECONDS", "DEFAULT_SUSP_SIGMA_M", "SystemConfigError", "sample_stats", "system_config"]

PROBE_SECONDS = 3.0
"""The sensor set and suspension rate are inferred from this much of the decoded data."""

DEFAULT_SUSP_SIGMA_M = 0.001
"""Suspension deflection sigma (``vdps replay --susp-sigma``; Table 1: 1 mm)."""


class SystemConfigError(ValueError):
    """A sensor set or setting the node cannot run with (one line)."""


def sample_stats(samples: Iterator[Sample], seconds: float = PROBE_SECONDS
                 ) -> tuple[list[Sample], dict[str, float], dict[str, set]]:
    """Take the samples of the first ``seconds`` from the iterator ``samples`` (plus the first
    sample after them, which ends the window): (the samples taken, in order; sample rate [Hz]
    per kind; catalogue fields with a finite value per kind). Samples of one instant from one
    kind count once in the rate. The caller feeds the samples taken to the system after
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
    cfg = SystemConfig.for_profile(rates.get("suspension", 1.0), susp_sigma_m, pipeline=pc, **kw)
    return cfg, kind_map, nodes, desc
