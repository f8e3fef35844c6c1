"""``vdps log``: record live CAN buses and serial devices into one MCAP until Ctrl-C, SIGTERM
or ``--duration``, with a live one-line status per source."""

from __future__ import annotations

import contextlib
import math
import os
import signal
import sys
import threading
import time

import click

from vdps_hil.cli.common import UserError, eprint, json_option, live_server, serve_option, write_json
from vdps_hil.cli.import_cmd import parse_dbc_options, parse_format_options

__all__ = ["log", "build_live_adapters"]


def build_live_adapters(can_specs, serial_specs, formats, signalmap, dbcs):
    """Adapters for ``--can BUS=SPEC`` and ``--serial NAME=PORT[@BAUD]`` and the decoding
    info; raises UserError (one line) for a person's mistake."""
    from vdps_hil.adapters.base import AdapterError
    from vdps_hil.adapters.can_adapter import CanAdapter
    from vdps_hil.adapters.imu_adapter import ImuAdapter
    from vdps_hil.adapters.nmea_adapter import NmeaAdapter
    from vdps_hil.adapters.serial_adapter import parse_port_spec
    from vdps_hil.adapters.signalmap import SignalMapError, load_signalmap
    from vdps_hil.codecs.imu_mtdata2 import DEFAULT_BAUD as IMU_BAUD
    from vdps_hil.record.importer import ImportError_, _can_decoder, serial_format
    from vdps_hil.record.schemas import check_name

    fmts = parse_format_options(formats)
    dbc = parse_dbc_options(dbcs)
    try:
        sigmap = load_signalmap(signalmap) if signalmap else None
    except SignalMapError as e:
        raise UserError(str(e)) from None
    adapters, info = [], {}
    if sum(s.partition("=")[2].partition("@")[0] == "-" for s in can_specs) > 1:
        raise UserError("--can BUS=-: standard input can feed one bus only")
    try:
        for spec in can_specs:
            if "=" not in spec:
                raise UserError(f"--can {spec!r}: expected BUS=INTERFACE:CHANNEL "
                                "(e.g. vdps=socketcan:can0)")
            bus, iface = spec.split("=", 1)
            check_name("bus", bus)
            dec, _ = _can_decoder(bus, sigmap, dbc, info)  # a map's log channel: files only
            stdin = iface == "-" or iface.startswith("-@")
            adapters.append(_stdin_adapter(bus, dec, iface[2:]) if stdin else CanAdapter(bus, iface, decoder=dec))
        for spec in serial_specs:
            if "=" not in spec:
                raise UserError(f"--serial {spec!r}: expected NAME=PORT[@BAUD]")
            name, port_spec = spec.split("=", 1)
            check_name("device", name)
            fmt = serial_format(name, fmts.get(name))
            if fmt == "imu":
                port, baud = parse_port_spec(port_spec, IMU_BAUD)
                adapters.append(ImuAdapter(name, port, baud))
            else:
                port, baud = parse_port_spec(port_spec)
                adapters.append(NmeaAdapter(name, port, baud))
            info[name] = {"format": fmt, "port": port, "baud": baud}
    except (AdapterError, ImportError_, ValueError) as e:
        raise UserError(str(e).splitlines()[0]) from None
    names = [a.name for a in adapters]
    if len(set(names)) != len(names):
        raise UserError(f"two sources share a name: {', '.join(names)}")
    meta_sm = None if sigmap is None else {"name": sigmap.name, "path": str(sigmap.path),
                                          "sha256": sigmap.sha256}
    return adapters, info, meta_sm


def _stdin_adapter(bus: str, decoder, channel: str):
    """``--can BUS=-[@CHANNEL]``: candump -L lines on standard input (``adapters.candump_stream``);
    with ``@CHANNEL`` only that candump channel is ``BUS``, the others are recorded raw as
    ``BUS.<channel>`` (``candump -L any``)."""
    import sys

    from vdps_hil.adapters.can_adapter import CanAdapter
    from vdps_hil.adapters.candump_stream import CandumpStreamBus

    return CanAdapter(bus, None, decoder=decoder, bus=CandumpStreamBus(sys.stdin.buffer),
                      decode_channels=[channel] if channel else None)


class RecordingStopped(UserError):
    """The file system refused the recording (disk full): one line, exit status 1; the file
    holds everything up to there (``vdps recover`` closes it)."""

    exit_code = 1


