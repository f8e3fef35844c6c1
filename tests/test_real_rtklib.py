"""The rtklibexplorer drive 0708 (549 s, residential hill streets then a parking lot): roof 6-axis
MEMS IMU at 100 Hz and an RTK single-antenna GNSS at 4 Hz (99.6 % fixed), converted by
tools/convert_rtklib.py and imported with `vdps import`'s code, run with the sensor set
``rtklib-car`` (stated IMU lag 0.125 s, standstill gyro calibration, gyro and accelerometer bias
states, non-holonomic constraint) and the model file ``rtklib-car-model`` (stated IMU orientation
+ misalignment, lever arms).

GNSS outages of 5 s and 10 s alternate every 30 s, from 20 s after the car first moves. Metric
(printed): horizontal error of the filter's antenna position at the last RTK epoch of each
outage against the RTK solution, and of constant-velocity extrapolation from the last RTK epoch
before the outage; per outage length the mean over the outages (acceptance: the filter's mean at
least 50 % lower; with the bias states and the constraint this drive gives 88-93 %, asserted
>= 80 %, with and without the standstill calibration), the largest, and the share of single
outages where it is halved. Then the stated 0.125 s IMU lag and the stated misalignment are
switched off, one at a time."""

from __future__ import annotations

import dataclasses
import importlib.util

import numpy as np
import pytest

from vdps_hil.estimation.pipeline_config import Latencies
from vdps_hil.estimation.sensorsets import load_sensorset
from vdps_hil.model.params import load_vehicle
from vdps_hil.pipeline.configure import sample_stats, system_config
from vdps_hil.realdata.outages import outage_errors, outage_windows, summarize_outages
from vdps_hil.realdata.reference import interp_angle, velocity_lag
from vdps_hil.realdata.rtklib import RTKLIB_DRIVE, publisher_mounting_rpy, read_rtklib_pos
from vdps_hil.realdata.runs import gnss_denied, load_samples, run_pipeline
from vdps_hil.record.importer import SerialSource
from vdps_hil.units import wrap_pi

from conftest import REAL_DATA, REPO

DRIVE = REAL_DATA / RTKLIB_DRIVE


@pytest.fixture(scope="module")
def drive(tmp_path_factory):
    if not DRIVE.is_dir():
        pytest.skip(f"real data not present: {DRIVE}")
    spec = importlib.util.spec_from_file_location("convert_rtklib", REPO / "tools" / "convert_rtklib.py")
    tool = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tool)
    out = tmp_path_factory.mktemp("rtk")
    doc = tool.convert(DRIVE / "gnss_1934_sf.pos", DRIVE / "imu_1934.csv", out, tag_path=DRIVE / "imu_1934.csv.tag")
    samples, _ = load_samples([], [SerialSource("gnss", str(out / "gnss.nmea")),
                                   SerialSource("imu", str(out / "imu.mti"), 115200)])
    ref = read_rtklib_pos(DRIVE / "gnss_1934_sf.pos").reference(t0_gpst_s=doc["t0_gpst_s"])
    veh = load_vehicle("rtklib-car-model", "model")
    ss = load_sensorset("rtklib-car")
    t_move = float(ref.t_s[np.argmax(ref.speed_mps > 3.0)])
    windows = outage_windows(t_move + 20.0, float(ref.t_s[-1]), 30.0, (5.0, 10.0), first_offset_s=0.0)
    return samples, ref, veh, ss, windows, t_move


PLAIN = dict(gyro_bias=False, accel_bias=False, nonholonomic=False)
"""The eq 7-11 filter without the real-car states and rows (what the sensor set had before)."""


