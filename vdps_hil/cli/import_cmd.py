"""``vdps import``: CAN logs (asc, blf, candump log, trc, mf4, csv) and NMEA/IMU serial logs
into one recording, decoded through a signal map."""

from __future__ import annotations

import os
import shutil
import sys
from pathlib import Path

import click

from vdps_hil.cli.common import UserError, eprint, json_option, quiet_option, write_json

__all__ = ["import_", "parse_dbc_options", "parse_format_options"]


def parse_dbc_options(values) -> dict[str, str]:
    """``--dbc FILE`` (every bus) or ``--dbc BUS=FILE`` -> {bus or "*": file}."""
    out: dict[str, str] = {}
    for v in values:
        if "=" in v and not v.startswith(("/", ".")) and "/" not in v.split("=", 1)[0]:
            bus, path = v.split("=", 1)
            out[bus] = path
        else:
            out["*"] = v
    return out


def parse_format_options(values) -> dict[str, str]:
    out = {}
    for v in values:
        if "=" not in v:
            raise UserError(f"--format {v!r}: expected NAME=nmea or NAME=imu")
        name, fmt = v.split("=", 1)
        if fmt not in ("nmea", "imu"):
            raise UserError(f"--format {v!r}: format must be nmea or imu")
        out[name] = fmt
    return out


def source_lines(sources: dict) -> list[str]:
    lines = []
    for name, st in sources.items():
        c = st["counters"]
        from vdps_hil.adapters.health import ERROR_COUNTERS

        errs = {k: v for k, v in c.items() if k in ERROR_COUNTERS and v}
        kinds = ", ".join(f"{k} {v['count']} @ {v['rate_hz']:.1f} Hz"
                          for k, v in st["kinds"].items()) or "no samples"
        extra = []
        if c.get("unknown_id"):
            extra.append(f"unknown IDs {c['unknown_id']}")
        if c.get("other_channel"):
            extra.append(f"other channel {c['other_channel']}")
        if c.get("unsupported"):
            extra.append(f"unsupported sentences {c['unsupported']}")
        lines.append(f"  {name}: {st['records']} records -> {kinds}; errors "
                     f"{sum(errs.values())}{' ' + str(errs) if errs else ''}"
                     f"{'; ' + ', '.join(extra) if extra else ''}")
        if st.get("last_error"):
            lines.append(f"    last problem: {st['last_error']}")
    return lines


_TEXT_LOGS = (".log", ".asc", ".trc", ".csv", ".nmea", ".txt")


class ImportProgress:
    """One progress bar per imported source (``import_logs`` calls it with the adapter after each
    read): text logs in records against their line count, binary IMU captures in bytes against
    the file size, other binary logs (blf, mf4, mcap) without a total."""

    def __init__(self, quiet: bool):
        self.quiet = quiet
        self.bar = None
        self.source = None
        self.unit = "rec"

    def __call__(self, a) -> None:
        from vdps_hil.batch.progress import ProgressBar, is_live

        if self.quiet or not is_live():
            return
        if a is not self.source:
            self.close()
            self.source = a
            total, self.unit = _expected(a)
            self.bar = ProgressBar(total, f"vdps import {a.name}", unit=self.unit)
        lines = getattr(a, "lines_read", None)  # a CAN text log: every channel's lines
        self.bar.update_to(a.health.bytes if self.unit == "B" else lines if lines is not None else a.health.records)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None

    def __enter__(self) -> "ImportProgress":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _expected(a) -> tuple[int | None, str]:
    """(what the source holds, unit) for its progress bar (``ImportProgress``)."""
    path = Path(str(a.device))
    try:
        if type(a).__name__ == "ImuFileAdapter":
            return path.stat().st_size, "B"
        if path.suffix.lower() in _TEXT_LOGS:
            with open(path, "rb") as f:
                return sum(block.count(b"\n") for block in iter(lambda: f.read(1 << 20), b"")), "rec"
    except OSError:
        pass
    return None, "rec"


