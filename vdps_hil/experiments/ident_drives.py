"""The identifier's inputs of a simulated drive, cached: what the identification studies replay.

A drive (scenario, truth backend, model vehicle file, seed) is simulated onto the real wire
formats, its ``/raw/`` topics are decoded and fed to the Figure-2 node
(``pipeline.node.VdpsSystem``: EKF, alpha-beta, identification feeder) on the *model* vehicle
file, and every ``IdentInputs`` the feeder builds is kept (``paper_chain.chain_run`` with
``record_inputs``). The identifier never feeds back into the estimator or the feeder (it only
changes the predictor's parameters), so the identifier of a replay is exactly ``Identifier``
run over these inputs in order: a study reruns the identification with another configuration
in a second instead of replaying the drive (tested in ``tests/test_ident_drives.py``).

Cache: one ``.npz`` per drive (``<dir>/<scenario>_<truth>_<model>_<seed>.npz``: every
``IdentInputs`` field as an array, ``allow_pickle=False``: nothing in it can execute code),
written atomically, so a study can be stopped at any time and resumed.
"""

from __future__ import annotations

import dataclasses
import os
import tempfile
from pathlib import Path
from typing import NamedTuple

import numpy as np

from vdps_hil.identification.inputs import IdentInputs

__all__ = ["CACHE_VERSION", "DriveKey", "cache_path", "drive_inputs", "inputs_from_arrays", "inputs_to_arrays"]

CACHE_VERSION = 2  # 2: ``susp_interval_s`` (2026-12-07)
_FIELDS = tuple(f.name for f in dataclasses.fields(IdentInputs))
_OPTIONAL = ("moments_nm", "specific_force_b_mps2", "vehicle_angles_rad", "lateral_velocity_sigma_mps",
             "susp_interval_s")


class DriveKey(NamedTuple):
    """One drive: scenario name, truth backend ("ours" or a ``--truth`` spec), model vehicle
    file, seed."""

    scenario: str
    truth: str
    model: str
    seed: int

    @property
    def name(self) -> str:
        return f"{self.scenario}_{self.truth.replace(':', '')}_{self.model}_{self.seed}"


def cache_path(directory: str | os.PathLike, key: DriveKey) -> Path:
    return Path(directory) / f"{key.name}.npz"


def inputs_to_arrays(inputs: list[IdentInputs]) -> dict[str, np.ndarray]:
    """Column arrays of a list of inputs (an optional field that is None everywhere is left
    out; None in some rows only is NaN there)."""
    out: dict[str, np.ndarray] = {"t_ns": np.array([i.t_ns for i in inputs], dtype=np.int64)}
    for name in _FIELDS[1:]:
        vals = [getattr(i, name) for i in inputs]
        if name in _OPTIONAL:
            if all(v is None for v in vals):
                continue
            first = next(v for v in vals if v is not None)
            empty = np.nan if isinstance(first, float) else (np.nan,) * len(first)
            vals = [empty if v is None else v for v in vals]
        out[name] = np.array(vals, dtype=float)
    return out


def inputs_from_arrays(arrays) -> list[IdentInputs]:
    """The inverse of :func:`inputs_to_arrays`."""
    t = arrays["t_ns"]
    cols = {n: arrays[n] for n in _FIELDS[1:] if n in arrays}
    out = []
    for k in range(len(t)):
        kw = {n: (float(c[k]) if c.ndim == 1 else tuple(c[k].tolist())) for n, c in cols.items()}
        for n in _OPTIONAL:
            if n in kw and np.any(np.isnan(kw[n])):  # None was written as NaN (inf is a value)
                kw[n] = None
        out.append(IdentInputs(t_ns=int(t[k]), **kw))
    return out


def _simulate(key: DriveKey) -> dict:
    from vdps_hil.experiments.paper_chain import chain_run

    run = chain_run(key.scenario, "table1-susp1k", key.seed, model=key.model, predict=False, record_inputs=True,
                    truth_backend=None if key.truth == "ours" else key.truth)
    return {"inputs": run["inputs"], "status": run["status"], "wall_s": run["wall_s"]}


def drive_inputs(key: DriveKey, directory: str | os.PathLike | None = None) -> list[IdentInputs]:
    """The ``IdentInputs`` of the drive, in order: from the cache ``directory`` when it holds
    them, else simulated and replayed (and stored there)."""
    if directory is None:
        return _simulate(key)["inputs"]
    path = cache_path(directory, key)
    if path.exists():
        with np.load(path, allow_pickle=False) as z:
            if int(z["cache_version"]) == CACHE_VERSION:
                return inputs_from_arrays(z)
    inputs = _simulate(key)["inputs"]
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=".npz", dir=path.parent)
    with os.fdopen(fd, "wb") as f:
        np.savez_compressed(f, cache_version=np.array(CACHE_VERSION), **inputs_to_arrays(inputs))
    os.replace(tmp, path)
    return inputs
