"""Fleet report: one self-contained HTML page (plots embedded as PNG) over a batch's results.

Sections
--------
1. **Batch**: command, tool version, counts, engine, wall time.
2. **Identified parameters per drive** with their 1-sigma, one panel per parameter, drives in
   batch order (sorted file names: usually chronological). Each drive is compared with the
   fleet by a robust score::

       x_ref  = median_j x_j                               fleet reference
       s_ref  = 1.4826 * median_j |x_j - x_ref|            robust fleet spread (MAD)
       z_i    = (x_i - x_ref) / sqrt(sigma_i^2 + s_ref^2)
       flag   |z_i| > z_flag  (default 3)

   The median and MAD ignore a minority of odd drives, so a drive where the mass jumped (a
   trailer, passengers, a full tank) stands out with its own sigma taken into account: a
   drive that identified the mass poorly (large sigma) is not flagged for being far off.
   Flagged drives are red in the plots and listed in a table.
3. **Effects recommended per drive** (diagnose batches): a drive x effect table and the
   count of drives recommending each effect (what the model misses across the fleet).
4. **Failed drives and why**: id, input, error type and message.
5. **Per-drive summary**: duration, raw records, rejects, mean NIS per dof, problems the
   reader met (a damaged chunk skipped, a truncated file), task wall time, worker peak memory.

Result documents come from different task functions; the accessors
(:func:`identified_params`, :func:`recommended_effects`) read the known layouts and return
nothing for the others, so the report never fails on an unexpected result (it shows less).
"""

from __future__ import annotations

import base64
import html
import io
import json
import math
import os
from pathlib import Path
from typing import Any, Iterable, Mapping

__all__ = ["write_report", "render_html", "aggregate_from_dir", "identified_params",
           "recommended_effects", "prior_params", "parameter_flags", "drive_summary", "Z_FLAG"]

Z_FLAG = 3.0

PARAM_ORDER = ("mass_kg", "inertia_x_kgm2", "inertia_y_kgm2", "inertia_z_kgm2",
               "cornering_stiffness_front_nprad", "cornering_stiffness_rear_nprad",
               "tracking_stiffness_1_n", "tracking_stiffness_2_n", "tracking_stiffness_3_n",
               "tracking_stiffness_4_n")


# ------------------------------------------------------------------------------- accessors
def _num(v) -> float | None:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return None
    v = float(v)
    return v if math.isfinite(v) else None


def identified_params(result: Mapping[str, Any] | None) -> dict[str, tuple[float, float | None]]:
    """``{parameter: (value, sigma)}`` from a task result: an ``identification`` /
    ``identified`` entry holding ``params`` and ``sigmas`` dicts (the replay's
    ``Identifier.status`` layout), or ``{name: {"value", "sigma"}}``, or the workbench's
    ``workbench.identified_parameters`` entries (diagnosis). Empty when the result has none."""
    if not isinstance(result, Mapping):
        return {}
    wb = result.get("workbench")
    if isinstance(wb, Mapping) and isinstance(wb.get("identified_parameters"), list):
        out = {}
        for entry in wb["identified_parameters"]:
            params = entry.get("parameters") if isinstance(entry, Mapping) else None
            for k, v in (params or {}).items():
                if isinstance(v, Mapping) and _num(v.get("value")) is not None:
                    out[str(k)] = (_num(v["value"]), _num(v.get("sigma")))
        if out:
            return out
    for key in ("identification", "identified", "ident"):
        block = result.get(key)
        if not isinstance(block, Mapping):
            continue
        for sub in (block, block.get("final"), block.get("last")):
            if isinstance(sub, Mapping) and isinstance(sub.get("params"), Mapping):
                sig = sub.get("sigmas") if isinstance(sub.get("sigmas"), Mapping) else {}
                out = {}
                for k, v in sub["params"].items():
                    x = _num(v)
                    if x is not None:
                        out[str(k)] = (x, _num(sig.get(k)))
                return out
        out = {}
        for k, v in block.items():
            if isinstance(v, Mapping) and _num(v.get("value")) is not None:
                out[str(k)] = (_num(v["value"]), _num(v.get("sigma")))
        if out:
            return out
    return {}


