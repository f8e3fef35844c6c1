"""``vdps info``: what a recording holds -- topics, counts, rates, duration, gaps, per-source
health (decode counters, and where data was lost: the OS, our reader, the devices' sequence
counters, decoding skipped) and the catalogue fields it provides."""

from __future__ import annotations

import json
import os

import click

from vdps_hil.cli.common import UserError, json_option, require_file, write_json

__all__ = ["info", "summarize"]

GAP_PERIODS = 10.0
"""An interval longer than this many median periods of its topic is a gap (decoded, GNSS and
health topics; a raw bus or byte stream mixes many rates, so only its longest silence is
shown)."""


def _topic_stats(ts: list[int], count_gaps: bool = True) -> dict:
    import numpy as np

    t = np.asarray(ts, dtype=np.int64)
    out = {"count": int(t.size), "first_t_ns": int(t[0]), "last_t_ns": int(t[-1]),
           "rate_hz": 0.0, "median_period_s": None, "max_gap_s": 0.0, "gaps": 0}
    if t.size >= 2:
        d = np.diff(t)
        span = (t[-1] - t[0]) / 1e9
        out["rate_hz"] = (t.size - 1) / span if span > 0 else 0.0
        pos = d[d > 0]
        if pos.size:
            med = float(np.median(pos))
            out["median_period_s"] = med / 1e9
            out["max_gap_s"] = float(d.max()) / 1e9
            out["gaps"] = int(np.count_nonzero(d > GAP_PERIODS * med)) if count_gaps else None
    return out


def summarize(path: str | os.PathLike) -> dict:
    """Everything ``vdps info`` prints, as a dict (raises RecordingError for a non-MCAP)."""
    from vdps_hil.record.recorder import HEALTH_METADATA, HEALTH_PREFIX
    from vdps_hil.bus.samples import FIELDS
    from vdps_hil.record import schemas as S
    from vdps_hil.record.reader import RecordingReader

    with RecordingReader(path) as r:
        topics = r.topics()
        md = r.metadata()
        times: dict[str, list[int]] = {t: [] for t in topics}
        fields: dict[str, dict[str, int]] = {}
        health_msgs: dict[str, dict] = {}
        invalid: dict[str, int] = {}
        for rec in r.iter_records():
            times[rec.topic].append(rec.t_ns)
            if rec.topic.startswith(S.DECODED_PREFIX):
                try:
                    doc = json.loads(rec.data)
                except ValueError:
                    continue
                src = rec.topic[len(S.DECODED_PREFIX):]
                for f, v in doc.get("fields", {}).items():
                    if v is not None:
                        d = fields.setdefault(f, {})
                        d[src] = d.get(src, 0) + 1
                if doc.get("valid") is False:
                    invalid[rec.topic] = invalid.get(rec.topic, 0) + 1
            elif rec.topic.startswith(HEALTH_PREFIX):
                try:
                    health_msgs[rec.topic[len(HEALTH_PREFIX):]] = json.loads(rec.data)
                except ValueError:
                    pass
        truncated, problems = r.truncated, list(r.problems)
    stats = {t: _topic_stats(ts, not t.startswith(S.RAW_PREFIX))
             for t, ts in times.items() if ts}
    for t, n in invalid.items():
        stats[t]["invalid"] = n
    firsts = [s["first_t_ns"] for s in stats.values()]
    lasts = [s["last_t_ns"] for s in stats.values()]
    health = {}
    for src, text in md.get(HEALTH_METADATA, {}).items():
        if src == "recorder":
            continue
        try:
            health[src] = json.loads(text)
        except ValueError:
            pass
    for src, doc in health_msgs.items():  # a file cut off before the end: last health message
        health.setdefault(src, doc)
    for doc in health.values():
        if isinstance(doc, dict):
            doc["loss"] = loss_of(doc)
    rec_md = md.get(S.METADATA_NAME, {})
    return {
        "path": os.fspath(path), "bytes": os.path.getsize(path), "truncated": truncated,
        "problems": problems, "layout_version": rec_md.get("layout_version"),
        "tool_version": rec_md.get("tool_version"), "mode": rec_md.get("mode"),
        "duration_s": (max(lasts) - min(firsts)) / 1e9 if firsts else 0.0,
        "first_t_ns": min(firsts) if firsts else None,
        "last_t_ns": max(lasts) if lasts else None,
        "topics": {t: {"schema": topics[t].schema, **stats.get(t, {"count": 0})}
                   for t in topics},
        "health": health,
        "fields": {f: fields[f] for f in sorted(fields)},
        "fields_not_in_catalogue": sorted(f for f in fields if f not in FIELDS),
        "hashes": {k: v for k, v in rec_md.items() if k.startswith("hash.")},
        "metadata": md,
    }


