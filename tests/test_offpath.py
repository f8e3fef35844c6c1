"""Tests of vdps_hil.prediction.offpath: predictions off the sample path, used at t0 +
prediction_latency_s; a live run (deadline "drop", a worker thread or a deliberately held one)
and its replay (deadline "wait", the live run's drops reproduced) give the same outputs bit for
bit; held jobs are dropped, counted and reported as status 3 while the sample path runs on.
No wall time is asserted: counts, order and digests only."""

from __future__ import annotations

import threading
from concurrent.futures import Future

import pytest
from replayed_drive import drive_samples

from vdps_hil.codecs.can_decode import VdpsCanDecoder
from vdps_hil.model.params import load_vehicle
from vdps_hil.pipeline.node import SystemConfig, VdpsSystem
from vdps_hil.pipeline.outputs import CanFrame, PredictionReport, outputs_digest
from vdps_hil.prediction.config import load_predictor_config
from vdps_hil.prediction.offpath import PredictionRunner, prediction_job
from vdps_hil.prediction.predictor import Predictor
from vdps_hil.prediction.warning import WarningStatus

MODEL = load_vehicle("sedan-model")
GATE_TIMEOUT_S = 60.0
"""A held job gives up waiting after this; a sample path that waited for it would show as a
job released by the timeout (asserted never to happen), not as a hung test."""


@pytest.fixture(scope="module")
def samples():
    return drive_samples(19, 2.5)


def config(**kw):
    """Started from identified parameters (frames valid at once: the drop status shows)."""
    return SystemConfig.for_profile(1000.0, 0.001, start_params=MODEL.params, **kw)


class HeldRunner(PredictionRunner):
    """A deliberately slowed worker: job k (0, 1, ...) of a held index runs in a thread of its own
    only after ``release`` (or the timeout); every other job is finished before ``submit``
    returns (a worker faster than the latency). Records, per held job, the sample count of the
    system when the job ran (``seen``) and how many ran by the timeout."""

    def __init__(self, predictor, held):
        super().__init__(predictor, "inline")
        self.base = predictor
        self.held = set(held)
        self.release = threading.Event()
        self.k = 0
        self.seen: list[int] = []
        self.timed_out = 0
        self.system = None

    def submit(self, params, init):
        k, self.k = self.k, self.k + 1
        if k not in self.held:
            return super().submit(params, init)
        fut = Future()

        def held_job():
            if not self.release.wait(GATE_TIMEOUT_S):
                self.timed_out += 1
            self.seen.append(self.system.counters["samples"])
            if fut.set_running_or_notify_cancel():
                fut.set_result(prediction_job(self.base.with_params(params), init))

        threading.Thread(target=held_job, daemon=True).start()
        return fut


def live_with(samples, held):
    runner = HeldRunner(Predictor(MODEL.with_params(**MODEL.params.as_dict()), load_predictor_config()), held)
    system = VdpsSystem(MODEL, config(prediction_deadline="drop"), runner=runner)
    runner.system = system
    out = []
    for s in samples:
        out += system.handle(s)
    runner.release.set()
    out += system.finish()
    return system, runner, out


def statuses(out):
    dec = VdpsCanDecoder()
    return [(o.t_ns, int(d.fields["warning_status"])) for o in out if isinstance(o, CanFrame)
            for d in dec.decode(o.t_ns, o.arbitration_id, o.data)]


def test_held_jobs_are_dropped_counted_and_sent_as_fault_without_stalling_the_samples(samples):
    held = {3, 4, 10}
    system, runner, out = live_with(samples, held)
    st = system.status()["prediction"]
    # every held job missed its deadline (the drive runs on > 20 ms after each): dropped and counted
    assert st["dropped"] == len(held) and st["used"] == st["started"] - len(held) and st["failed"] == 0
    assert st["deadline"] == "drop" and st["latency_s"] == 0.02
    # the sample path never waited: the held jobs ran (if at all) after the last sample, by release
    assert runner.timed_out == 0 and all(n == len(samples) for n in runner.seen)
    # no report of a dropped prediction; from each drop's deadline to the next used prediction the
    # frames say "fault" (3); the status counters count what was sent
    rep = {o.t0_ns for o in out if isinstance(o, PredictionReport)}
    assert rep.isdisjoint(system.prediction_drops_t0_ns) and len(rep) == st["used"]
    rows = statuses(out)
    for t0 in system.prediction_drops_t0_ns:
        nxt = min(t for t in rep if t > t0)
        window = [s for t, s in rows if t0 + 20_000_000 <= t < nxt + 20_000_000]
        assert window and all(s == WarningStatus.FAULT for s in window)
    assert system.counters["status"]["fault"] >= sum(1 for _, s in rows if s == WarningStatus.FAULT) > 0
    # without held jobs: nothing dropped, no fault frame on this drive
    clean, _, clean_out = live_with(samples, ())
    assert clean.status()["prediction"]["dropped"] == 0
    assert not any(s == WarningStatus.FAULT for _, s in statuses(clean_out))


