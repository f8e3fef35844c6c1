#!/usr/bin/env python3
"""The full real-car study behind tests/test_real_rav4.py and tests/test_real_rtklib.py, with more
variants than the tests run (they keep to a few passes).

RAV4 (comma2k19 segment 40): filter vs raw u-blox vs mean wheel speed (RMS speed / course error
against global_pose), the u-blox latency on and off, GNSS-denied windows of 20 s starting every
5 s (drift of speed, course, position vs dead reckoning from wheel speeds + ESC yaw rate), the
head to head with openpilot's learned parameters and the observability report.

RTKLIB drive 0708: outages of 5, 10 (and 15) s every 30 s; variants switching off one thing at a
time: the stated IMU lag, the misalignment, the whole stated rotation, the standstill gyro
calibration, the real-car states and rows (bias states, non-holonomic constraint: "plain"), and
using the .pos velocities (with their own 0.13 s latency, ``Latencies.gnss_vel_s``).

Both cars also run "plain": the eq 7-11 filter without the real-car rows and states the sensor
sets switch on (wheel speed, non-holonomic constraint, IMU bias states, wheel-speed scale).

Usage::

    python tools/real_cars.py [--data ../shared/data/real] [--json out.json] [--quick]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from vdps_hil.identification.observability_report import IdentificationMonitor, observability_report
from vdps_hil.estimation.pipeline_config import Latencies
from vdps_hil.estimation.sensorsets import load_sensorset
from vdps_hil.model.params import load_vehicle
from vdps_hil.realdata.capture_writers import nmea_fix_lines
from vdps_hil.realdata.comma2k19 import COMMA_SEGMENT, read_comma_reference, read_comma_ublox
from vdps_hil.realdata.outages import outage_errors, outage_windows, summarize_outages
from vdps_hil.realdata.reference import dead_reckoning, speed_course_errors, velocity_lag
from vdps_hil.realdata.rtklib import RTKLIB_DRIVE, publisher_mounting_rpy, read_rtklib_pos
from vdps_hil.realdata.runs import gnss_denied, load_samples, run_pipeline, series
from vdps_hil.realdata.steering import OPENPILOT_RAV4, steer_response_fit, steer_signals, understeer_gradient
from vdps_hil.record.importer import CanSource, SerialSource
from vdps_hil.pipeline.node import SystemConfig, VdpsSystem
from vdps_hil.units import wrap_pi

REPO = Path(__file__).resolve().parents[1]
PLAIN = dict(gyro_bias=False, accel_bias=False, wheel_speed=False, wheel_scale_state=False, nonholonomic=False)
"""The eq 7-11 filter without the real-car rows and states."""


def _tool(name):
    import importlib.util

    spec = importlib.util.spec_from_file_location(name, REPO / "tools" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def rav4(data: Path, tmp: Path, quick: bool) -> dict:
    seg = data / COMMA_SEGMENT
    fixes = read_comma_ublox(seg)
    (tmp / "gnss.nmea").write_bytes(b"".join(nmea_fix_lines(fixes, 0.0)))
    samples, _ = load_samples([CanSource("pt", str(seg / "rav4_seg40.candump.log"), "can0")],
                              [SerialSource("gnss", str(tmp / "gnss.nmea"))], signalmap="toyota_rav4_2017",
                              dbc={"*": str(seg / "toyota_new_mc_pt_generated.dbc")})
    ref = read_comma_reference(seg)
    veh = load_vehicle("rav4-model", "model")
    ss = load_sensorset("rav4-can-ublox")
    out: dict = {}

    def run(windows=(), plain=False, **kw):
        cfg = ss.pipeline_config(observability_window_s=None, output_period_s=0.05, **kw)
        if plain:
            cfg = dataclasses.replace(cfg, ekf=dataclasses.replace(cfg.ekf, **PLAIN))
        r = run_pipeline(veh, cfg, samples, kind_map=ss.kind_map, origin=ref.origin,
                         drop=gnss_denied(windows, cfg.latencies.gnss_s) if windows else None)
        pa, va = r.track.antenna(veh.mounting.gnss_lever_arm_m)
        return r, pa, va

    r, pa, va = run()
    tw, w = series(samples, "wheel_speed", [f"wheel_speed_radps_{i}" for i in range(1, 5)])
    vw = w.mean(axis=1) * veh.tire.rolling_radius_m
    rows = {"filter": speed_course_errors(r.track.t_s, np.hypot(va[:, 0], va[:, 1]), np.arctan2(va[:, 1], va[:, 0]),
                                          ref),
            "u-blox": speed_course_errors(fixes.t_s, fixes.speed_mps, fixes.course_rad, ref),
            "wheels": speed_course_errors(tw, vw, np.full_like(vw, np.nan), ref)}
    rp, _, vap = run(plain=True)
    rows["filter, plain eq 7-11"] = speed_course_errors(rp.track.t_s, np.hypot(vap[:, 0], vap[:, 1]),
                                                          np.arctan2(vap[:, 1], vap[:, 0]), ref)
    r0, _, va0 = run(latencies=Latencies())
    rows["filter, no u-blox latency"] = speed_course_errors(r0.track.t_s, np.hypot(va0[:, 0], va0[:, 1]),
                                                            np.arctan2(va0[:, 1], va0[:, 0]), ref)
    print("RAV4: RMS errors against global_pose")
    for k, e in rows.items():
        print(f"  {k:28s} speed {e['speed_rms_mps']:.3f} m/s (mean {e['speed_mean_mps']:+.3f})  course "
              f"{e['course_rms_deg']:.3f} deg")
    out["baselines"] = rows
    out["augmented_state"] = {k: list(v) for k, v in r.pipeline.augmented_state().items()}
    print("RAV4 estimated states beyond eq 7: " + ", ".join(f"{k} {v:+.5f} +- {sg:.5f}"
                                                           for k, (v, sg) in r.pipeline.augmented_state().items()))
    ty, wz = series(samples, "esc_imu", ["angular_rate_radps_z"])
    wz_w = np.interp(tw, ty, wz[:, 0])
    t0 = ref.t_s[0]
    starts = [5.0, 20.0, 35.0] if quick else list(np.arange(2.0, 38.1, 4.0))
    drift = []
    print("RAV4: GNSS-denied 20 s windows, error at the end: filter | dead reckoning (wheels + ESC yaw rate)"
          " | plain eq 7-11 filter position")
    for s0 in starts:
        a, b = t0 + s0, t0 + s0 + 20.0
        rr, pa2, va2 = run([(a, b)])
        rq, paq, _ = run([(a, b)], plain=True)
        tr = rr.track
        i0, i1 = int(np.searchsorted(tr.t_s, a)) - 1, int(np.searchsorted(tr.t_s, b)) - 1
        pr, vr = ref.at([tr.t_s[i1]])
        sp2, crs2 = np.hypot(va2[:, 0], va2[:, 1]), np.arctan2(va2[:, 1], va2[:, 0])
        tt, dsp, dcrs, dp = dead_reckoning(tw, vw, wz_w, pa2[i0, :2], float(crs2[i0]), tr.t_s[i0], tr.t_s[i1])
        c_ref = math.atan2(vr[0, 1], vr[0, 0])
        d = {"start_s": s0, "filter": {"speed_mps": float(sp2[i1] - np.hypot(*vr[0, :2])),
                                       "course_deg": float(np.degrees(wrap_pi(crs2[i1] - c_ref))),
                                       "position_m": float(np.hypot(*(pa2[i1, :2] - pr[0, :2])))},
             "dead_reckoning": {"speed_mps": float(dsp[-1] - np.hypot(*vr[0, :2])),
                                "course_deg": float(np.degrees(wrap_pi(dcrs[-1] - c_ref))),
                                "position_m": float(np.hypot(*(dp[-1] - pr[0, :2])))}}
        iq = int(np.searchsorted(rq.track.t_s, b)) - 1
        prq, _ = ref.at([rq.track.t_s[iq]])
        d["plain"] = {"position_m": float(np.hypot(*(paq[iq, :2] - prq[0, :2])))}
        drift.append(d)
        f, g = d["filter"], d["dead_reckoning"]
        print(f"  {s0:4.0f}-{s0 + 20:2.0f} s: speed {f['speed_mps']:+7.2f} | {g['speed_mps']:+6.2f} m/s  course "
              f"{f['course_deg']:+6.2f} | {g['course_deg']:+6.2f} deg  position {f['position_m']:6.1f} | "
              f"{g['position_m']:5.1f} | {d['plain']['position_m']:6.1f} m")
    out["gnss_denied_20s"] = drift
    print(f"  mean position error at the end: filter {np.mean([d['filter']['position_m'] for d in drift]):.1f} m, "
          f"dead reckoning {np.mean([d['dead_reckoning']['position_m'] for d in drift]):.1f} m, plain "
          f"{np.mean([d['plain']['position_m'] for d in drift]):.1f} m")
    # head to head
    ren = [dataclasses.replace(s, kind="imu") if s.kind == "esc_imu" else s for s in samples]
    t, u, sw, wzt, cr = steer_signals(ren, r.track)
    op = OPENPILOT_RAV4
    k0 = understeer_gradient(op["mass_kg"], op["center_to_front_m"], op["wheelbase_m"] - op["center_to_front_m"],
                             op["cornering_stiffness_front_nprad"], op["cornering_stiffness_rear_nprad"])
    fit = steer_response_fit(t, u, sw, wzt, cr, wheelbase_m=op["wheelbase_m"], understeer0=k0,
                             prior_steer_ratio=op["steer_ratio"])
    print(f"RAV4 head to head: steer ratio {fit.steer_ratio:.1f} +- {fit.steer_ratio_sigma:.1f} (openpilot 16.88), "
          f"stiffness factor {fit.stiffness_factor:.2f} +- {fit.stiffness_factor_sigma:.2f} (1.0), angle offset "
          f"{fit.angle_offset_deg:+.3f} +- {fit.angle_offset_sigma_deg:.3f} deg; gains {fit.gains}")
    for e in fit.explanations:
        print(f"  {e.text}")
    out["openpilot"] = {"steer_ratio": [fit.steer_ratio, fit.steer_ratio_sigma],
                        "stiffness_factor": [fit.stiffness_factor, fit.stiffness_factor_sigma],
                        "angle_offset_deg": [fit.angle_offset_deg, fit.angle_offset_sigma_deg],
                        "combination_m": list(fit.combination), "gains": list(fit.gains),
                        "observable": fit.observable(), "explanations": [e.text for e in fit.explanations]}
    pc = ss.pipeline_config(emit_estimates=False, observability_window_s=20.0)
    system = VdpsSystem(veh, SystemConfig(pipeline=pc, predict=False, suspension_rate_hz=None, tire_compliance=False,
                                          estimate_period_s=0.05, ident_period_s=0.05), ref.origin)
    system.identifier = IdentificationMonitor(system.identifier)
    for s in ren:
        system.handle(s)
    rep = observability_report(system.pipeline, system.identifier)
    print("RAV4 observability report:")
    for line in rep.summary_lines():
        print(f"  {line}")
    out["observability"] = rep.to_json()
    return out


def rtklib(data: Path, tmp: Path, quick: bool) -> dict:
    drive = data / RTKLIB_DRIVE
    doc = _tool("convert_rtklib").convert(drive / "gnss_1934_sf.pos", drive / "imu_1934.csv", tmp,
                                          tag_path=drive / "imu_1934.csv.tag")
    samples, _ = load_samples([], [SerialSource("gnss", str(tmp / "gnss.nmea")),
                                   SerialSource("imu", str(tmp / "imu.mti"), 115200)])
    ref = read_rtklib_pos(drive / "gnss_1934_sf.pos").reference(t0_gpst_s=doc["t0_gpst_s"])
    veh = load_vehicle("rtklib-car-model", "model")
    ss = load_sensorset("rtklib-car")
    t_move = float(ref.t_s[np.argmax(ref.speed_mps > 3.0)])
    lengths = (5.0, 10.0) if quick else (5.0, 10.0, 15.0)
    wins = outage_windows(t_move + 20.0, float(ref.t_s[-1]), 30.0, lengths, first_offset_s=0.0)
    mount = veh.mounting
    variants = {
        "published": (veh, {}, True),
        "no IMU lag": (veh, {"latencies": Latencies()}, True),
        "no misalignment": (dataclasses.replace(veh, mounting=dataclasses.replace(
            mount, imu_rotation_rpy_rad=publisher_mounting_rpy((180.0, 0.0, 180.0)))), {}, True),
        "no standstill gyro calibration": (veh, {}, False),
        "plain eq 7-11 filter": (veh, {"plain": True}, True),
        "plain, no standstill calibration": (veh, {"plain": True}, False),
    }
    if not quick:
        variants["no rotation at all"] = (dataclasses.replace(veh, mounting=dataclasses.replace(
            mount, imu_rotation_rpy_rad=(0.0, 0.0, 0.0))), {}, True)
        variants["with the .pos velocities"] = (veh, {"use_vel": True, "latencies": dataclasses.replace(
            ss.latencies, gnss_vel_s=velocity_lag(ref))}, True)
        variants[".pos velocities, one GNSS latency"] = (veh, {"use_vel": True}, True)
    out = {}
    print(f"RTKLIB drive 0708: {len(wins)} outages every 30 s ({', '.join(f'{x:g}' for x in lengths)} s)")
    for name, (v, kw, cal) in variants.items():
        t = time.perf_counter()
        cfg = ss.pipeline_config(observability_window_s=None, output_period_s=0.05, latencies=kw.get("latencies"))
        if kw.get("use_vel"):
            cfg = dataclasses.replace(cfg, ekf=dataclasses.replace(cfg.ekf, use_gnss_velocity=True))
        if kw.get("plain"):
            cfg = dataclasses.replace(cfg, ekf=dataclasses.replace(cfg.ekf, **PLAIN))
        r = run_pipeline(v, cfg, samples, origin=ref.origin, drop=gnss_denied(wins),
                         preprocess=ss.calibration_nodes(v) if cal else ())
        s = summarize_outages(outage_errors(r.track, v.mounting.gnss_lever_arm_m, ref, wins))
        gated = r.pipeline.counters["ekf"]["updates"]["gnss_pos"]["gated"]
        out[name] = {"outages": s, "gnss_pos_gated": gated, "reacquisitions": r.pipeline.counters["reacquisitions"],
                     "augmented_state": {k: list(v) for k, v in r.pipeline.augmented_state().items()},
                     "wall_s": time.perf_counter() - t}
        print(f"  {name:32s} " + "; ".join(f"{k}: {d['filter_mean_m']:.2f} m vs CV {d['cv_mean_m']:.2f} m "
                                          f"({100 * d['reduction']:.0f} % lower)" for k, d in s.items())
              + f"; gnss_pos gated {gated}, re-acquired {out[name]['reacquisitions']}; {out[name]['wall_s']:.1f} s")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default=str(REPO.parent / "shared" / "data" / "real"))
    ap.add_argument("--json", default=None)
    ap.add_argument("--quick", action="store_true", help="fewer windows and variants")
    a = ap.parse_args(argv)
    data = Path(a.data)
    if not data.is_dir():
        print(f"real_cars: no data folder {data}", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory() as d:
        doc = {"rav4": rav4(data, Path(d), a.quick)}
        (Path(d) / "rtk").mkdir()
        doc["rtklib"] = rtklib(data, Path(d) / "rtk", a.quick)
    if a.json:
        Path(a.json).write_text(json.dumps(doc, indent=2, default=float) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
