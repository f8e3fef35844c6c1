"""vdps_hil.adapters.quiet_readers: a noisy reader's logger and its __del__ errors are kept off
the terminal inside the block, and nothing else is (the real asammdf case: test_can_adapter)."""

from __future__ import annotations

import gc
import logging
import sys

from vdps_hil.adapters.quiet_readers import NOISY_LOGGERS, collect_half_built, library_noise_off


class _HalfBuilt:
    """Raises in __del__ as asammdf's MDF4 does when its constructor failed."""

    def __del__(self):
        raise AttributeError("'MDF4' object has no attribute '_file'")


class _Other:
    def __del__(self):
        raise RuntimeError("not ours to hide")


def _recording_hook(monkeypatch) -> list:
    """Python's unraisable hook replaced by one that records (pytest installs its own)."""
    seen: list = []
    monkeypatch.setattr(sys, "unraisablehook", lambda u: seen.append(type(u.exc_value).__name__))
    return seen


def test_a_noisy_library_s_del_error_and_log_lines_are_dropped_inside_the_block(capfd, monkeypatch):
    monkeypatch.setattr(_HalfBuilt.__del__, "__module__", NOISY_LOGGERS[0] + ".blocks.mdf_v4")  # as MDF4.__del__
    seen = _recording_hook(monkeypatch)
    lg = logging.getLogger(NOISY_LOGGERS[0])
    handler = logging.StreamHandler()  # as asammdf installs its console handler
    lg.addHandler(handler)
    try:
        with library_noise_off():
            lg.error("Expected ##CG block")
            x = _HalfBuilt()
            x.self = x  # a reference cycle: only the collector frees it
            del x
            collect_half_built()
        assert capfd.readouterr().err == "" and seen == []
        assert lg.disabled is False and sys.unraisablehook is not None
        lg.error("after the block")
        assert "after the block" in capfd.readouterr().err
    finally:
        lg.removeHandler(handler)


def test_other_del_errors_still_reach_python_s_hook(monkeypatch):
    seen = _recording_hook(monkeypatch)
    with library_noise_off():
        y = _Other()
        del y
        collect_half_built()
        z = _HalfBuilt()  # not from a noisy library: passed on too
        del z
    gc.collect()
    assert seen == ["RuntimeError", "AttributeError"]