def _run(drive, vehicle=None, latencies=None, windows=None, until_s=None, calibration=True, ekf=None):
    samples, ref, veh, ss, wins, _ = drive
    v = veh if vehicle is None else vehicle
    w = wins if windows is None else windows
    if until_s is not None:
        samples = [s for s in samples if s.t_ns / 1e9 < until_s]
    cfg = ss.pipeline_config(observability_window_s=None, output_period_s=0.05, latencies=latencies)
    if ekf:
        cfg = dataclasses.replace(cfg, ekf=dataclasses.replace(cfg.ekf, **ekf))
    r = run_pipeline(v, cfg, samples, origin=ref.origin, drop=gnss_denied(w) if w else None,
                     preprocess=ss.calibration_nodes(v) if calibration else ())
    return r, outage_errors(r.track, v.mounting.gnss_lever_arm_m, ref, w)


def _attitude_offsets(track, ref, t0, t1):
    """Mean (yaw - course of the reference) and mean pitch [deg] while moving above 4 m/s."""
    m = (track.t_s >= t0) & (track.t_s <= t1)
    t = track.t_s[m]
    c = interp_angle(t, ref.t_s, ref.course_rad)
    moving = np.interp(t, ref.t_s, ref.speed_mps) > 4.0
    yaw = np.degrees(np.mean(wrap_pi(track.x[m, 8][moving] - c[moving])))
    return float(yaw), float(np.degrees(np.mean(track.x[m, 7][moving])))


def _print_table(title, summary):
    print(title)
    for k, d in summary.items():
        print(f"  {k:>4s} outages (n={d['n']}): filter mean {d['filter_mean_m']:5.2f} m (max {d['filter_max_m']:5.2f})"
              f" | constant velocity mean {d['cv_mean_m']:6.2f} m | {100 * d['reduction']:3.0f} % lower; "
              f"halved in {100 * d['halved_fraction']:3.0f} % of the outages")


@pytest.fixture(scope="module")
def published(drive):
    return _run(drive)


def test_outages_at_least_halve_the_constant_velocity_error(drive, published):
    samples, ref, veh, ss, wins, t_move = drive
    r, errs = published
    assert r.pipeline.counters["ekf"]["nan_resets"] == 0
    c = r.pipeline.counters["ekf"]["updates"]
    s = summarize_outages(errs)
    bias = ss.calibration_nodes(veh)
    _print_table(f"\nRTKLIB drive 0708: {len(wins)} GNSS outages every 30 s from {t_move + 20 - ref.t_s[0]:.0f} s "
                 f"(horizontal error at the last RTK epoch of each outage)", s)
    vlag = velocity_lag(ref)
    print(f"  gnss_pos updates accepted/gated {c['gnss_pos']['accepted']}/{c['gnss_pos']['gated']}, mean NIS/dof "
          + ", ".join(f"{k} {v['mean_nis_per_dof']:.2f}" for k, v in r.nis.items())
          + f"; the .pos velocities lag its positions by {vlag:.3f} s (not used: use_gnss_velocity = false)")
    assert 0.1 <= vlag <= 0.16
    aug = r.pipeline.augmented_state()
    print("  estimated IMU biases: " + ", ".join(f"{k} {v:+.4f} +- {sg:.4f}" for k, (v, sg) in aug.items()))
    assert bias and set(s) == {"5s", "10s"} and s["5s"]["n"] >= 8 and s["10s"]["n"] >= 8
    for k in ("5s", "10s"):
        assert s[k]["reduction"] >= 0.8, (k, s[k])  # measured 0.93 / 0.88 (was >= 0.5: 0.87 / 0.82)
    assert c["gnss_pos"]["gated"] == 0  # re-acquires after every outage
    assert c["nhc"]["accepted"] > 900 and c["nhc"]["gated"] < 0.03 * c["nhc"]["accepted"]  # a few, in low-speed turns
    assert abs(aug["gyro_bias_z_radps"][0]) < 3 * aug["gyro_bias_z_radps"][1] + 1e-3  # calibrated before