class _Status:
    """Live status on stderr: rewritten in place on a terminal, a line per source every
    ``every_s`` otherwise."""

    def __init__(self, quiet: bool, every_s: float = 5.0):
        self.quiet = quiet
        self.tty = sys.stderr.isatty()
        self.every_s = every_s
        self._n = 0
        self._last = 0.0

    def __call__(self, lines):
        if self.quiet:
            return
        if self.tty:
            if self._n:
                sys.stderr.write(f"\x1b[{self._n}F")
            for ln in lines:
                sys.stderr.write("\x1b[2K" + ln[:200] + "\n")
            sys.stderr.flush()
            self._n = len(lines)
        else:
            now = time.monotonic()
            if now - self._last >= self.every_s:
                self._last = now
                for ln in lines:
                    eprint(ln)


@click.command("log")
@click.option("--can", "can_specs", multiple=True, metavar="BUS=INTERFACE:CHANNEL",
              help="A live CAN bus: any python-can interface string (socketcan:can0, "
                   "pcan:PCAN_USBBUS1,bitrate=500000, slcan:/dev/ttyACM0, virtual:hil); "
                   "'-[@CHANNEL]': candump -L lines on standard input (candump -L can0 | vdps log --can pt=- ...).")
@click.option("--serial", "serial_specs", multiple=True, metavar="NAME=PORT[@BAUD]",
              help="A serial device (NMEA GNSS, or the IMU when NAME starts with imu).")
@click.option("--format", "formats", multiple=True, metavar="NAME=nmea|imu",
              help="Protocol of a --serial device (default by NAME).")
@click.option("--dbc", "dbcs", multiple=True, metavar="[BUS=]FILE", help="DBC of a bus.")
@click.option("--signalmap", metavar="FILE|NAME", default=None,
              help="Signal map for the CAN buses (a bus named vdps uses the vdps map).")
@click.option("-o", "--output", required=True, metavar="FILE.mcap", help="Recording to write.")
@click.option("--duration", type=float, default=None, metavar="S",
              help="Stop after S seconds (default: until Ctrl-C or SIGTERM).")
@click.option("--rotate-mb", type=float, default=None, metavar="MB",
              help="Start a new file (FILE_0000.mcap, ...) every MB megabytes.")
@click.option("--rotate-s", type=float, default=None, metavar="S",
              help="Start a new file every S seconds of data.")
@click.option("--flush-s", type=float, default=0.5, show_default=True, metavar="S",
              help="Close the MCAP chunk in progress every S seconds (a crash loses at most "
                   "about that much).")
@click.option("--reserve-mb", type=float, default=64.0, show_default=True, metavar="MB",
              help="When less than MB is left on the disk, decoded topics stop (counted) and the "
                   "rest is kept for the raw topics.")
@click.option("--decode-lag-s", type=float, default=2.0, show_default=True, metavar="S",
              help="Records read more than S seconds ago are recorded raw but not decoded "
                   "(counted as decoded_skipped): how far decoding may fall behind the readers.")
@click.option("--quiet", is_flag=True, help="No live status.")
@click.option("--pipeline", is_flag=True,
              help="Run the estimator, identifier, predictor and warning live on the decoded "
                   "samples (configured as vdps replay does, from the first 3 s of data); its "
                   "estimates and warning frames are recorded under /est/, the latest warning "
                   "shows in the status line, and the input order is recorded so `vdps replay "
                   "FILE --input-order recorded` reproduces the run (not with --rotate-mb/-s).")
@click.option("--vehicle", default="sedan-model", show_default=True, metavar="FILE",
              help="Model vehicle file for --pipeline.")
@click.option("--params", default=None, metavar="FILE",
              help="--pipeline starts from saved identified parameters (vdps replay --save-params): "
                   "warnings valid at once [default: the priors, valid once the cornering stiffnesses converge].")
