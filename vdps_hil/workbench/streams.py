"""A drive's samples: decoded from the recording's ``/raw/`` topics, collected per kind as packed
arrays, resampled onto uniform grids and smoothed there.

Smoothing (offline, zero phase): a Butterworth low-pass (:class:`Smoother`, order 4) run forward
and backward (``scipy.signal.filtfilt``) on the stream's own uniform grid (median step,
:func:`uniform`); derivatives are central differences of the smoothed signal (:func:`smoothed`),
none for a stream slower than the caller's minimum rate. The values are then interpolated
linearly onto the table's grid (:func:`on_grid`, NaN outside the stream's span).
"""

from __future__ import annotations

import math
import os
from array import array
from typing import Iterable, Iterator, Mapping, Sequence

import numpy as np
from scipy.signal import butter, filtfilt

from vdps_hil.bus.samples import Sample, axis_fields, wheel_fields
from vdps_hil.units import GRAVITY_MPS2

__all__ = ["DatasetError", "iter_raw", "decode_raw", "Streams", "stream", "Smoother", "uniform", "on_grid", "smoothed",
           "smoothed_or_substituted", "ESC_SUBSTITUTES",
           "STREAM_FIELDS", "SPECIFIC_FORCE_FIELDS", "ANGULAR_RATE_FIELDS", "WHEEL_SPEED_FIELDS", "WHEEL_TORQUE_FIELDS",
           "SUSPENSION_FIELDS", "GNSS_POS_FIELDS", "GNSS_ATT_FIELDS", "GNSS_VEL_FIELDS"]

SPECIFIC_FORCE_FIELDS = axis_fields("specific_force_mps2")
ANGULAR_RATE_FIELDS = axis_fields("angular_rate_radps")
WHEEL_SPEED_FIELDS = wheel_fields("wheel_speed_radps")
WHEEL_TORQUE_FIELDS = wheel_fields("wheel_torque_nm")
SUSPENSION_FIELDS = wheel_fields("susp_deflection_m")
GNSS_POS_FIELDS = ("gnss_lat_deg", "gnss_lon_deg", "gnss_alt_m", "gnss_geoid_sep_m", "gnss_pos_sigma_h_m",
                   "gnss_pos_sigma_v_m", "gnss_fix_quality")
GNSS_ATT_FIELDS = ("gnss_roll_rad", "gnss_pitch_rad", "gnss_yaw_rad", "gnss_roll_sigma_rad", "gnss_pitch_sigma_rad",
                   "gnss_yaw_sigma_rad")
GNSS_VEL_FIELDS = ("gnss_speed_mps", "gnss_course_rad")
STREAM_FIELDS = {"imu": tuple(SPECIFIC_FORCE_FIELDS) + tuple(ANGULAR_RATE_FIELDS), "wheel_speed": tuple(WHEEL_SPEED_FIELDS),
                 "suspension": tuple(SUSPENSION_FIELDS), "steer": ("steer_wheel_angle_rad",),
                 "wheel_torque": tuple(WHEEL_TORQUE_FIELDS), "gnss_pos": GNSS_POS_FIELDS, "gnss_att": GNSS_ATT_FIELDS,
                 "gnss_vel": GNSS_VEL_FIELDS}
"""The sample kinds a drive table uses and their fields (:class:`Streams`' default)."""


class DatasetError(ValueError):
    """A recording the workbench cannot use (one-line message)."""


# ----------------------------------------------------------------------------------- decoding
def iter_raw(path: str | os.PathLike, *, dbc=None, signalmap=None) -> Iterator[Sample]:
    """The decoded ``/raw/`` samples of a recording in t_ns order, one at a time (nothing else
    is read, nothing is held: memory does not grow with the drive's length)."""
    from vdps_hil.record.decode import DecodeError, decode_recording

    try:
        yield from decode_recording(path, dbc=dbc, signalmap=signalmap)
    except DecodeError as e:
        raise DatasetError(str(e)) from None


def decode_raw(path: str | os.PathLike, *, dbc=None, signalmap=None) -> list[Sample]:
    """The decoded ``/raw/`` samples of a recording in t_ns order, as a list (about 2 MiB per
    second of drive: the workbench itself streams with :func:`iter_raw`)."""
    return list(iter_raw(path, dbc=dbc, signalmap=signalmap))


