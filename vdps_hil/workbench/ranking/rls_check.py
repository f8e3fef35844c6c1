"""The workbench's parameters checked against the identifier on the same drive (issue 18).

The ranking identifies the ten parameters itself (its base fit: every row of eq 13 at once,
``ranking.identification``), so that each candidate effect is judged against a re-identified
model. That fit has no status of its own: on a drive the model does not match it still returns a
value with a small sigma (a CommonRoad sine drive: front cornering stiffness +36 % at 1 % sigma).
The identifier of ``vdps replay`` (eq 19-23, ``identification``) runs on the same samples during
the estimator pass (``DatasetConfig(identify=True)``, kept as ``table.rls``) and says per
parameter whether it was identified, or why not (excitation gates, bounds, the model-mismatch
tests). Each base-fit parameter is labelled by what the identifier found (``verdict``):

* ``agrees``: identified by the identifier, and the two values within ``AGREE_Z`` combined
  sigmas, z = (v_fit - v_rls) / sqrt(s_fit^2 + s_rls^2);
* ``disagrees``: identified by the identifier, the two values further apart: at least one of
  the two models does not describe this drive (the words say "not confirmed");
* ``unconfirmed``: the identifier did not identify it (its status, e.g. "model mismatch",
  "not excited", "at bound", is given), or the two cannot be compared (no finite z);
* no label when the drive was prepared without the identifier (``table.rls`` None).

Only labels: the values the workbench fits with are not changed (the candidates are ranked on
the base fit, whatever the identifier says).
"""

from __future__ import annotations

import math
from collections.abc import Iterable

from .results import RankEntry

AGREE_Z = 3.0
"""Largest |z| of two values of one parameter taken as the same (about 3 combined sigmas: a
0.3 % chance for two unbiased Gaussian estimates)."""

VERDICTS = ("agrees", "disagrees", "unconfirmed")


def agreement_z(value: float, sigma: float, other: float, other_sigma: float) -> float:
    """z of two estimates of one quantity (NaN when a value or both sigmas are missing)."""
    den = math.hypot(sigma if math.isfinite(sigma) else 0.0, other_sigma if math.isfinite(other_sigma) else 0.0)
    if not (math.isfinite(value) and math.isfinite(other)) or den <= 0.0:
        return math.nan
    return (value - other) / den


def verdict(status: str, z: float) -> str:
    """``VERDICTS`` entry for the identifier's per-parameter ``status`` and the agreement z."""
    if status != "identified" or not math.isfinite(z):
        return "unconfirmed"
    return "agrees" if abs(z) <= AGREE_Z else "disagrees"


def cross_check(entries: Iterable[RankEntry], rls) -> None:
    """Label each parameter entry with the identifier's value, sigma, status, z and verdict
    (``RankEntry.identifier``); ``rls``: ``table.rls`` (an ``estimator_run.RlsResult``) or None
    (nothing labelled)."""
    if rls is None:
        return
    for e in entries:
        if e.kind != "parameter" or len(e.parameters) != 1:
            continue
        (p, (v, s)), = e.parameters.items()
        if p not in rls.params:
            continue
        rv = float(rls.params[p])
        rs = float(rls.sigmas.get(p, math.nan))
        st = rls.status.get(p, "not converged")
        z = agreement_z(float(v), float(s), rv, rs)
        e.identifier = {"param": p, "value": rv, "sigma": rs, "status": st, "z": z, "verdict": verdict(st, z)}
