"""``vdps plot FILE SIGNAL...``: signals of any recording against time, as a PNG or a
self-contained HTML page (the figure inline as SVG), like ``cantools plot`` on a log.

A SIGNAL is ``TOPIC.KEY`` (``/est/state.phi_v_rad``, ``/decoded/imu/imu.angular_rate_radps_z``,
``/est/tf.translation.x``): KEY is looked up in the message's ``values``, then ``fields``, then
as a dotted path from the message root; or a bare catalogue field name (``wheel_speed_radps_1``,
``steer_wheel_angle_rad``): the recording's ``/raw/`` topics decoded (with the signal map and DBC
its metadata names, ``record.recorded_decoding``), else its ``/decoded/`` topics. Time on the
x axis is seconds from the first plotted point (``t_ns``).
"""

from __future__ import annotations

import io
import math
import os
from typing import Iterable

__all__ = ["PlotError", "collect_series", "plot_signals", "recorded_samples", "write_figure"]


class PlotError(ValueError):
    """A signal that is not in the recording, an unreadable file, an unknown output type: one line."""


def _lookup(doc: dict, key: str) -> float | None:
    for part in ("values", "fields"):
        sub = doc.get(part)
        if isinstance(sub, dict) and key in sub:
            v = sub[key]
            return math.nan if v is None else float(v)
    node = doc
    for k in key.split("."):
        if not isinstance(node, dict) or k not in node:
            return None
        node = node[k]
    if isinstance(node, bool) or not isinstance(node, (int, float)):
        return None
    return float(node)


def _split(signal: str, topics: Iterable[str]) -> tuple[str, str] | None:
    """(topic, key) of ``TOPIC.KEY`` for the longest recorded topic that prefixes it."""
    best = None
    for t in topics:
        if signal.startswith(t + ".") and (best is None or len(t) > len(best)):
            best = t
    return None if best is None else (best, signal[len(best) + 1:])


def recorded_samples(reader, path):
    """The bus samples of a recording (``reader`` of the file at ``path``): its ``/raw/`` topics
    decoded with the signal map and DBC its metadata names, else its ``/decoded/`` topics.
    PlotError (one line) when the recorded decoding cannot be found."""
    from vdps_hil.record import schemas as S
    from vdps_hil.record.decode import DecodeError, decode_recording
    from vdps_hil.record.recorded_decoding import RecordedDecodingError, find_recorded_decoding

    if not any(t.startswith(S.RAW_PREFIX) for t in reader.topics()):
        return reader.iter_samples()
    try:
        rd = find_recorded_decoding(reader, path)
        return decode_recording(reader, dbc=rd.dbc, signalmap=rd.signalmap)
    except (RecordedDecodingError, DecodeError) as e:
        raise PlotError(str(e).splitlines()[0]) from None


def _decoded_fields(reader, path, names: set[str]) -> dict[str, tuple[list, list]]:
    out: dict[str, tuple[list, list]] = {}
    for s in recorded_samples(reader, path):
        for n in names.intersection(s.fields):
            ts, vs = out.setdefault(n, ([], []))
            ts.append(s.t_ns)
            vs.append(s.fields[n])
    return out


def collect_series(path, signals: list[str]) -> dict[str, tuple[list[float], list[float]]]:
    """{signal: (t [s] from the first message, values)} for each SIGNAL (module docstring)."""
    from vdps_hil.record.reader import RecordingError, RecordingReader

    try:
        reader = RecordingReader(path)
    except RecordingError as e:
        raise PlotError(str(e)) from None
    with reader:
        topics = reader.topics()
        on_topic = {s: _split(s, topics) for s in signals if s.startswith("/")}
        missing = [s for s, where in on_topic.items() if where is None]
        if missing:
            raise PlotError(f"{missing[0]}: no such topic in {os.fspath(path)} (topics: "
                            f"{', '.join(t for t in topics if not t.startswith('/raw/'))[:300]})")
        got: dict[str, tuple[list, list]] = {}
        wanted = {}
        for s, (topic, key) in on_topic.items():
            wanted.setdefault(topic, []).append((s, key))
        if wanted:
            for topic, t_ns, doc in reader.iter_messages(topics=list(wanted)):
                for s, key in wanted[topic]:
                    v = _lookup(doc, key)
                    if v is not None:
                        ts, vs = got.setdefault(s, ([], []))
                        ts.append(t_ns)
                        vs.append(v)
        bare = {s for s in signals if not s.startswith("/")}
        if bare:
            got.update(_decoded_fields(reader, path, bare))
        for s in signals:
            if not got.get(s, ((),))[0]:
                raise PlotError(f"{s}: not found in {os.fspath(path)} (give TOPIC.KEY, e.g. /est/state.phi_v_rad, "
                                "or a decoded field name, e.g. wheel_speed_radps_1)")
        t0 = min(ts[0] for ts, _ in got.values() if ts)
    return {s: ([(t - t0) / 1e9 for t in got[s][0]], got[s][1]) for s in signals}


def write_figure(series: dict[str, tuple[list[float], list[float]]], output, title: str) -> None:
    """One axis per signal, shared time; ``output`` ``.png`` or ``.html`` (SVG inline)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    kind = os.path.splitext(os.fspath(output))[1].lower()
    if kind not in (".png", ".html"):
        raise PlotError(f"-o {output}: give a .png or .html file")
    fig, axes = plt.subplots(len(series), 1, sharex=True, squeeze=False, figsize=(10, 2.2 * len(series) + 0.8))
    for ax, (name, (t, v)) in zip(axes[:, 0], series.items()):
        ax.plot(t, v, lw=0.9)
        ax.set_ylabel(name, fontsize=8)
        ax.grid(True, alpha=0.3)
    axes[-1, 0].set_xlabel("time [s]")
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    try:
        if kind == ".png":
            fig.savefig(output, dpi=100)
        else:
            buf = io.StringIO()
            fig.savefig(buf, format="svg")
            svg = buf.getvalue()
            svg = svg[svg.find("<svg"):]
            with open(output, "w", encoding="utf-8") as f:
                f.write(f"<!DOCTYPE html>\n<html><head><meta charset='utf-8'><title>{_escape(title)}</title></head>"
                        f"<body>\n{svg}\n</body></html>\n")
    except OSError as e:
        raise PlotError(f"cannot write {output}: {e.strerror or e}") from None
    finally:
        plt.close(fig)


def _escape(s: str) -> str:
    return s.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")


def plot_signals(path, signals: list[str], output) -> dict:
    """Collect and write; returns {signal: number of points}."""
    series = collect_series(path, signals)
    write_figure(series, output, f"{os.path.basename(os.fspath(path))}: {', '.join(signals)}")
    return {s: len(v[0]) for s, v in series.items()}