def prior_params(result: Mapping[str, Any] | None) -> dict[str, float]:
    """The identifier's start values (the model vehicle file's ``prior`` in a replay result)."""
    if not isinstance(result, Mapping):
        return {}
    block = result.get("identification")
    prior = block.get("prior") if isinstance(block, Mapping) else None
    if not isinstance(prior, Mapping):
        return {}
    return {str(k): x for k, v in prior.items() if (x := _num(v)) is not None}


def recommended_effects(result: Mapping[str, Any] | None) -> list[str]:
    """Effect names a diagnosis recommends, best first: the workbench's forward selection
    (``workbench.selected``; the first is its ``recommendation``), or ``recommended_effects``
    (names or dicts with ``name``/``effect``), or ``recommendations`` / ``effects.recommended``
    likewise, or the single ``recommendation``."""
    if not isinstance(result, Mapping):
        return []
    wb = result.get("workbench")
    if isinstance(wb, Mapping) and isinstance(wb.get("selected"), list):
        sel = [str(n) for n in wb["selected"] if isinstance(n, str)]
        rec = result.get("recommendation")
        if isinstance(rec, str) and rec not in sel:
            sel.insert(0, rec)
        return sel
    cands = [result.get("recommended_effects"), result.get("recommendations")]
    eff = result.get("effects")
    if isinstance(eff, Mapping):
        cands.append(eff.get("recommended"))
    for c in cands:
        if isinstance(c, list):
            names = []
            for item in c:
                if isinstance(item, str):
                    names.append(item)
                elif isinstance(item, Mapping):
                    n = item.get("name", item.get("effect"))
                    if isinstance(n, str):
                        names.append(n)
            return names
    rec = result.get("recommendation")
    return [rec] if isinstance(rec, str) else []


def drive_summary(result: Mapping[str, Any] | None) -> dict:
    """Duration, raw records, rejects (sum), mean NIS per dof per update kind and the reader's
    problems of a replay result (``system.replay_file`` layout); empty values otherwise."""
    r = result if isinstance(result, Mapping) else {}
    msgs = r.get("messages_read") if isinstance(r.get("messages_read"), Mapping) else {}
    rej = r.get("rejected") if isinstance(r.get("rejected"), Mapping) else {}
    inn = r.get("innovations") if isinstance(r.get("innovations"), Mapping) else {}
    dec = r.get("decode") if isinstance(r.get("decode"), Mapping) else {}
    reader = dec.get("reader") if isinstance(dec.get("reader"), Mapping) else {}
    nis = {}
    for k, v in inn.items():
        x = _num(v.get("mean_nis_per_dof")) if isinstance(v, Mapping) else None
        if x is not None:
            nis[str(k)] = x
    return {"duration_s": _num(r.get("duration_s")),
            "raw_records": msgs.get("raw_records") if isinstance(msgs.get("raw_records"), int) else None,
            "rejected": sum(v for v in rej.values() if isinstance(v, int) and not isinstance(v, bool)),
            "nis": nis, "problems": [str(p) for p in reader.get("problems") or []]}


def parameter_flags(values: list[float | None], sigmas: list[float | None],
                    z_flag: float = Z_FLAG) -> tuple[float | None, float | None, list[float | None]]:
    """(x_ref, s_ref, z per drive) of the robust fleet comparison (module docstring); z is None
    where a drive has no value."""
    xs = [v for v in values if v is not None]
    if not xs:
        return None, None, [None] * len(values)
    xs_sorted = sorted(xs)
    ref = _median(xs_sorted)
    s_ref = 1.4826 * _median(sorted(abs(x - ref) for x in xs))
    z = []
    for v, s in zip(values, sigmas):
        if v is None:
            z.append(None)
            continue
        den = math.sqrt((s or 0.0) ** 2 + s_ref ** 2)
        z.append((v - ref) / den if den > 0 else (0.0 if v == ref else math.copysign(math.inf, v - ref)))
    return ref, s_ref, z