def test_outages_without_the_standstill_calibration(drive, published):
    """The gyro bias states replace the stopgap: without the standstill calibration the filter
    still halves constant velocity (measured 0.93 / 0.88, asserted >= 0.8), the plain eq 7-11
    filter without it does worse (measured 0.82 / 0.77), and the z bias the filter estimates is the
    gyro's reading at rest (0.17 deg/s stated; asserted within 0.1 deg/s)."""
    samples, ref, veh, ss, wins, t_move = drive
    r, errs = _run(drive, calibration=False)
    r_plain, errs_plain = _run(drive, calibration=False, ekf=PLAIN)
    s, sp = summarize_outages(errs), summarize_outages(errs_plain)
    _print_table("\nRTKLIB drive 0708 without the standstill gyro calibration (bias states in the filter):", s)
    _print_table("  the plain eq 7-11 filter (no bias states, no constraint), also without it:", sp)
    bz, sbz = r.pipeline.augmented_state()["gyro_bias_z_radps"]
    print(f"  estimated z gyro bias {np.degrees(bz):+.3f} +- {np.degrees(sbz):.3f} deg/s")
    assert r.pipeline.counters["ekf"]["updates"]["gnss_pos"]["gated"] == 0
    for k in ("5s", "10s"):
        assert s[k]["reduction"] >= 0.8, (k, s[k])
        assert s[k]["filter_mean_m"] < sp[k]["filter_mean_m"], (k, s[k], sp[k])
    assert abs(np.degrees(bz) - 0.17) < 0.1


def test_effect_of_the_stated_imu_lag_and_misalignment(drive, published):
    samples, ref, veh, ss, wins, t_move = drive
    r_pub, e_pub = published
    r_lag, e_lag = _run(drive, latencies=Latencies())
    no_mis = dataclasses.replace(veh, mounting=dataclasses.replace(
        veh.mounting, imu_rotation_rpy_rad=publisher_mounting_rpy((180.0, 0.0, 180.0))))
    t_end = t_move + 150.0
    # what the mounting rotation does to the attitude: the plain filter (no bias states, no
    # constraint) then estimates the IMU's attitude
    r_pub_plain, _ = _run(drive, windows=[], until_s=t_end, ekf=PLAIN)
    r_mis, _ = _run(drive, vehicle=no_mis, windows=[], until_s=t_end, ekf=PLAIN)
    # the filter of the sensor set: the constraint holds the attitude to the velocity; the pitch
    # misalignment reappears as an accelerometer bias b_a,x = -g sin(6.79 deg)
    r_pub_full, _ = _run(drive, windows=[], until_s=t_end)
    r_mis_full, _ = _run(drive, vehicle=no_mis, windows=[], until_s=t_end)
    pooled = {name: float(np.mean([e.filter_m for e in errs])) for name, errs in (("published", e_pub),
                                                                                  ("no lag", e_lag))}
    att_pub = _attitude_offsets(r_pub_plain.track, ref, t_move, t_end)
    att_mis = _attitude_offsets(r_mis.track, ref, t_move, t_end)
    att_full = _attitude_offsets(r_pub_full.track, ref, t_move, t_end)
    bax = {k: r.pipeline.augmented_state()["accel_bias_x_mps2"][0] for k, r in (("pub", r_pub_full),
                                                                                ("mis", r_mis_full))}
    nis = {k: r.nis["gnss_pos"]["mean_nis_per_dof"] for k, r in (("pub", r_pub_full), ("mis", r_mis_full))}
    _print_table("\nRTKLIB drive 0708, the stated 0.125 s IMU lag switched off:", summarize_outages(e_lag))
    print(f"  mean end-of-outage error over all {len(e_pub)} outages: {pooled['published']:.2f} m with the lag, "
          f"{pooled['no lag']:.2f} m without; mean NIS/dof gnss_pos "
          f"{r_pub.nis['gnss_pos']['mean_nis_per_dof']:.2f} vs {r_lag.nis['gnss_pos']['mean_nis_per_dof']:.2f}")
    print(f"  misalignment [0, -6.79, 5.35] deg switched off (orientation [180, 0, 180] kept), first 150 s of motion: "
          f"mean yaw - course {att_pub[0]:+.2f} -> {att_mis[0]:+.2f} deg, mean pitch {att_pub[1]:+.2f} -> "
          f"{att_mis[1]:+.2f} deg (the plain filter then estimates the IMU's attitude, not the car's)")
    print(f"  the sensor set's filter (bias states, non-holonomic constraint), published mounting: mean yaw - course "
          f"{att_full[0]:+.2f} deg, pitch {att_full[1]:+.2f} deg; misalignment off: accelerometer bias x "
          f"{bax['pub']:+.3f} -> {bax['mis']:+.3f} m/s^2 (-g sin 6.79 deg = -1.160), gnss_pos NIS/dof "
          f"{nis['pub']:.2f} -> {nis['mis']:.2f}")
    assert pooled["published"] < pooled["no lag"]
    # measured yaw - course -0.27 deg (the car's own sideslip is in it), pitch +0.03 deg (plain: +0.34 / +0.35)
    assert abs(att_full[0]) < 0.5 and abs(att_full[1]) < 0.2
    assert abs((bax["mis"] - bax["pub"]) + 9.80665 * np.sin(np.radians(6.79))) < 0.25
    assert nis["mis"] > 2.0 * nis["pub"]
    assert abs((att_mis[1] - att_pub[1]) - (-6.79)) < 1.0  # pitch offset = the stated misalignment pitch
    assert abs((att_mis[0] - att_pub[0]) - (-5.35)) < 1.5  # yaw offset = the stated misalignment yaw


