#!/usr/bin/env python3
"""Convert a comma2k19 segment's numpy GNSS and IMU arrays into files ``vdps import`` reads.

comma2k19 keeps the u-blox fixes and the phone IMU as numpy arrays (``processed_log/GNSS/
live_gnss_ublox``, ``processed_log/IMU/{accelerometer,gyro}``); the CAN stream is already a
candump log. This tool writes, into OUT_DIR:

==================  ========================================================================
``gnss.nmea``       the u-blox fixes as time-stamped NMEA text (``<t> $GPGGA`` and ``<t> $GPRMC``
                    per fix; single antenna: no attitude sentence). Height: the arrays give the
                    ellipsoidal height; it is printed in the GGA altitude field with a geoid
                    separation of 0 (see ``realdata.capture_writers.nmea_fix_lines``).
``imu.mti``         the phone IMU as an Xsens MTData2 capture at ``--baud`` whose wire time puts
                    every packet at its stamp (``realdata.capture_writers.mti_capture``); axes
                    converted from comma's documented [forward, right, down] to x forward, y
                    left, z up.
``pt.candump.log``  the segment's candump log with every stamp moved by -t0 (with ``--can``), so
                    CAN, GNSS and IMU share one clock.
``convert.json``    t0, baud, counts and the ``vdps import`` command line.
==================  ========================================================================

Clock: every output time is t_boot - t0 (comma's device boot seconds minus t0). ``--t0 auto``
(the default) takes t0 = floor(earliest stamp) - 1 s, needed for the IMU capture (its wire time
starts at 0). ``--t0 0`` keeps boot seconds (then no IMU capture: its padding would be hours).

Example::

    python tools/convert_comma2k19.py ../shared/data/real/comma2k19_rav4_2018-08-02_seg40 out/
    vdps import --can pt=out/pt.candump.log@can0 --serial gnss=out/gnss.nmea \\
        --serial imu=out/imu.mti@115200 --signalmap toyota_rav4_2017 \\
        --dbc ../shared/data/real/comma2k19_rav4_2018-08-02_seg40/toyota_new_mc_pt_generated.dbc \\
        -o rav4.mcap
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
from pathlib import Path

from vdps_hil.realdata.capture_writers import mti_capture, nmea_fix_lines
from vdps_hil.realdata.comma2k19 import read_comma_phone_imu, read_comma_ublox

CANDUMP_NAME = "rav4_seg40.candump.log"
DBC_NAME = "toyota_new_mc_pt_generated.dbc"
_CANDUMP_LINE = re.compile(rb"^\((\d+)\.(\d+)\)(.*)$", re.S)


def shift_candump(src: Path, dst: Path, t0_s: float) -> tuple[int, int]:
    """Copy a candump ``-L`` log moving every ``(seconds)`` stamp by -t0 (exact decimal
    arithmetic on the printed digits). Lines without a stamp are copied unchanged. Returns
    (lines, shifted)."""
    t0_us = int(round(t0_s * 1e6))
    n = shifted = 0
    with open(src, "rb") as fi, open(dst, "wb") as fo:
        for line in fi:
            n += 1
            m = _CANDUMP_LINE.match(line)
            if not m:
                fo.write(line)
                continue
            frac = m.group(2)
            us = int(m.group(1)) * 1_000_000 + int((frac + b"000000")[:6])
            us -= t0_us
            sign = "-" if us < 0 else ""
            us = abs(us)
            fo.write(f"({sign}{us // 1_000_000}.{us % 1_000_000:06d})".encode() + m.group(3))
            shifted += 1
    return n, shifted


def convert(seg_dir, out_dir, *, t0: float | str = "auto", imu: bool = True, can: bool = True,
            baud: int = 115200) -> dict:
    """Write the files of the module docstring; returns the ``convert.json`` document."""
    seg = Path(seg_dir)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    fixes = read_comma_ublox(seg)
    phone = read_comma_phone_imu(seg) if imu else None
    if t0 == "auto":
        firsts = [float(fixes.t_s[0])] + ([float(phone.t_s[0])] if phone is not None else [])
        t0_s = float(math.floor(min(firsts)) - 1.0)
    else:
        t0_s = float(t0)
    lines = nmea_fix_lines(fixes, t0_s)
    (out / "gnss.nmea").write_bytes(b"".join(lines))
    doc = {"source": str(seg), "clock": "device boot seconds - t0", "t0_s": t0_s,
           "gnss": {"file": "gnss.nmea", "fixes": len(fixes), "lines": len(lines)}}
    serial = [f"--serial gnss={out / 'gnss.nmea'}"]
    if phone is not None:
        data, stats = mti_capture(phone, t0_s, baud)
        (out / "imu.mti").write_bytes(data)
        doc["imu"] = {"file": "imu.mti", "baud": baud, "packets": stats.packets, "delayed": stats.delayed,
                      "padding_bytes": stats.padding_bytes, "max_time_error_s": stats.max_error_s,
                      "axes": "x forward, y left, z up (from comma's forward, right, down)"}
        serial.append(f"--serial imu={out / 'imu.mti'}@{baud}")
    cmd = ["vdps import"]
    if can:
        n, k = shift_candump(seg / CANDUMP_NAME, out / "pt.candump.log", t0_s)
        doc["can"] = {"file": "pt.candump.log", "lines": n, "shifted": k}
        cmd.append(f"--can pt={out / 'pt.candump.log'}@can0")
    cmd += serial
    cmd += ["--signalmap toyota_rav4_2017", f"--dbc {seg / DBC_NAME}", "-o rav4.mcap"]
    doc["import"] = " ".join(cmd)
    (out / "convert.json").write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
    return doc


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    ap.add_argument("segment", help="comma2k19 segment folder (with processed_log/ and global_pose/)")
    ap.add_argument("out_dir")
    ap.add_argument("--t0", default="auto", help="clock offset [s] subtracted from every stamp, or 'auto'")
    ap.add_argument("--no-imu", action="store_true", help="do not write the phone IMU capture")
    ap.add_argument("--no-can", action="store_true", help="do not write the shifted candump log")
    ap.add_argument("--baud", type=int, default=115200, help="baud of the IMU capture (default 115200)")
    a = ap.parse_args(argv)
    try:
        t0 = a.t0 if a.t0 == "auto" else float(a.t0)
        doc = convert(a.segment, a.out_dir, t0=t0, imu=not a.no_imu, can=not a.no_can, baud=a.baud)
    except (OSError, ValueError) as e:
        print(f"convert_comma2k19: {e}", file=sys.stderr)
        return 2
    print(json.dumps(doc, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