def _median(xs: list[float]) -> float:
    n = len(xs)
    return xs[n // 2] if n % 2 else 0.5 * (xs[n // 2 - 1] + xs[n // 2])


# ---------------------------------------------------------------------------- aggregate
def aggregate_from_dir(out_dir: str | os.PathLike) -> dict:
    """The aggregate of a batch directory: ``batch.json`` when present, else assembled from
    ``drives/*.json`` (an interrupted batch)."""
    from vdps_hil.batch.runner import AGGREGATE, RESULT_DIR

    out = Path(out_dir)
    agg = out / AGGREGATE
    if agg.is_file():
        doc = json.loads(agg.read_text(encoding="utf-8"))
        if not isinstance(doc, dict) or "tasks" not in doc:
            raise ValueError(f"{agg} is not a batch aggregate")
        return doc
    files = sorted((out / RESULT_DIR).glob("*.json"))
    if not files:
        raise ValueError(f"no {AGGREGATE} and no {RESULT_DIR}/*.json")
    tasks = []
    for f in files:
        try:
            d = json.loads(f.read_text(encoding="utf-8"))
        except ValueError:
            continue
        if isinstance(d, dict) and "id" in d:
            tasks.append(d)
    ok = sum(t.get("status") == "ok" for t in tasks)
    return {"kind": tasks[0].get("kind", "batch") if tasks else "batch", "tool": None, "options": {},
            "counts": {"total": len(tasks), "ok": ok, "failed": len(tasks) - ok}, "tasks": tasks,
            "failed": [{"id": t["id"], "input": t.get("input"), "error": t.get("error")}
                       for t in tasks if t.get("status") != "ok"],
            "run": {"assembled_from": os.fspath(out / RESULT_DIR)}}


# -------------------------------------------------------------------------------- plots
def _png(fig) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, bbox_inches="tight")
    import matplotlib.pyplot as plt
    plt.close(fig)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _param_figure(ids: list[str], table: dict[str, dict], z_flag: float,
                  priors: Mapping[str, float] | None = None) -> tuple[str | None, list]:
    import matplotlib
    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    names = [p for p in PARAM_ORDER if p in table] + sorted(p for p in table if p not in PARAM_ORDER)
    if not names:
        return None, []
    flags = []
    ncol = 2
    nrow = math.ceil(len(names) / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(11, 2.4 * nrow), squeeze=False, sharex=True)
    x = list(range(len(ids)))
    for ax, name in zip(axes.flat, names):
        vals = [table[name].get(i, (None, None))[0] for i in ids]
        sigs = [table[name].get(i, (None, None))[1] for i in ids]
        ref, s_ref, z = parameter_flags(vals, sigs, z_flag)
        for xi, v, s, zi, i in zip(x, vals, sigs, z, ids):
            if v is None:
                continue
            bad = zi is not None and abs(zi) > z_flag
            ax.errorbar([xi], [v], yerr=[s or 0.0], fmt="o", ms=4, capsize=2,
                        color="tab:red" if bad else "tab:blue")
            if bad:
                flags.append((i, name, v, s, ref, zi))
        if priors and name in priors:
            ax.axhline(priors[name], color="tab:green", lw=0.8, ls=":")
        if ref is not None:
            ax.axhline(ref, color="0.4", lw=0.8, ls="--")
            if s_ref:
                ax.axhspan(ref - s_ref, ref + s_ref, color="0.85", zorder=0)
        ax.set_title(name, fontsize=9)
        ax.tick_params(labelsize=7)
    for ax in list(axes.flat)[len(names):]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xticks(x)
        ax.set_xticklabels(ids, rotation=60, ha="right", fontsize=6 if len(ids) > 20 else 7)
    fig.suptitle("Identified parameters per drive (value, error bar 1 sigma; dashed: fleet "
                 "median, grey: robust spread; dotted green: model file; red: |z| > %.0f)" % z_flag,
                 fontsize=10)
    fig.tight_layout()
    return _png(fig), flags


def _effects_figure(counts: dict[str, int], n_drives: int) -> str | None:
    if not counts:
        return None
    import matplotlib
    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    names = sorted(counts, key=lambda k: (-counts[k], k))
    fig, ax = plt.subplots(figsize=(8, 0.35 * len(names) + 1.2))
    ax.barh(names[::-1], [counts[n] for n in names[::-1]], color="tab:orange")
    ax.set_xlabel(f"drives recommending the effect (of {n_drives})")
    ax.set_xlim(0, max(1, n_drives))
    fig.tight_layout()
    return _png(fig)


