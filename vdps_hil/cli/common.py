"""Shared CLI pieces: one-line user errors, shared option decorators, JSON output."""

from __future__ import annotations

import contextlib
import json
import math
import os
import sys
from pathlib import Path

import click


class UserError(click.ClickException):
    """A mistake the person made (bad option, unreadable file): one line, exit status 2."""

    exit_code = 2

    def show(self, file=None) -> None:  # one line, no traceback
        click.echo(f"vdps: error: {self.format_message()}", err=True, file=file)


def _clean(o):
    if isinstance(o, float) and not math.isfinite(o):
        return None
    if isinstance(o, dict):
        return {str(k): _clean(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_clean(v) for v in o]
    if hasattr(o, "item") and callable(o.item):  # numpy scalars
        return _clean(o.item())
    return o


def require_file(path) -> None:
    """A one-line :class:`UserError` unless ``path`` is an existing regular file (a directory is
    said to be one)."""
    p = os.fspath(path)
    if os.path.isdir(p):
        raise UserError(f"{p}: is a directory, not a file")
    if not os.path.isfile(p):
        raise UserError(f"{p}: no such file")


def write_json(doc: dict, target: str | None) -> None:
    """Write ``doc`` as JSON to ``target`` (``-`` = stdout); non-finite floats become null."""
    if not target:
        return
    text = json.dumps(_clean(doc), indent=2, sort_keys=True)
    if target == "-":
        click.echo(text)
        return
    try:
        Path(target).write_text(text + "\n", encoding="utf-8")
    except OSError as e:
        raise UserError(f"cannot write {target}: {e.strerror or e}") from None


json_option = click.option("--json", "json_out", metavar="FILE", default=None,
                           help="Write a machine-readable summary to FILE ('-' for stdout).")
output_option = click.option("-o", "--output", "output", metavar="FILE", default=None,
                             help="Output file.")
seed_option = click.option("--seed", type=click.IntRange(0, None), default=0, show_default=True,
                           help="Seed of every random number generator.")


def vehicle_option(default: str, help_text: str):
    return click.option("--vehicle", "vehicle", metavar="FILE", default=default, show_default=True,
                        help=help_text)


def debug_enabled() -> bool:
    ctx = click.get_current_context(silent=True)
    while ctx is not None:
        if ctx.obj and isinstance(ctx.obj, dict) and "debug" in ctx.obj:
            return bool(ctx.obj["debug"])
        ctx = ctx.parent
    return False


def fail_user(exc: BaseException) -> None:
    """Turn a known error type into a one-line UserError (re-raise with --debug)."""
    if debug_enabled():
        raise exc
    raise UserError(str(exc).splitlines()[0] if str(exc) else exc.__class__.__name__) from None


def eprint(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def recorded_decoding(path, dbc=None, signalmap=None) -> tuple[str | None, str | None]:
    """(dbc, signalmap) to decode the recording at ``path`` with: the options when given, else
    the files its metadata names, found by path and content hash
    (``record.recorded_decoding``); a file that cannot be found is a one-line UserError."""
    from vdps_hil.record.reader import RecordingError, RecordingReader
    from vdps_hil.record.recorded_decoding import RecordedDecodingError, find_recorded_decoding

    if dbc is not None or signalmap is not None:
        return dbc, signalmap
    try:
        with RecordingReader(path) as reader:
            rd = find_recorded_decoding(reader, path)
    except (RecordingError, RecordedDecodingError) as e:
        raise UserError(str(e)) from None
    return rd.dbc, rd.signalmap


def recording_span_s(path) -> float | None:
    """The time a recording covers [s] from its MCAP statistics (first to last log time; None
    without a summary, e.g. a file cut off by a crash): the total of a progress bar."""
    from mcap.reader import make_reader

    try:
        with open(path, "rb") as f:
            st = make_reader(f).get_summary().statistics
        span = (st.message_end_time - st.message_start_time) / 1e9
    except Exception:  # noqa: BLE001 - no usable summary: a bar without a total
        return None
    return span if span > 0 else None


quiet_option = click.option("--quiet", "-q", is_flag=True, help="No progress bar on the terminal.")

serve_option = click.option(
    "--serve", "serve_port", type=click.IntRange(0, 65535), default=None, metavar="PORT",
    help="Also serve the topics live to Foxglove (WebSocket, ws://127.0.0.1:PORT only; 0: a free port; "
         "layout configs/foxglove/vdps-layout.json).")


@contextlib.contextmanager
def live_server(port: int | None, *, wait: bool):
    """The ``--serve`` server (``app.live_view.LiveServer``) around a command, or None; its URL on
    stderr; ``wait``: block until a client subscribes (a replay, so the view starts at the start)."""
    if port is None:
        yield None
        return
    from vdps_hil.app.live_view import LAYOUT_TOPICS, LiveServer, LiveServerError

    try:
        live = LiveServer(port)
    except LiveServerError as e:
        raise UserError(str(e)) from None
    with live:
        live.advertise(LAYOUT_TOPICS)
        eprint(f"serving on {live.url} (Foxglove: Open connection -> Foxglove WebSocket)"
               + ("; waiting for a client to subscribe" if wait else ""))
        while wait and not live.wait_for_subscriber(0.5):
            pass
        yield live
