"""Signals of scenario files (sim/signals.py): each type, the modifiers, the channel list."""

import math

import pytest

from vdps_hil.sim.scenarios import CHANNELS
from vdps_hil.sim.signals import build_signal


def test_signals():
    sine = build_signal({"type": "sine", "offset": 1.0, "amplitude": 2.0, "frequency_hz": 0.5, "start_s": 1.0}, "s")
    assert sine(0.5) == 1.0 and sine(1.5) == pytest.approx(1.0 + 2.0 * math.sin(math.pi * 0.5))
    pts = build_signal({"type": "points", "points": [[0, 0], [1, 10], [1, 20], [2, 20]]}, "p")
    assert pts(-1) == 0 and pts(0.5) == 5 and pts(1.0) == 20 and pts(3) == 20
    held = build_signal({"type": "sine", "amplitude": 1.0, "frequency_hz": 1.0, "hold_from_s": 10.25}, "h")
    assert held(12.0) == pytest.approx(1.0) and held(10.0) == pytest.approx(0.0, abs=1e-12)
    sw = build_signal({"type": "sine", "amplitude": 1.0, "frequency_hz": 1.0, "then_s": 2.0,
                       "then": {"type": "const", "value": 5.0}}, "w")
    assert sw(1.25) == pytest.approx(1.0) and sw(2.0) == 5.0
    sweep = build_signal({"type": "sweep", "amplitude": 1.0, "f0_hz": 0.5, "f1_hz": 2.0, "duration_s": 4.0}, "c")
    assert sweep(5.0) == 0.0 and abs(sweep(1.0)) <= 1.0
    assert len(CHANNELS) == 9