# --------------------------------------------------------------------------------- html
_CSS = """body{font-family:system-ui,sans-serif;margin:1.5em;max-width:1200px}
table{border-collapse:collapse;font-size:0.85em;margin:0.5em 0}
td,th{border:1px solid #ccc;padding:2px 6px;text-align:left}th{background:#f0f0f0}
td.num{text-align:right;font-variant-numeric:tabular-nums}.bad{color:#b00}.ok{color:#070}
img{max-width:100%}code{font-size:0.9em}"""


def _e(v: Any) -> str:
    return html.escape("" if v is None else str(v))


def _fmt(v: float | None, digits: int = 4) -> str:
    if v is None:
        return "-"
    if v != 0 and (abs(v) >= 1e5 or abs(v) < 1e-3):
        return f"{v:.{digits - 1}e}"
    return f"{v:.{digits}g}"


def _table(head: Iterable[str], rows: Iterable[Iterable[str]]) -> str:
    h = "".join(f"<th>{_e(c)}</th>" for c in head)
    body = "".join("<tr>" + "".join(rows_cell for rows_cell in r) + "</tr>" for r in rows)
    return f"<table><tr>{h}</tr>{body}</table>"


def _td(v: Any, num: bool = False, cls: str = "") -> str:
    c = " ".join(x for x in ("num" if num else "", cls) if x)
    return f"<td class=\"{c}\">{_e(v)}</td>" if c else f"<td>{_e(v)}</td>"


def render_html(aggregate: Mapping[str, Any], *, z_flag: float = Z_FLAG) -> str:
    """The report page of an aggregate document (``runner.run_batch``)."""
    tasks = [t for t in aggregate.get("tasks", []) if isinstance(t, Mapping)]
    ok_tasks = [t for t in tasks if t.get("status") == "ok"]
    parts = _batch_section(aggregate, tasks, ok_tasks)
    parts += _params_section([str(t.get("id")) for t in tasks], ok_tasks, z_flag)
    parts += _effects_section(aggregate, ok_tasks)
    parts += _failures_section(tasks)
    parts += _summary_section(tasks)
    parts.append("</body></html>")
    return "\n".join(parts)


def _batch_section(aggregate: Mapping[str, Any], tasks: list, ok_tasks: list) -> list[str]:
    """Page head and section 1: counts, tool, engine, wall time, options."""
    counts = aggregate.get("counts", {})
    run = aggregate.get("run", {}) or {}
    eng = run.get("engine") or {}
    parts = [f"<!doctype html><html><head><meta charset=\"utf-8\"><title>vdps batch "
             f"{_e(aggregate.get('kind'))}</title><style>{_CSS}</style></head><body>",
             f"<h1>vdps batch {_e(aggregate.get('kind'))}: fleet report</h1>",
             "<p>" + ", ".join([f"<b>{_e(counts.get('total', len(tasks)))}</b> tasks",
                                f"<span class=ok>{_e(counts.get('ok', len(ok_tasks)))} ok</span>",
                                f"<span class=bad>{_e(counts.get('failed', 0))} failed</span>"]) + "</p>",
             f"<p>tool {_e(aggregate.get('tool'))}; engine {_e(eng.get('backend'))} with "
             f"{_e(eng.get('workers'))} worker(s)"
             + (f" at <code>{_e(eng.get('scheduler'))}</code>" if eng.get("scheduler") else "")
             + (f"; {_fmt(run.get('wall_s'), 3)} s wall, {_e(run.get('computed'))} computed, "
                f"{_e(run.get('reused'))} reused" if "wall_s" in run else "") + "</p>"]
    if aggregate.get("options"):
        parts.append(f"<p>options: <code>{_e(json.dumps(aggregate['options'], sort_keys=True))}</code></p>")
    return parts