@json_option
@serve_option
def log(can_specs, serial_specs, formats, dbcs, signalmap, output, duration, rotate_mb,
        rotate_s, flush_s, reserve_mb, decode_lag_s, quiet, pipeline, vehicle, params, json_out,
        serve_port):
    """Record live CAN buses and serial devices losslessly into one MCAP.

    \b
    Example:
      vdps log --can vdps=socketcan:can0 --serial gnss=/dev/ttyUSB0@115200 \\
               --serial imu=/dev/ttyUSB1@921600 -o track.mcap
    Raw frames and bytes always go to /raw/..., decoded samples to /decoded/..., GNSS fixes
    to /gnss/fix (Foxglove map), health to /health/... . Each device is drained by a reader
    of its own; raw records are written first, decoding and --pipeline come after and lose
    their own work (counted) when they fall behind, never the raw records. The status shows
    per device what was lost and where (os, reader, seq counters, decode skipped). Stops
    cleanly on Ctrl-C, SIGTERM or --duration; a killed logger's file is rescued by `vdps
    recover`.
    """
    from vdps_hil.app.session import LogSession, start_readers

    _check_options(can_specs, serial_specs, duration, flush_s, rotate_mb, rotate_s, decode_lag_s)
    if reserve_mb < 0:
        raise UserError("--reserve-mb must not be negative")
    _pipeline_start(pipeline, vehicle, params)  # the files checked before a device opens
    adapters, info, sigmap = build_live_adapters(can_specs, serial_specs, formats, signalmap,
                                                 dbcs)
    _open_adapters(adapters)  # devices first: a bad port fails before a file is created
    start_readers(adapters)  # and drained from now on
    with _stop_on_signals() as stop:  # before the file appears: from then on SIGTERM stops cleanly
        writer = _open_writer(output, rotate_mb, rotate_s, adapters,
                              _recording_metadata(can_specs, serial_specs, adapters, info, sigmap),
                              _content_hashes(info, sigmap))
        tap = None
        if pipeline:  # a process of its own; a rotated recording gets no input order (PipelineTap)
            from vdps_hil.app.tap_process import TapProcess

            tap = TapProcess(vehicle, params, writer, record_order=not (rotate_mb or rotate_s),
                             params_file=None if params is None else os.path.basename(params))
        session = LogSession(adapters, writer, flush_s=flush_s, status=_Status(quiet), tap=tap,
                             reserve_bytes=int(reserve_mb * 1e6), decode_lag_s=decode_lag_s)
        if tap is not None:
            tap.recording_allowed = lambda: session.decoded_ok
        try:
            with live_server(serve_port, wait=False) as live:
                writer.mirror = None if live is None else live.mirror
                summary = session.run(stop, duration)
                writer.mirror = None
            if tap is not None and session.tap is tap:  # a tap that failed wrote no order
                _finish_tap(tap, session, summary)
        finally:
            writer.close()
    _report(summary, getattr(writer, "files", [output]), session, tap, quiet, json_out)
    if summary.get("fatal"):
        raise RecordingStopped(summary["fatal"])


