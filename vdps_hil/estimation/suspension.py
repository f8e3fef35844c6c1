"""Suspension conditioning of the Figure 2 node (``pipeline.node.VdpsSystem``): window means of
a fast suspension sensor and the tire-compliance correction, before the EKF sees the samples.

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

Symbols: t [ns], T window [s], H deflection [m] (compression +), sigma [m], n samples per window.
"""

from __future__ import annotations

import math

from vdps_hil.bus.samples import Sample, wheel_fields
from vdps_hil.model.params import Vehicle

__all__ = ["CONDITIONING_SIGMA_FACTOR", "SUSPENSION_STAMPS", "SuspensionConditioner"]

_SUSP = wheel_fields("susp_deflection_m")
_NEVER = 1 << 62
_MAX_SUSP_LEAD_NS = 50_000_000
"""The identifier's H, H_dot are carried forward / led only over at most 50 ms (five 100 Hz
windows); a slower suspension sensor (table1's 1 Hz) gets the filter's values unchanged."""

SUSPENSION_STAMPS = ("mean", "end")
CONDITIONING_SIGMA_FACTOR = 1.5
"""``suspension_stamp = "end"`` only: sigma of a window mean extrapolated to the window's end
over sigma_H / sqrt(n) (the alpha-beta rate of the extrapolation adds its noise and lag; without
it the y1_sus NIS per degree of freedom was 2.2 on the ISO 3888 lane change)."""


class SuspensionConditioner:
    """Window means and the tire-compliance correction of suspension samples (module
    docstring). ``due(t_ns)`` returns the conditioned sample of a window that has ended by
    ``t_ns`` (call it with every sample's time, in order); ``add(sample)`` absorbs a suspension
    sample. ``raw_filtered()`` is the alpha-beta (H, H_dot) of the *measured* deflections (the
    identifier's eq 14 forces need them; the EKF gets H_eff)."""

    def __init__(self, vehicle: Vehicle, rate_hz: float | None, tire_compliance: bool, raw_bandwidth_hz: float,
                 rate_bandwidth_hz: float, max_gap_s: float, rate_lead: bool = True, stamp: str = "end"):
        from vdps_hil.estimation.alpha_beta import TimedAlphaBetaBank
        from vdps_hil.model.spring_law import suspension_forces_n

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