def _params_section(ids: list[str], ok_tasks: list, z_flag: float) -> list[str]:
    """Section 2: identified parameters per drive against the fleet (module docstring)."""
    table: dict[str, dict[str, tuple[float, float | None]]] = {}
    priors: dict[str, float] = {}
    for t in ok_tasks:
        for name, vs in identified_params(t.get("result")).items():
            table.setdefault(name, {})[str(t["id"])] = vs
        for name, v in prior_params(t.get("result")).items():
            priors.setdefault(name, v)  # the first drive's model file (one vehicle per batch)
    if not table:
        return []
    parts = []
    img, flags = _param_figure(ids, table, z_flag, priors)
    parts.append("<h2>Identified parameters per drive</h2>")
    parts.append(f"<p>Each drive against the fleet: z = (x - median) / sqrt(sigma&sup2; + "
                 f"s_ref&sup2;), s_ref = 1.4826 MAD; flagged when |z| &gt; {z_flag:g}.</p>")
    parts.append(f"<img alt=\"identified parameters\" src=\"{img}\">")
    if flags:
        parts.append("<h3 class=bad>Drives that differ from the fleet</h3>")
        parts.append(_table(["drive", "parameter", "value", "sigma", "fleet median", "z"],
                            [[_td(i), _td(n), _td(_fmt(v), True), _td(_fmt(s), True),
                              _td(_fmt(r), True), _td(_fmt(z, 3), True, "bad")]
                             for i, n, v, s, r, z in flags]))
    else:
        parts.append("<p class=ok>No drive differs from the fleet by more than the flag.</p>")
    return parts


def _effects_section(aggregate: Mapping[str, Any], ok_tasks: list) -> list[str]:
    """Section 3: effects recommended per drive (diagnose batches)."""
    eff = {str(t["id"]): recommended_effects(t.get("result")) for t in ok_tasks}
    if not (any(eff.values()) or aggregate.get("kind") == "diagnose"):
        return []
    parts = []
    cnt: dict[str, int] = {}
    for names in eff.values():
        for n in set(names):
            cnt[n] = cnt.get(n, 0) + 1
    parts.append("<h2>Effects recommended per drive</h2>")
    img = _effects_figure(cnt, len(ok_tasks))
    if img:
        parts.append(f"<img alt=\"effects across the fleet\" src=\"{img}\">")
    cols = sorted(cnt, key=lambda k: (-cnt[k], k))
    parts.append(_table(["drive", *cols, "recommended"],
                        [[_td(i), *[_td("x" if c in eff[i] else "") for c in cols],
                          _td(", ".join(eff[i]) or "none")] for i in eff]))
    return parts


def _failures_section(tasks: list) -> list[str]:
    """Section 4: failed drives and why."""
    failed = [t for t in tasks if t.get("status") != "ok"]
    parts = [f"<h2>Failed drives ({len(failed)})</h2>"]
    if failed:
        parts.append(_table(["drive", "input", "error", "message"],
                            [[_td(t.get("id")), _td(t.get("input")),
                              _td((t.get("error") or {}).get("type"), cls="bad"),
                              _td((t.get("error") or {}).get("message"))] for t in failed]))
    else:
        parts.append("<p class=ok>None.</p>")
    return parts


def _summary_section(tasks: list) -> list[str]:
    """Section 5: the per-drive summary."""
    rows = []
    for t in tasks:
        r = t.get("result") if isinstance(t.get("result"), Mapping) else {}
        s = drive_summary(r)
        trun = t.get("run") or {}
        rows.append([_td(t.get("id")), _td(t.get("status"), cls="ok" if t.get("status") == "ok" else "bad"),
                     _td(_fmt(s["duration_s"], 4), True), _td(s["raw_records"] or "-", True),
                     _td(s["rejected"], True),
                     _td(", ".join(f"{k} {_fmt(v, 3)}" for k, v in sorted(s["nis"].items())) or "-"),
                     _td("; ".join(s["problems"]) or "", cls="bad" if s["problems"] else ""),
                     _td(_fmt(_num(trun.get("wall_s")), 3), True),
                     _td(_fmt(_num(trun.get("peak_rss_mib")), 4), True)])
    return ["<h2>Per-drive summary</h2>",
            _table(["drive", "status", "duration [s]", "raw records", "rejected",
                    "mean NIS/dof per update kind", "recording problems", "task wall [s]",
                    "worker peak RSS [MiB]"], rows)]


def write_report(aggregate: Mapping[str, Any], report_dir: str | os.PathLike, *,
                 z_flag: float = Z_FLAG) -> Path:
    """Write ``<report_dir>/index.html``; returns its path."""
    d = Path(report_dir)
    d.mkdir(parents=True, exist_ok=True)
    path = d / "index.html"
    tmp = d / f".index.html.tmp{os.getpid()}"
    tmp.write_text(render_html(aggregate, z_flag=z_flag), encoding="utf-8")
    os.replace(tmp, path)
    return path
