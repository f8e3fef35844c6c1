"""Import logs from other tools into the recording layout (``vdps import``).

CAN logs are read with python-can's readers (``can.LogReader``): Vector ``.asc`` and ``.blf``,
candump ``-L`` ``.log``, PCAN ``.trc``, ASAM MDF4 ``.mf4`` (through asammdf), python-can
``.csv`` and ``.db``, and our own ``.mcap``. Serial logs are NMEA/ASCII text (time stamps:
:mod:`vdps_hil.adapters.nmea_adapter`) or binary IMU captures (wire time at the baud).

Every frame and every line goes to ``/raw/...`` unchanged; decoded samples go beside them
through exactly the code a live log uses (the same adapters, decoders and health counters), so
an imported file and a live one are read the same way. Sources are imported one after the
other; within a source, records keep the file's order (a time going backwards is counted, the
record kept). Times are the file's own: ``t_ns = round(timestamp * 1e9)`` and the MCAP
``log_time`` is the same number (a candump log of seconds since boot shows in Foxglove near
1970-01-01; an epoch-stamped log shows its real date).

Decoding CAN: ``--signalmap`` (a map from ``configs/signalmaps`` by name, or a file) says
which frames feed which bus fields; ``--dbc`` gives the DBC (all buses, or ``BUS=FILE``).
Without a signal map, a bus decodes with the project's ``dbc/vdps.dbc`` (map ``vdps``) only if
it is named ``vdps``; other buses are recorded raw.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Sequence

from vdps_hil.adapters.base import Adapter, AdapterError, EndOfInput
from vdps_hil.record.recorder import Recorder

__all__ = ["CanSource", "SerialSource", "ImportError_", "import_logs", "parse_can_source",
           "parse_serial_source", "SERIAL_FORMATS"]

SERIAL_FORMATS = ("nmea", "imu")


class ImportError_(ValueError):
    """An import that cannot start (bad option, unreadable map or DBC): one line."""


@dataclass(frozen=True)
class CanSource:
    """``--can BUS=FILE[@CHANNEL]``: the frames of ``FILE`` (only channel ``CHANNEL`` when
    given) as bus ``BUS``."""

    bus: str
    path: str
    channel: str | None = None


@dataclass(frozen=True)
class SerialSource:
    """``--serial NAME=FILE[@BAUD]``: a serial log as device ``NAME``; ``fmt`` ``nmea`` (text)
    or ``imu`` (binary MTi capture); by default ``imu`` when NAME starts with ``imu``."""

    name: str
    path: str
    baud: int | None = None
    fmt: str | None = None


def _split_eq(opt: str, spec: str) -> tuple[str, str]:
    if "=" not in spec:
        raise ImportError_(f"{opt} {spec!r}: expected NAME=FILE")
    name, rest = spec.split("=", 1)
    name = name.strip()
    if not name or not rest:
        raise ImportError_(f"{opt} {spec!r}: expected NAME=FILE")
    from vdps_hil.record.schemas import check_name

    try:
        check_name("bus/device", name)
    except ValueError as e:
        raise ImportError_(f"{opt} {spec!r}: {e}") from None
    return name, rest


def parse_can_source(spec: str) -> CanSource:
    bus, rest = _split_eq("--can", spec)
    channel = None
    if "@" in rest and not os.path.exists(rest):
        rest, channel = rest.rsplit("@", 1)
    return CanSource(bus, rest, channel)


def parse_serial_source(spec: str, fmt: str | None = None) -> SerialSource:
    name, rest = _split_eq("--serial", spec)
    baud = None
    if "@" in rest and not os.path.exists(rest):
        rest, b = rest.rsplit("@", 1)
        try:
            baud = int(b)
        except ValueError:
            raise ImportError_(f"--serial {spec!r}: baud {b!r} is not an integer") from None
        if baud <= 0:
            raise ImportError_(f"--serial {spec!r}: baud must be positive")
    if fmt is not None and fmt not in SERIAL_FORMATS:
        raise ImportError_(f"serial format {fmt!r} unknown (known: {', '.join(SERIAL_FORMATS)})")
    return SerialSource(name, rest, baud, fmt)


def serial_format(name: str, fmt: str | None) -> str:
    return fmt if fmt else ("imu" if name.lower().startswith("imu") else "nmea")


def _can_decoder(bus: str, sigmap, dbc: dict[str, str], info: dict):
    """(decoder or None, decode channel) of one bus; fills ``info`` for the metadata."""
    from vdps_hil.adapters.signalmap import SignalMapError, load_signalmap
    from vdps_hil.adapters.signalmap_decoder import build_decoder

    dbc_path = dbc.get(bus, dbc.get("*"))
    try:
        if sigmap is None and bus == "vdps":
            sigmap = load_signalmap("vdps")
        if sigmap is None:
            if dbc_path is not None:
                raise ImportError_(f"--dbc given for bus {bus} but no --signalmap saying which "
                                   "frames feed which fields (see configs/signalmaps/)")
            info[bus] = {"decoded": False, "reason": "no signal map"}
            return None, None
        dec, binfo = build_decoder(sigmap, bus, dbc_path)
    except SignalMapError as e:
        raise ImportError_(str(e)) from None
    if dec is None:
        info[bus] = {"decoded": False, "reason": f"signal map {sigmap.name} has no bus {bus}"}
        return None, None
    binfo["decoded"] = True
    info[bus] = binfo
    return dec, binfo.get("channel")


def build_adapters(can: Sequence[CanSource] = (), serial: Sequence[SerialSource] = (), *,
                   signalmap: str | os.PathLike | None = None,
                   dbc: dict[str, str] | None = None) -> tuple[list[Adapter], dict]:
    """File adapters for the sources, with their decoders; and the decoding info per bus."""
    from vdps_hil.adapters.can_adapter import CanFileAdapter
    from vdps_hil.adapters.imu_adapter import ImuFileAdapter
    from vdps_hil.adapters.nmea_adapter import NmeaTextFileAdapter
    from vdps_hil.adapters.signalmap import SignalMapError, load_signalmap

    dbc = dict(dbc or {})
    sigmap = None
    if signalmap is not None:
        try:
            sigmap = load_signalmap(signalmap)
        except SignalMapError as e:
            raise ImportError_(str(e)) from None
    info: dict = {}
    adapters: list[Adapter] = []
    for src in can:
        if not os.path.isfile(src.path):
            raise ImportError_(f"--can {src.bus}: no such file {src.path}")
        dec, chan = _can_decoder(src.bus, sigmap, dbc, info)
        adapters.append(CanFileAdapter(src.bus, src.path, decoder=dec,
                                       channels=None if src.channel is None else [src.channel],
                                       decode_channels=None if chan is None else [chan]))
    for src in serial:
        if not os.path.isfile(src.path):
            raise ImportError_(f"--serial {src.name}: no such file {src.path}")
        fmt = serial_format(src.name, src.fmt)
        if fmt == "imu":
            from vdps_hil.codecs.imu_mtdata2 import DEFAULT_BAUD as IMU_BAUD

            adapters.append(ImuFileAdapter(src.name, src.path, src.baud or IMU_BAUD))
        else:
            adapters.append(NmeaTextFileAdapter(src.name, src.path, src.baud or 115200))
        info[src.name] = {"format": fmt, "path": src.path}
    names = [a.name for a in adapters]
    if len(set(names)) != len(names):
        raise ImportError_(f"two sources share a name: {', '.join(names)}")
    return adapters, {"buses": info, "signalmap": None if sigmap is None else
                      {"name": sigmap.name, "path": str(sigmap.path), "sha256": sigmap.sha256}}


def import_logs(output: str | os.PathLike, can: Sequence[CanSource] = (),
                serial: Sequence[SerialSource] = (), *,
                signalmap: str | os.PathLike | None = None, dbc: dict[str, str] | None = None,
                metadata: dict | None = None, progress=None) -> dict:
    """Import the sources into ``output`` (MCAP). Returns a report: per-source health, messages
    written, write errors. Raises ImportError_ (one line) before anything is written when a
    source, the map or a DBC cannot be used; a broken source file met while reading ends that
    source (counted ``read_errors``), the others are still imported.
    """
    from vdps_hil.record.writer import RecordingWriter

    if not can and not serial:
        raise ImportError_("nothing to import: give --can BUS=FILE and/or --serial NAME=FILE")
    adapters, info = build_adapters(can, serial, signalmap=signalmap, dbc=dbc)
    for a in adapters:
        try:
            a.open()
        except AdapterError as e:
            for b in adapters:
                b.close()
            raise ImportError_(str(e)) from None
    hashes: dict = {}
    for bus, bi in info["buses"].items():
        if bi.get("dbc"):
            hashes[f"dbc.{bus}"] = bi["dbc"]
        if bi.get("path"):
            hashes[f"input.{bus}"] = bi["path"]
    for src in can:
        hashes[f"input.{src.bus}"] = src.path
    if info["signalmap"] is not None:
        hashes["signalmap"] = info["signalmap"]["path"]
    md = {"mode": "import", "sources": {a.name: a.device for a in adapters},
          "decoding": info["buses"]}
    if info["signalmap"] is not None:
        md["signalmap"] = info["signalmap"]
    md.update(metadata or {})
    try:
        writer = RecordingWriter(output, metadata=md, content_hashes=hashes)
    except OSError as e:
        for a in adapters:
            a.close()
        raise ImportError_(f"cannot write {output}: {e.strerror or e}") from None
    rec = Recorder(writer)
    from vdps_hil.bus.subscription import Subscription

    try:
        for a in adapters:
            sub = a.subscribe(Subscription(f"import-{a.name}", 1 << 30))
            while True:
                try:
                    n = a.poll(0.0)
                except EndOfInput:
                    break
                rec.write_many(sub.drain())
                if n == 0 and not a.is_open:
                    break
                if progress is not None:
                    progress(a)
            rec.write_many(sub.drain())
            rec.write_health([a])
            a.close()
            a.unsubscribe(sub)
        rec.write_final_health(adapters)
    finally:
        for a in adapters:
            a.close()
        writer.close()
    return {"output": os.fspath(output), "written": rec.written,
            "write_errors": rec.write_errors, "problems": rec.problems,
            "sources": {a.name: a.status() for a in adapters}, "decoding": info["buses"]}