def test_the_inferred_probe_waits_for_the_imu_that_starts_after_the_gnss(drive):
    """``vdps replay FILE`` without a named set sizes the system from the drive's first seconds.
    On this drive the IMU stream starts 3.4 s after the GNSS: the probe waits for it
    (``pipeline.configure.ProbeWindow``; a probe of the first 3 s alone found no IMU and the
    replay refused the drive, "no IMU") and infers a 6-axis IMU with a single antenna, which runs
    the real-car rows (``tests/test_configure.py``)."""
    samples, _, veh, _, _, _ = drive
    first: dict[str, int] = {}
    for smp in samples:
        first.setdefault(smp.kind, smp.t_ns)
    assert first["imu"] - first["gnss_pos"] > 3e9  # the drive's own late IMU, the reason for the rule
    _, rates, fields = sample_stats(iter(samples))
    assert rates["imu"] == pytest.approx(100.0, rel=0.02)
    cfg, _, _, desc = system_config(rates, fields, veh)
    assert (desc["imu"], desc["gnss"]) == ("6axis", "single_antenna")
    assert cfg.pipeline.ekf.nonholonomic and cfg.pipeline.ekf.gyro_bias


def test_the_recorded_order_gives_the_effective_time_order_s_estimates(drive):
    """``vdps replay`` hands the samples on in the recorded order, and the pipeline's sequencing
    (``estimation.sequencing``) must make the stated 0.125 s IMU lag what ordering by effective
    time makes it: the same updates accepted and the same final state (to the ordering's float
    noise). Before, the 50 ms hold released every RTK fix 75 ms before its IMU samples: `vdps
    replay FILE --vehicle rtklib-car-model --sensorset rtklib-car` accepted 916 of 2579 fixes and
    its heading ran 95 deg off the course."""
    samples, _, veh, ss, _, _ = drive
    cfg = ss.pipeline_config(observability_window_s=None, output_period_s=0.05)
    assert not cfg.ekf.use_gnss_velocity  # its velocity updates are "disabled" (the replay's by_status)
    runs = [run_pipeline(veh, cfg, samples, preprocess=ss.calibration_nodes(veh), order_by_effective_time=o)
            for o in (True, False)]
    ups = [{k: (v["accepted"], v["gated"]) for k, v in r.pipeline.counters["ekf"]["updates"].items()} for r in runs]
    assert ups[0] == ups[1] and ups[0]["gnss_pos"][1] == 0 and ups[0]["gnss_pos"][0] > 2000
    x0, x1 = runs[0].track.x[-1], runs[1].track.x[-1]
    assert np.hypot(x0[0] - x1[0], x0[1] - x1[1]) < 0.01 and abs(wrap_pi(x0[8] - x1[8])) < 1e-3