# ----------------------------------------------------------------------------------- streams
SINGLE_PRECISION_KINDS = frozenset({"imu", "wheel_speed", "suspension", "wheel_torque", "steer"})
"""Kinds whose values are held in single precision (24 significant bits, 6e-8 relative): finer
than every such sensor's resolution (Xsens MTData2 sends IEEE singles; the CAN signals are
integers times a scale of 1e-4 or coarser), and half the memory of the 1 kHz streams. GNSS
keeps double precision (a latitude in single precision is 0.4 m coarse)."""


class Streams:
    """The valid samples of each kind the table uses, collected in one pass as packed arrays
    (t_ns, and the kind's fields with NaN where a sample lacks one): 8 bytes a time stamp,
    4 or 8 a value (:data:`SINGLE_PRECISION_KINDS`), so a drive is never held as Sample objects
    (about 6 MiB per minute of a Table 1 drive with 1 kHz suspension). ``count``: every sample
    seen."""

    def __init__(self, kinds: Mapping[str, Sequence[str]] | None = None):
        self.names = {k: tuple(v) for k, v in (kinds or STREAM_FIELDS).items()}
        self._t = {k: array("q") for k in self.names}
        self._v = {k: array("f" if k in SINGLE_PRECISION_KINDS else "d") for k in self.names}
        self.count = 0

    def add(self, s: Sample) -> None:
        self.count += 1
        names = self.names.get(s.kind)
        if names is None or not s.valid:
            return
        f = s.fields
        self._t[s.kind].append(s.t_ns)
        self._v[s.kind].extend([f.get(n, math.nan) for n in names])

    def tap(self, samples: Iterable[Sample]) -> Iterator[Sample]:
        """Pass the samples through, collecting them on the way."""
        for s in samples:
            self.add(s)
            yield s

    def get(self, kind: str, names: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
        """(t_ns (n,), values (n, k)) of ``names`` of one kind."""
        have = self.names[kind]
        t = np.frombuffer(self._t[kind], dtype=np.int64).copy() if len(self._t[kind]) else np.zeros(0, np.int64)
        v = self._values(kind, len(t))
        return t, v[:, [have.index(n) for n in names]].astype(float)

    def view(self, kind: str, names: Sequence[str]) -> tuple[np.ndarray, list[np.ndarray]]:
        """(t_ns (n,), one strided view per name) of one kind, without copying: read them before
        the kind's next :meth:`add` (an exported buffer cannot grow)."""
        have = self.names[kind]
        t = np.frombuffer(self._t[kind], dtype=np.int64) if len(self._t[kind]) else np.zeros(0, np.int64)
        v = self._values(kind, len(t))
        return t, [v[:, have.index(n)] for n in names]

    def _values(self, kind: str, n: int) -> np.ndarray:
        a = self._v[kind]
        k = len(self.names[kind])
        return np.frombuffer(a, dtype=np.float32 if a.typecode == "f" else float).reshape(n, k) if n else np.zeros((0, k))


def stream(samples, kind: str, names: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """(t_ns (n,), values (n, k)) of one sample kind (from :class:`Streams` or a sample
    sequence); a field missing in a sample -> NaN."""
    if not isinstance(samples, Streams):
        st = Streams({kind: names})
        for s in samples:
            st.add(s)
        samples = st
    return samples.get(kind, names)


def uniform(t_ns: np.ndarray, v: np.ndarray, t0_ns: int = 0) -> tuple[np.ndarray, np.ndarray, float]:
    """Resample a stream (NaN-free rows) onto its own uniform grid (median step); times in s
    relative to ``t0_ns``."""
    ok = np.all(np.isfinite(v), axis=1)
    t_ns, v = t_ns[ok], v[ok]
    if len(t_ns) < 3:
        return (t_ns - t0_ns).astype(float) * 1e-9, v, 0.0
    t, tg, rate = _uniform_grid(t_ns, t0_ns)
    vg = np.column_stack([np.interp(tg, t, v[:, k]) for k in range(v.shape[1])])
    return tg, vg, rate


def _uniform_grid(t_ns: np.ndarray, t0_ns: int) -> tuple[np.ndarray, np.ndarray, float]:
    """(sample times, the uniform grid at the median step, its rate) of at least 3 stamps [s,
    relative to ``t0_ns``]."""
    dt = float(np.median(np.diff(t_ns))) * 1e-9
    if dt <= 0:
        dt = 1e-3
    t = (t_ns - t0_ns).astype(float) * 1e-9
    return t, np.arange(t[0], t[-1] + 0.5 * dt, dt), 1.0 / dt


def on_grid(grid_s: np.ndarray, t_s: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Linear interpolation onto the grid; NaN outside the stream's span."""
    out = np.full((len(grid_s), v.shape[1]), np.nan)
    if len(t_s) < 2:
        return out
    inside = (grid_s >= t_s[0]) & (grid_s <= t_s[-1])
    for k in range(v.shape[1]):
        out[inside, k] = np.interp(grid_s[inside], t_s, v[:, k])
    return out


def smoothed(samples, kind, names, smoother, grid_s, t0_ns, min_rate_hz, want_rate: bool):
    """(values on the grid, derivatives on the grid or NaN, native rate) of one stream: as
    :func:`uniform`, the smoother, :func:`on_grid` and ``np.gradient`` on the whole stream, one
    field at a time, so the transient memory is a few copies of one field at the native rate
    (the same numbers: each step works per column)."""
    if isinstance(samples, Streams):
        t_ns, cols = samples.view(kind, names)
    else:
        t_ns, v = stream(samples, kind, names)
        cols = [v[:, k] for k in range(v.shape[1])]
    val = np.full((len(grid_s), len(names)), np.nan)
    der = np.full_like(val, np.nan)
    ok = np.ones(len(t_ns), dtype=bool)
    for c in cols:
        ok &= np.isfinite(c)
    t_ns = t_ns[ok]
    if len(t_ns) < 3:
        return val, der, 0.0
    t, tg, rate = _uniform_grid(t_ns, t0_ns)
    del t_ns
    for k, c in enumerate(cols):
        vs = smoother(np.interp(tg, t, c[ok]), rate)
        val[:, k] = on_grid(grid_s, tg, vs[:, None])[:, 0]
        if want_rate and rate >= min_rate_hz:
            der[:, k] = on_grid(grid_s, tg, np.gradient(vs, 1.0 / rate)[:, None])[:, 0]
    return val, der, rate


ESC_SUBSTITUTES = {"specific_force_mps2_z": GRAVITY_MPS2, "angular_rate_radps_x": 0.0, "angular_rate_radps_y": 0.0}
"""An ESC cluster's missing IMU axes, as the estimator substitutes them (``EkfConfig.substitute_*``:
f_z := g, w_x = w_y := 0, a level car); the equations that need them are not evaluated
(``residuals.compute_residuals``, ``DriveTable.sensors["imu_substituted"]``)."""


def smoothed_or_substituted(samples: "Streams", kind: str, names: Sequence[str], substitutes: Mapping[str, float],
                            smoother, grid_s, t0_ns, min_rate_hz):
    """:func:`smoothed` of ``names`` (with derivatives), except that the fields of
    ``substitutes`` the stream never carries (finite in no sample) are their constants, wherever
    the measured fields reach, with a zero derivative, when every other field is measured: (values,
    derivatives, native rate, the substituted names). Otherwise as :func:`smoothed`, nothing
    substituted."""
    _, raw = samples.view(kind, names)
    have = {n for n, c in zip(names, raw) if np.isfinite(c).any()}
    del raw
    subst = tuple(n for n in substitutes if n in names and n not in have)
    if not subst or not all(n in have for n in names if n not in substitutes):
        return (*smoothed(samples, kind, names, smoother, grid_s, t0_ns, min_rate_hz, True), ())
    measured = [n for n in names if n not in subst]
    v, d, rate = smoothed(samples, kind, measured, smoother, grid_s, t0_ns, min_rate_hz, True)
    there = np.isfinite(v).all(axis=1)  # rows the measured fields reach
    val, der = np.empty((len(grid_s), len(names))), np.empty((len(grid_s), len(names)))
    for k, n in enumerate(names):
        if n in subst:
            val[:, k], der[:, k] = np.where(there, substitutes[n], np.nan), np.where(there, 0.0, np.nan)
        else:
            j = measured.index(n)
            val[:, k], der[:, k] = v[:, j], d[:, j]
    return val, der, rate, subst


class Smoother:
    """Zero-phase Butterworth low-pass at one cutoff, designed per sampling rate."""

    def __init__(self, cutoff_hz: float, order: int = 4):
        self.cutoff_hz = cutoff_hz
        self.order = order
        self._cache: dict[float, tuple] = {}

    def __call__(self, y: np.ndarray, rate_hz: float) -> np.ndarray:
        if rate_hz <= 2.2 * self.cutoff_hz:
            return y.copy()
        key = round(rate_hz, 6)
        if key not in self._cache:
            self._cache[key] = butter(self.order, self.cutoff_hz / (0.5 * rate_hz))
        b, a = self._cache[key]
        padlen = 3 * max(len(a), len(b))
        if y.shape[0] <= padlen:
            return y.copy()
        return filtfilt(b, a, y, axis=0)
