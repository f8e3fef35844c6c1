"""Fixtures shared by the batch engine and runner tests: short simulated drives (1 s, seeds 0-7,
one with 300 kg more on board) and a corrupt file."""

from __future__ import annotations

import os

import pytest

from vdps_hil.model.params import load_vehicle
from vdps_hil.sim.drive import Drive

N_DRIVES = 8
DRIVE_S = 1.0
HEAVY = 5
"""The drive with 300 kg more on board (passengers, luggage): the fleet report must flag it."""


@pytest.fixture(scope="module")
def drives(tmp_path_factory) -> list[str]:
    d = tmp_path_factory.mktemp("drives")
    truth = load_vehicle("sedan-truth")
    paths = []
    for seed in range(N_DRIVES):
        p = d / f"drive{seed}.mcap"
        veh = truth.with_params(mass_kg=truth.params.mass_kg + 300.0) if seed == HEAVY else truth
        Drive("paper", seed=seed, duration_s=DRIVE_S, vehicle=veh).run(p)
        paths.append(os.fspath(p))
    return paths


@pytest.fixture(scope="module")
def corrupt(tmp_path_factory) -> str:
    """An MCAP magic followed by garbage: not a recording anyone can replay."""
    p = tmp_path_factory.mktemp("bad") / "corrupt.mcap"
    p.write_bytes(b"\x89MCAP0\r\n" + bytes(range(256)) * 4)
    return os.fspath(p)
