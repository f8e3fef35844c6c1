#!/usr/bin/env python3
"""Convert an RTKLIB ``.pos`` solution and an IMU ``.csv`` with its RTKLIB time-tag file into files
``vdps import`` reads.

Input (the rtklibexplorer GNSS_IMU layout, e.g. ../shared/data/real/rtklibexplorer_drive_0708):

* ``gnss_*.pos``: RTKLIB solution, GPST, lat/lon/height, Q, ns, sigmas, velocities N/E/U;
* ``imu_*.csv``: ``ax, ay, az`` [g], ``gx, gy, gz`` [deg/s], device counter [ms], 100 Hz;
* ``imu_*.csv.tag``: RTKLIB time tags (GPST start of the IMU log and its last tick).

Output, into OUT_DIR, on one clock t = GPST - t0 (GPST calendar seconds since 1970 as RTKLIB
prints them, minus t0; ``--t0 auto``: floor of the earliest epoch - 1 s):

==================  ========================================================================
``gnss.nmea``       ``<t> $GPGGA`` + ``<t> $GPRMC`` per epoch (RTK fixed -> GGA quality 4 and RMC
                    mode R, float -> 5/F); UTC in the sentences = GPST - 18 s; single antenna.
``imu.mti``         the IMU as an Xsens MTData2 capture at ``--baud``
                    (``realdata.capture_writers.mti_capture``), in the IMU's own axes and SI
                    (g -> m/s^2, deg/s -> rad/s). Times follow the publisher's rule
                    (``realdata.rtklib.read_rtklib_imu``).
``convert.json``    t0, counts and the ``vdps import`` command line.
==================  ========================================================================

Not baked in (configuration, so each can be switched off): the publisher's IMU orientation and
misalignment and the lever arms (model vehicle file ``configs/vehicles/rtklib-car-model.toml``),
the IMU time-stamp lag of 0.125 s (sensor set ``configs/sensorsets/rtklib-car.toml``,
``[latencies] imu_s``).

Example::

    python tools/convert_rtklib.py ../shared/data/real/rtklibexplorer_drive_0708 out/
    vdps import --serial gnss=out/gnss.nmea --serial imu=out/imu.mti@115200 -o rtk.mcap
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from vdps_hil.realdata.capture_writers import mti_capture, nmea_fix_lines
from vdps_hil.realdata.rtklib import read_rtklib_imu, read_rtklib_pos


def find_inputs(folder) -> tuple[Path, Path, Path | None]:
    """(pos, imu csv, tag or None) of a folder with exactly one ``*.pos`` and one ``imu*.csv``."""
    d = Path(folder)
    pos = sorted(d.glob("*.pos"))
    csv = sorted(d.glob("imu*.csv"))
    if len(pos) != 1 or len(csv) != 1:
        raise ValueError(f"{d}: expected one *.pos and one imu*.csv, found {len(pos)} and {len(csv)}")
    tag = csv[0].with_name(csv[0].name + ".tag")
    return pos[0], csv[0], tag if tag.exists() else None


def convert(pos_path, imu_csv=None, out_dir=".", *, tag_path=None, t0: float | str = "auto",
            baud: int = 115200) -> dict:
    """Write the files of the module docstring; returns the ``convert.json`` document."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    sol = read_rtklib_pos(pos_path)
    imu = read_rtklib_imu(imu_csv, tag_path) if imu_csv is not None else None
    if imu is not None and tag_path is None:
        raise ValueError("the IMU log needs its time-tag file (GPST of the log)")
    if t0 == "auto":
        firsts = [float(sol.t_gpst_s[0])] + ([float(imu.t_s[0])] if imu is not None else [])
        t0_s = float(math.floor(min(firsts)) - 1.0)
    else:
        t0_s = float(t0)
    fixes = sol.fixes(t0_s)
    lines = nmea_fix_lines(fixes, 0.0)
    (out / "gnss.nmea").write_bytes(b"".join(lines))
    doc = {"source": str(pos_path), "clock": "GPST calendar seconds since 1970 - t0", "t0_gpst_s": t0_s,
           "gnss": {"file": "gnss.nmea", "epochs": len(fixes), "lines": len(lines),
                    "rtk_fixed_fraction": float((sol.q == 1).mean())}}
    cmd = ["vdps import", f"--serial gnss={out / 'gnss.nmea'}"]
    if imu is not None:
        data, stats = mti_capture(imu, t0_s, baud)
        (out / "imu.mti").write_bytes(data)
        doc["imu"] = {"file": "imu.mti", "source": str(imu_csv), "tag": str(tag_path), "baud": baud,
                      "packets": stats.packets, "delayed": stats.delayed, "padding_bytes": stats.padding_bytes,
                      "max_time_error_s": stats.max_error_s, "axes": "the IMU's own (mounting in the model file)"}
        cmd.append(f"--serial imu={out / 'imu.mti'}@{baud}")
    cmd.append("-o rtk.mcap")
    doc["import"] = " ".join(cmd)
    (out / "convert.json").write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
    return doc


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    ap.add_argument("input", help="a folder with one *.pos and one imu*.csv (+ .tag), or a .pos file")
    ap.add_argument("out_dir")
    ap.add_argument("--imu", default=None, help="IMU csv (with a folder input: found there)")
    ap.add_argument("--tag", default=None, help="time-tag file (default: IMU csv + .tag)")
    ap.add_argument("--t0", default="auto", help="clock offset [s, GPST] subtracted from every stamp, or 'auto'")
    ap.add_argument("--baud", type=int, default=115200, help="baud of the IMU capture (default 115200)")
    a = ap.parse_args(argv)
    try:
        if Path(a.input).is_dir():
            pos, csv, tag = find_inputs(a.input)
        else:
            pos, csv = Path(a.input), (Path(a.imu) if a.imu else None)
            tag = None if csv is None else csv.with_name(csv.name + ".tag")
        if a.imu:
            csv = Path(a.imu)
        if a.tag:
            tag = Path(a.tag)
        if tag is not None and not tag.exists():
            tag = None
        t0 = a.t0 if a.t0 == "auto" else float(a.t0)
        doc = convert(pos, csv, a.out_dir, tag_path=tag, t0=t0, baud=a.baud)
    except (OSError, ValueError) as e:
        print(f"convert_rtklib: {e}", file=sys.stderr)
        return 2
    print(json.dumps(doc, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
