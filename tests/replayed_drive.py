"""A short simulated drive and its replay output, for tests of commands that read recordings."""

from __future__ import annotations

from pathlib import Path


def replayed_drive(d: Path, seed: int, duration_s: float = 2.0) -> Path:
    """``d/paper.mcap`` (the ``paper`` scenario, ``seed``) and ``d/out.mcap`` (its replay); returns ``d``."""
    from vdps_hil.app.replay import replay_file
    from vdps_hil.sim.drive import Drive

    Drive("paper", seed=seed, duration_s=duration_s).run(d / "paper.mcap")
    replay_file(d / "paper.mcap", output=d / "out.mcap")
    return d


def drive_samples(seed: int, duration_s: float = 2.5, scenario: str = "paper") -> list:
    """The decoded samples of a simulated drive (``scenario``, ``seed``), written and read in memory."""
    import io

    from vdps_hil.record.decode import decode_recording
    from vdps_hil.sim.drive import Drive

    buf = io.BytesIO()
    Drive(scenario, seed=seed, duration_s=duration_s).run(buf)
    buf.seek(0)
    return list(decode_recording(buf))