def test_replay_with_the_recorded_drops_equals_the_live_run_bit_for_bit(samples):
    system, _, live_out = live_with(samples, {2, 5, 6, 11})
    drops = system.prediction_drops_t0_ns
    assert len(drops) == 4
    _, again = VdpsSystem.replay(MODEL, config(prediction_drops_t0_ns=drops), system.input_log)
    assert len(again) == len(live_out) > 1000 and outputs_digest(again) == outputs_digest(live_out)
    # the drops matter: a replay without them differs (and equals a live run without drops)
    _, plain = VdpsSystem.replay(MODEL, config(), system.input_log)
    assert outputs_digest(plain) != outputs_digest(live_out)
    _, _, clean = live_with(samples, ())
    assert outputs_digest(plain) == outputs_digest(clean)


@pytest.mark.parametrize("worker", ["thread", "process"])
def test_a_real_worker_racing_the_sample_path_replays_identically(samples, worker):
    """Live: the samples fed as fast as they come, the worker on its own (thread or process);
    however many jobs missed their deadline here, the replay with those drops and an inline
    worker gives the same outputs."""
    cfg = config(prediction_worker=worker, prediction_deadline="drop")
    system, live_out = VdpsSystem.replay(MODEL, cfg, samples)
    st = system.status()["prediction"]
    assert st["worker"] == worker and st["started"] >= 20 and st["used"] + st["dropped"] <= st["started"]
    _, again = VdpsSystem.replay(MODEL, config(prediction_drops_t0_ns=system.prediction_drops_t0_ns), samples)
    assert outputs_digest(again) == outputs_digest(live_out)


def test_waiting_workers_equal_the_inline_reference(samples):
    """Deadline "wait": no miss by construction, the same outputs from every worker."""
    digests = set()
    for worker in ("inline", "thread", "process"):
        system, out = VdpsSystem.replay(MODEL, config(prediction_worker=worker), samples)
        st = system.status()["prediction"]
        # at most the last job is still before its deadline at the end (cadence 100 ms > latency 20 ms)
        assert st["dropped"] == st["failed"] == 0 and st["started"] - 1 <= st["used"] <= st["started"]
        digests.add(outputs_digest(out))
    assert len(digests) == 1


def test_bad_worker_settings_are_refused():
    with pytest.raises(ValueError, match="prediction_worker"):
        SystemConfig(prediction_worker="gpu")
    with pytest.raises(ValueError, match="prediction_deadline"):
        SystemConfig(prediction_deadline="never")
    with pytest.raises(ValueError, match="prediction worker"):
        PredictionRunner(Predictor(MODEL), "cluster")


def test_a_dead_worker_is_a_counted_fault_not_an_exception():
    """The worker process killed (SIGKILL) mid-run: the jobs after it are counted failures and the
    chain sends status 3; a closed worker likewise."""
    import os
    import signal

    from vdps_hil.prediction.initial_state import PredictorInitialState
    from vdps_hil.prediction.warning import WarningChain

    pred = Predictor(MODEL)
    init = PredictorInitialState(t_ns=0, pos_g_m=(0.0, 0.0, 0.0), vel_g_mps=(20.0, 0.0, 0.0),
                                 euler_g_rad=(0.0, 0.0, 0.0), road_bank_rad=0.0, road_grade_rad=0.0,
                                 rate_b_radps=(0.0, 0.0, 0.0), wheel_speed_radps=(60.0,) * 4)
    runner = PredictionRunner(pred, "process")
    assert runner.ready(GATE_TIMEOUT_S)
    chain = WarningChain(pred, runner=runner)
    chain.handle(0, init)
    chain.handle(20_000_000, None)
    assert chain.assessments_total == 1 and chain.prediction_failures == 0
    for pid in list(runner._pool._processes):
        os.kill(pid, signal.SIGKILL)
    frames = []
    for k in range(1, 4):  # a job per 100 ms, each looked at 20 ms later
        chain.handle(k * 100_000_000, init)
        frames += chain.handle(k * 100_000_000 + 20_000_000, None)
    assert chain.prediction_failures == 3 and "prediction worker" in chain.last_failure
    assert chain.status == WarningStatus.FAULT
    dec = VdpsCanDecoder()
    assert all(int(d.fields["warning_status"]) == WarningStatus.FAULT for f in frames
               for d in dec.decode(0, f.arbitration_id, bytes(f.data)))
    chain.close()
    thread = PredictionRunner(pred, "thread")
    thread.close()
    assert thread.submit(None, init).result()[0] is None
