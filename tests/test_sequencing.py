"""``estimation.sequencing.ImuSequencer``: a measurement waits for the IMU samples up to its time,
also when the IMU's time stamps lag; it is released when the IMU stops."""

from __future__ import annotations

from vdps_hil.bus.samples import Sample
from vdps_hil.estimation.sequencing import ImuSequencer

MS = 1_000_000


def _run(seq: ImuSequencer, stream) -> list[tuple[str, int]]:
    """Feed (kind, raw t_ns) in arrival order as the pipeline does; the handlers' calls in order."""
    calls: list[tuple[str, int]] = []

    def handler(kind):
        return lambda s, out: calls.append((kind, s.t_ns))

    out: list = []
    for kind, t in stream:
        s = Sample(t, kind, kind, {})
        fn = handler(kind)
        if not seq.offer(s, kind, fn, out):
            fn(s, out)
    seq.release_all(out)
    return calls


def test_a_fix_waits_for_an_imu_whose_time_stamps_lag_longer_than_the_hold():
    """The IMU's stamps lag 125 ms (rtklib-car), the hold is 50 ms: a GNSS fix stamped 500 ms
    arrives with the IMU sample stamped 500 ms, whose time is 375 ms. It is handed on just before
    the first IMU sample at or past its time (stamped 630 ms: 505 ms), not expired at 550 ms
    (before, every fix of that drive went on with the IMU 75 ms short of it)."""
    seq = ImuSequencer(50 * MS, 125 * MS, {"gnss_pos": 0})
    stream = []
    for t in range(0, 800 * MS, 10 * MS):
        stream.append(("imu", t))
        if t == 500 * MS:
            stream.append(("gnss_pos", t))
    calls = _run(seq, stream)
    k = calls.index(("gnss_pos", 500 * MS))
    assert calls[k - 1] == ("imu", 620 * MS) and calls[k + 1] == ("imu", 630 * MS)
    assert seq.held == 1 and seq.hold_expired == 0


def test_a_fix_is_released_when_the_imu_stops():
    """The IMU stops at 200 ms (stamps lagging 125 ms): the fix stamped 300 ms is handed on once the
    newest sample time (the wheel speeds' here) is the hold plus that lag past its arrival, and
    counted as expired; without a lag, after the hold alone."""
    for imu_lat, released_at in ((125 * MS, 480 * MS), (0, 350 * MS)):
        seq = ImuSequencer(50 * MS, imu_lat, {"gnss_pos": 0})
        stream = [("imu", t) for t in range(0, 210 * MS, 10 * MS)]
        stream.append(("gnss_pos", 300 * MS))
        stream += [("wheel_speed", t) for t in range(300 * MS, 600 * MS, 10 * MS)]
        calls = _run(seq, stream)
        k = calls.index(("gnss_pos", 300 * MS))
        assert calls[k - 1] == ("wheel_speed", released_at), (imu_lat, calls[k - 3:k + 2])
        assert seq.hold_expired == 1