@contextlib.contextmanager
def _stop_on_signals():
    """An event set by SIGINT or SIGTERM while in the block (the handlers before it restored
    after)."""
    stop = threading.Event()
    old = {s: signal.signal(s, lambda signum, frame: stop.set()) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield stop
    finally:
        for s, h in old.items():
            signal.signal(s, h)


MAX_DECODE_LAG_S = 600.0
"""--decode-lag-s at most: the backlog it allows is held in memory."""


def _check_options(can_specs, serial_specs, duration, flush_s, rotate_mb, rotate_s,
                   decode_lag_s: float = 2.0) -> None:
    """UserError unless there is something to log and every given duration or size is a finite
    positive number (``--rotate-mb 0`` would otherwise silently mean "no rotation"), the decode
    lag limit at most ``MAX_DECODE_LAG_S``."""
    if not can_specs and not serial_specs:
        raise UserError("nothing to log: give --can BUS=INTERFACE:CHANNEL and/or "
                        "--serial NAME=PORT[@BAUD]")
    for name, v in (("--duration", duration), ("--flush-s", flush_s), ("--rotate-mb", rotate_mb),
                    ("--rotate-s", rotate_s), ("--decode-lag-s", decode_lag_s)):
        if v is not None and not (math.isfinite(v) and v > 0):
            raise UserError(f"{name} must be a finite positive number, got {v:g}")
    if decode_lag_s > MAX_DECODE_LAG_S:
        raise UserError(f"--decode-lag-s must be at most {MAX_DECODE_LAG_S:g} s (the backlog is "
                        f"held in memory), got {decode_lag_s:g}")
    if rotate_mb is not None and rotate_mb * 1e6 < 1000:
        raise UserError(f"--rotate-mb must be at least 0.001 (1 kB), got {rotate_mb:g}")


def _pipeline_start(pipeline: bool, vehicle: str, params: str | None):
    """(model vehicle, start parameters or None) for ``--pipeline`` ((None, None) without it);
    UserError for an unusable vehicle or parameter file, or ``--params`` without ``--pipeline``."""
    if not pipeline:
        if params is not None:
            raise UserError("--params applies to --pipeline")
        return None, None
    from vdps_hil.model.params import VehicleFileError, load_vehicle

    try:
        model = load_vehicle(vehicle, expect_kind="model")
    except VehicleFileError as e:
        raise UserError(str(e)) from None
    start = None
    if params is not None:
        from vdps_hil.identification.persistence import ParamsFileError, load_params

        try:
            start = load_params(params, model).params
        except ParamsFileError as e:
            raise UserError(str(e).splitlines()[0]) from None
    return model, start


def _open_adapters(adapters) -> None:
    """Open every device; on the first that fails close them all (UserError)."""
    from vdps_hil.adapters.base import AdapterError

    for a in adapters:
        try:
            a.open()
        except AdapterError as e:
            for b in adapters:
                b.close()
            raise UserError(str(e)) from None


def _content_hashes(info: dict, sigmap: dict | None) -> dict:
    """The files whose hashes the recording's metadata carries (DBCs, the signal map)."""
    hashes = {f"dbc.{b}": i["dbc"] for b, i in info.items() if i.get("dbc")}
    if sigmap:
        hashes["signalmap"] = sigmap["path"]
    return hashes


def _recording_metadata(can_specs, serial_specs, adapters, info: dict, sigmap: dict | None) -> dict:
    """The ``vdps.recording`` metadata of a live recording: command, sources, decoding, host."""
    md = {"mode": "log", "command": "vdps log " + " ".join(
        [*(f"--can {s}" for s in can_specs), *(f"--serial {s}" for s in serial_specs)]),
        "sources": {a.name: a.device for a in adapters}, "decoding": info,
        "host": os.uname().nodename if hasattr(os, "uname") else ""}
    if sigmap:
        md["signalmap"] = sigmap
    return md


def _open_writer(output, rotate_mb, rotate_s, adapters, md: dict, hashes: dict):
    """The recording writer (rotating with ``--rotate-mb/-s``); on failure the devices are
    closed (UserError)."""
    from vdps_hil.record.writer import RecordingWriter

    try:
        if rotate_mb or rotate_s:
            from vdps_hil.record.rotation import RotatingRecordingWriter

            return RotatingRecordingWriter(
                output, max_bytes=None if not rotate_mb else int(rotate_mb * 1e6),
                max_s=rotate_s, metadata=md, content_hashes=hashes)
        return RecordingWriter(output, metadata=md, content_hashes=hashes)
    except (OSError, ValueError) as e:
        for a in adapters:
            a.close()
        raise UserError(f"cannot write {output}: {getattr(e, 'strerror', None) or e}") from None


def _finish_tap(tap, session, summary: dict) -> None:
    """The pipeline's last outputs and input order (before the writer closes); a failure is one
    more reader error, the recording is closed properly whatever it does."""
    try:
        tap.finish()
    except Exception as e:  # noqa: BLE001 - the recording is closed properly whatever it does
        session.errors.append(f"tap: {type(e).__name__}: {e}")
        summary["reader_errors"] = list(session.errors)


def _report(summary: dict, files: list, session, tap, quiet: bool, json_out) -> None:
    """The closing lines on stderr and the ``--json`` summary."""
    if not quiet:
        lost = {src: {k: v for k, v in d.items() if k in ("os", "reader", "sequence",
                                                           "decoded_skipped") and v}
                for src, d in summary["loss"].items()}
        lost = {k: v for k, v in lost.items() if v}
        eprint(f"vdps log: {summary['written']} messages in {summary['duration_s']:.1f} s to "
               f"{', '.join(files)}; lost: {lost or 'nothing'}")
        for ln in session.status_lines():
            eprint("  " + ln)
    summary["files"] = files
    if tap is not None:
        summary["pipeline"] = tap.summary()
    write_json(summary, json_out)