def _stdin_sources(can: list, work: str) -> list:
    """``--can BUS=-``: standard input (``candump -L`` lines, e.g. ``candump -L can0 | vdps import
    --can pt=- ...``) read to its end into ``work/stdin.log``, which python-can's candump reader
    then imports like a file; at most one source may be ``-``."""
    from dataclasses import replace

    if sum(1 for c in can if c.path == "-") > 1:
        raise UserError("only one --can source can read standard input (-)")
    out = []
    for c in can:
        if c.path == "-":
            path = os.path.join(work, "stdin.log")
            with open(path, "wb") as f:
                shutil.copyfileobj(sys.stdin.buffer, f)
            c = replace(c, path=path)
        out.append(c)
    return out


@click.command("import")
@click.option("--can", "can_specs", multiple=True, metavar="BUS=FILE[@CHANNEL]",
              help="A CAN log as bus BUS (asc, blf, candump .log, trc, mf4, csv, mcap); "
                   "@CHANNEL keeps only that channel of a multi-channel log.")
@click.option("--serial", "serial_specs", multiple=True, metavar="NAME=FILE[@BAUD]",
              help="A serial log as device NAME: NMEA/ASCII text (time stamps optional) or a "
                   "binary IMU capture (NAME imu*, or --format NAME=imu).")
@click.option("--format", "formats", multiple=True, metavar="NAME=nmea|imu",
              help="Format of a --serial log (default: imu if NAME starts with imu, else nmea).")
@click.option("--dbc", "dbcs", multiple=True, metavar="[BUS=]FILE",
              help="DBC of every bus, or of bus BUS (overrides the signal map's).")
@click.option("--signalmap", metavar="FILE|NAME", default=None,
              help="Signal map (configs/signalmaps/NAME.toml or a file): which frames feed "
                   "which bus fields. A bus named vdps uses the vdps map by default.")
@click.option("-o", "--output", required=True, metavar="OUT.mcap", help="Recording to write.")
@json_option
@quiet_option
def import_(can_specs, serial_specs, formats, dbcs, signalmap, output, json_out, quiet):
    """Import CAN and serial logs into one recording (raw + decoded + health).

    \b
    Examples:
      vdps import --can pt=rav4.log@can0 --signalmap toyota_rav4_2017 \\
                  --dbc toyota_new_mc_pt_generated.dbc -o rav4.mcap
      vdps import --can gnss=gnss1.MF4 --signalmap canedge_gnss_imu --dbc gnss.dbc -o a.mcap
      vdps import --serial gnss=rst39.nmea -o oxts.mcap
      candump -L can0 | vdps import --can vdps=- -o bus.mcap     # candump -L on standard input

    \b
    Serial text time stamps (at the start of a line, before the $ sentence):
      (1673458929.103950) $GP...   [12.5] $GP...   1673458929.1 $GP...
      1673458929103950000 $GP... (integer ns)   2014-02-19T20:41:32.1Z $GP...
      none: the sentence's own UTC time on the file's RMC/ZDA date.
    """
    from vdps_hil.record.importer import (ImportError_, import_logs, parse_can_source,
                                          parse_serial_source)

    import tempfile

    fmts = parse_format_options(formats)
    stdin_dir = tempfile.TemporaryDirectory(prefix="vdps-import-stdin-")
    try:
        can = [parse_can_source(s) for s in can_specs]
        can = _stdin_sources(can, stdin_dir.name)
        serial = []
        for s in serial_specs:
            src = parse_serial_source(s)
            serial.append(parse_serial_source(s, fmts.get(src.name)))
        with ImportProgress(quiet) as progress:
            report = import_logs(output, can, serial, signalmap=signalmap,
                                 dbc=parse_dbc_options(dbcs), progress=progress,
                                 metadata={"command": "vdps import " + " ".join(
                                     [*(f"--can {s}" for s in can_specs),
                                      *(f"--serial {s}" for s in serial_specs)])})
    except ImportError_ as e:
        raise UserError(str(e)) from None
    finally:
        stdin_dir.cleanup()
    eprint(f"vdps import: wrote {report['written']} messages to {output}"
           + (f" ({report['write_errors']} refused by the writer)" if report["write_errors"]
              else ""))
    for line in source_lines(report["sources"]):
        eprint(line)
    write_json(report, json_out)
