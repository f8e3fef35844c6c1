"""Tests of vdps_hil.workbench.streams: the drive's packed sample streams and their smoothing
onto the table's grid."""

from __future__ import annotations

import numpy as np

from vdps_hil.bus.samples import Sample
from vdps_hil.units import GRAVITY_MPS2
from vdps_hil.workbench.streams import (ANGULAR_RATE_FIELDS, ESC_SUBSTITUTES, GNSS_POS_FIELDS, SPECIFIC_FORCE_FIELDS,
                                        Smoother, Streams, on_grid, smoothed, smoothed_or_substituted, uniform)

IMU = tuple(SPECIFIC_FORCE_FIELDS) + tuple(ANGULAR_RATE_FIELDS)


def _imu_streams(rate_hz=1000.0, duration_s=4.0, seed=7):
    """A 1 kHz IMU with 1.3 Hz motion plus white noise, every 97th sample missing a field."""
    rng = np.random.default_rng(seed)
    st = Streams()
    n = int(duration_s * rate_hz)
    for i in range(n):
        t = i / rate_hz
        vals = {f: 2.0 * np.sin(2 * np.pi * 1.3 * t + k) + 0.05 * rng.standard_normal() for k, f in enumerate(IMU)}
        if i % 97 == 5:
            vals.pop(IMU[2])
        st.add(Sample(int(round(t * 1e9)), "imu", "imu", fields=vals))
    return st


def test_high_rate_streams_hold_single_precision_and_gnss_double():
    """Memory: the 1 kHz kinds keep 4 bytes a value, GNSS 8 (a latitude in single precision is
    0.4 m coarse); values come back as float64 and a single's rounding is below 6e-8 relative."""
    st = Streams()
    st.add(Sample(1, "imu", "imu", fields={f: 9.80665 for f in IMU}))
    st.add(Sample(2, "gnss", "gnss_pos", fields={"gnss_lat_deg": 48.123456789, "gnss_lon_deg": 11.5}))
    assert st._v["imu"].itemsize == 4 and st._v["gnss_pos"].itemsize == 8
    _, v = st.get("imu", IMU)
    assert v.dtype == np.float64 and abs(v[0, 0] - 9.80665) <= 6e-8 * 9.80665
    _, g = st.get("gnss_pos", GNSS_POS_FIELDS)
    assert g[0, 0] == 48.123456789 and np.isnan(g[0, 2])


def test_smoothed_field_by_field_equals_the_whole_stream_formulation():
    """smoothed() works one field at a time; it gives the values of resampling all fields at
    once, filtering and differentiating them along time, within 1e-12 (rows with a missing field
    are left out for every field, as before)."""
    st = _imu_streams()
    sm = Smoother(10.0)
    grid = np.arange(0.05, 3.9, 0.02)
    val, der, rate = smoothed(st, "imu", IMU, sm, grid, 0, 20.0, True)
    t_ns, v = st.get("imu", IMU)
    tg, vg, rate_ref = uniform(t_ns, v, 0)
    vs = sm(vg, rate_ref)
    assert rate == rate_ref and abs(rate - 1000.0) < 1e-6
    np.testing.assert_allclose(val, on_grid(grid, tg, vs), rtol=0, atol=1e-12)
    np.testing.assert_allclose(der, on_grid(grid, tg, np.gradient(vs, 1.0 / rate_ref, axis=0)), rtol=0, atol=1e-10)
    # physics: the 10 Hz low-pass keeps the 1.3 Hz motion (amplitude 2) and its derivative
    t = grid
    np.testing.assert_allclose(val[:, 0], 2.0 * np.sin(2 * np.pi * 1.3 * t), atol=0.03)
    d_true = 2.0 * 2 * np.pi * 1.3 * np.cos(2 * np.pi * 1.3 * t)  # amplitude 16.3; noise passes the 10 Hz
    assert np.sqrt(np.mean((der[:, 0] - d_true) ** 2)) < 0.03 * 16.3  # band differentiated: RMS within 3 %


def test_smoothed_slow_stream_gives_values_without_derivative_and_empty_stream_nan():
    st = _imu_streams(rate_hz=10.0, duration_s=20.0)
    grid = np.arange(0.0, 30.0, 0.02)
    val, der, rate = smoothed(st, "imu", IMU[:1], Smoother(10.0), grid, 0, 20.0, True)
    assert abs(rate - 10.0) < 1e-9 and np.isnan(der).all()
    assert np.isfinite(val[grid <= 19.8]).all() and np.isnan(val[grid > 19.95]).all()  # NaN outside the span
    val, der, rate = smoothed(Streams(), "suspension", ["susp_deflection_m_1"], Smoother(10.0), grid, 0, 20.0, True)
    assert rate == 0.0 and np.isnan(val).all() and np.isnan(der).all()


def _esc_streams(rate_hz=83.0, duration_s=4.0):
    """An ESC cluster: a_x, a_y and the yaw rate only (1.3 Hz motion)."""
    st = Streams()
    for i in range(int(duration_s * rate_hz)):
        t = i / rate_hz
        st.add(Sample(int(round(t * 1e9)), "can.pt", "imu", fields={
            "specific_force_mps2_x": np.sin(2 * np.pi * 1.3 * t), "specific_force_mps2_y": np.cos(2 * np.pi * 1.3 * t),
            "angular_rate_radps_z": 0.1 * np.sin(2 * np.pi * 1.3 * t)}))
    return st


def test_an_esc_cluster_has_its_missing_axes_substituted_where_it_is_measured():
    """f_z := g and w_x = w_y := 0 (derivatives 0) on the rows the three measured axes reach; those
    three are smoothed exactly as ``smoothed`` smooths them alone; the substituted names are
    returned. A six-axis IMU substitutes nothing and equals ``smoothed``."""
    grid = np.arange(-0.5, 4.5, 0.02)
    sm = Smoother(10.0)
    esc = _esc_streams()
    val, der, rate, subst = smoothed_or_substituted(esc, "imu", IMU, ESC_SUBSTITUTES, sm, grid, 0, 5.0)
    assert set(subst) == {"specific_force_mps2_z", "angular_rate_radps_x", "angular_rate_radps_y"}
    measured = [n for n in IMU if n not in subst]
    v, d, r = smoothed(esc, "imu", measured, sm, grid, 0, 5.0, True)
    assert r == rate
    there = np.isfinite(v).all(axis=1)
    assert 0 < there.sum() < len(grid)  # the grid runs past the stream on both ends
    for k, n in enumerate(IMU):
        if n in subst:
            want = GRAVITY_MPS2 if n == "specific_force_mps2_z" else 0.0
            assert np.all(val[there, k] == want) and np.all(der[there, k] == 0.0)
            assert np.isnan(val[~there, k]).all() and np.isnan(der[~there, k]).all()
        else:
            j = measured.index(n)
            np.testing.assert_array_equal(val[:, k], v[:, j])
            np.testing.assert_array_equal(der[:, k], d[:, j])
    six = _imu_streams(duration_s=2.0)
    val, der, rate, subst = smoothed_or_substituted(six, "imu", IMU, ESC_SUBSTITUTES, sm, grid, 0, 5.0)
    ref = smoothed(six, "imu", IMU, sm, grid, 0, 5.0, True)
    assert subst == () and rate == ref[2]
    np.testing.assert_array_equal(val, ref[0])
    np.testing.assert_array_equal(der, ref[1])