def loss_of(h: dict) -> dict:
    """Where a source lost data (``adapters.health.LOSS_STAGES``): the recorded ``loss`` of a
    source's health, or the same sums from its counters (recordings made before it existed)."""
    from vdps_hil.adapters.health import LOSS_STAGES

    if isinstance(h.get("loss"), dict):
        return h["loss"]
    c = h.get("counters", {})
    out = {stage: sum(c.get(k, 0) for k in names) for stage, names in LOSS_STAGES.items()}
    out["detail"] = {k: c[k] for names in LOSS_STAGES.values() for k in names if c.get(k)}
    out["os_counters"] = "not recorded"
    return out


def _health_line(src: str, h: dict) -> str:
    from vdps_hil.adapters.health import DROP_COUNTERS, ERROR_COUNTERS

    c = h.get("counters", {})
    errs = {k: v for k, v in c.items() if k in ERROR_COUNTERS and v}
    notes = {k: c[k] for k in ("unknown_id", "unknown_id_extended", "unsupported", "unmapped",
                               "other_channel", "outages", "reconnects", "time_clamped",
                               "comments", "invalid_samples") if c.get(k)}
    drops = sum(c.get(k, 0) for k in DROP_COUNTERS)
    s = (f"  {src}: records {h.get('records', '?')}, samples {h.get('samples', '?')}, "
         f"drops {drops}, errors {sum(errs.values())}")
    if errs:
        s += " " + json.dumps(errs, sort_keys=True)
    if notes:
        s += "; " + ", ".join(f"{k} {v}" for k, v in notes.items())
    if h.get("outage_s"):
        s += f"; outage {h['outage_s']:.2f} s"
    lo = loss_of(h)
    os_ = lo.get("os", 0) if lo.get("os_counters") == "yes" else "?"
    s += (f"\n    lost: os {os_}, reader {lo.get('reader', 0)}, seq counters "
          f"{lo.get('sequence', 0)}; decoding skipped {lo.get('decoded_skipped', 0)}")
    if lo.get("detail"):
        s += " " + json.dumps(lo["detail"], sort_keys=True)
    if lo.get("os_counters") not in (None, "yes"):
        s += f" (os: {lo['os_counters']})"
    return s


def render(doc: dict) -> list[str]:
    lines = [f"{doc['path']}: {doc['bytes'] / 1e6:.2f} MB, layout {doc['layout_version']}, "
             f"vdps-hil {doc['tool_version']}, mode {doc['mode']}, duration "
             f"{doc['duration_s']:.3f} s"]
    if doc["truncated"]:
        lines.append(f"  NOTE: no summary (cut off by a crash?): read by scanning; "
                     f"`vdps recover {doc['path']} -o FIXED.mcap` writes a closed copy")
    for p in doc["problems"][:5]:
        lines.append(f"  problem: {p}")
    lines.append("topics:")
    w = max((len(t) for t in doc["topics"]), default=10)
    for t, s in doc["topics"].items():
        extra = ""
        if s.get("count", 0) >= 2:
            extra = f" {s['rate_hz']:9.2f} Hz  max gap {s['max_gap_s']:.3f} s"
            if s.get("gaps") is not None:
                extra += f"  gaps {s['gaps']}"
        if s.get("invalid"):
            extra += f"  invalid {s['invalid']}"
        lines.append(f"  {t:<{w}} {s['count']:>9}{extra}")
    if doc["health"]:
        lines.append("sources:")
        for src, h in sorted(doc["health"].items()):
            lines.append(_health_line(src, h))
    if doc["fields"]:
        lines.append("catalogue fields provided:")
        for f, srcs in doc["fields"].items():
            lines.append(f"  {f}: " + ", ".join(f"{s} ({n})" for s, n in srcs.items()))
    for k, v in doc["hashes"].items():
        lines.append(f"  {k} {v}")
    return lines


@click.command("info")
@click.argument("recording", metavar="FILE.mcap")
@json_option
def info(recording, json_out):
    """Topics, counts, rates, duration, gaps, per-source health and the catalogue fields a
    recording provides.

    Example: vdps info track.mcap --json info.json
    """
    from vdps_hil.record.reader import RecordingError

    require_file(recording)
    try:
        doc = summarize(recording)
    except RecordingError as e:
        raise UserError(str(e)) from None
    for ln in render(doc):
        click.echo(ln)
    write_json(doc, json_out)
