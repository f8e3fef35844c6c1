"""Tests of vdps_hil.prediction.warning: measures, policy, the CAN node, and the warning path on
the truth simulator (truth-initialised predictor with the true parameters, held inputs)."""

import math

import pytest

from vdps_hil.codecs.can_decode import VdpsCanDecoder
from vdps_hil.codecs.can_e2e import crc8_j1850
from vdps_hil.experiments.truth_init import initial_state_from_truth
from vdps_hil.experiments.scoring import evaluate_warning_frames
from vdps_hil.model.params import load_vehicle
from vdps_hil.prediction.config import PredictionConfigError, load_predictor_config
from vdps_hil.prediction.initial_state import PredictorInitialState
from vdps_hil.prediction.predictor import Predictor
from vdps_hil.prediction.warning import (RolloverAssessment, WarningChain, WarningLevel, WarningNode,
                                         WarningNodeConfig, WarningPolicy, WarningStatus,
                                         load_warning_config, replay_assessments,
                                         warning_config_from_table)
from vdps_hil.sim.scenarios import load_scenario
from vdps_hil.sim.simulator import Simulator

MS = 1_000_000


def assessment(t0_ns=0, ttr=None, peak_ltr=0.0, roll=0.0):
    return RolloverAssessment(t0_ns, ttr, None, peak_ltr, 0.0, roll, 5.0, "horizon")


def decode(frames):
    dec = VdpsCanDecoder()
    out = [s for m in frames for s in dec.decode_message(m)]
    return out, dec


# ----------------------------------------------------------------------------- measures and policy
def test_policy_levels():
    pol = WarningPolicy(reaction_time_s=1.0, margin_s=0.5, imminent_time_s=0.5, caution_ltr=0.9)
    assert pol.warning_time_s == 1.5
    assert pol.level(None, 0) == WarningLevel.NONE
    assert pol.level(assessment(), 0) == WarningLevel.NONE
    assert pol.level(assessment(peak_ltr=-0.95), 0) == WarningLevel.CAUTION
    assert pol.level(assessment(ttr=3.0), 0) == WarningLevel.CAUTION  # rollover beyond T_w
    assert pol.level(assessment(ttr=1.5), 0) == WarningLevel.WARNING
    assert pol.level(assessment(ttr=0.5), 0) == WarningLevel.IMMINENT
    # the TTR ages with time since t0: 2.0 s predicted at t0, 0.6 s later it is 1.4 s
    a = assessment(t0_ns=1000 * MS, ttr=2.0)
    assert a.ttr_at(1600 * MS) == pytest.approx(1.4)
    assert pol.level(a, 1400 * MS) == WarningLevel.CAUTION and pol.level(a, 1600 * MS) == WarningLevel.WARNING
    assert a.ttr_at(5000 * MS) == 0.0
    assert WarningPolicy(caution_on_predicted_rollover=False).level(assessment(ttr=3.0), 0) == WarningLevel.NONE


def test_warning_config_file_and_errors():
    pol, node = load_warning_config()
    assert (pol.reaction_time_s, pol.margin_s, pol.imminent_time_s, pol.hold_s) == (1.0, 0.5, 0.5, 0.5)
    assert (node.period_s, node.max_prediction_age_s, node.prediction_latency_s) == (0.02, 0.5, 0.02)
    with pytest.raises(PredictionConfigError, match="unknown key 'reaction_s'"):
        warning_config_from_table({"reaction_s": 1.0})
    with pytest.raises(PredictionConfigError, match="imminent_time_s"):
        WarningPolicy(imminent_time_s=3.0)
    with pytest.raises(PredictionConfigError, match="period_s"):
        WarningNodeConfig(period_s=0.0)


def test_validity_rule_in_the_config_file():
    """``require_converged`` and ``converged_hold_s`` (the system's validity rule, module docstring
    "Validity"): the file names the cornering problem and a 1 s hold; names are checked against the
    identification problems."""
    pol, _ = load_warning_config()
    assert pol.require_converged == ("cornering",) == WarningPolicy().require_converged
    assert pol.converged_hold_s == 1.0 == WarningPolicy().converged_hold_s
    p2, _ = warning_config_from_table({"require_converged": ["mass", "inertia"]})
    assert p2.require_converged == ("mass", "inertia")
    assert warning_config_from_table({"require_converged": []})[0].require_converged == ()
    with pytest.raises(PredictionConfigError, match="unknown identification problem 'cornering_stiffness'"):
        warning_config_from_table({"require_converged": ["cornering_stiffness"]})
    with pytest.raises(PredictionConfigError, match="require_converged: expected a list"):
        warning_config_from_table({"require_converged": "cornering"})
    # the hold (chosen on the declared tuning drives): a finite number >= 0
    assert warning_config_from_table({"converged_hold_s": 0})[0].converged_hold_s == 0
    for bad in (-0.1, float("nan"), "1", True):
        with pytest.raises(PredictionConfigError, match="converged_hold_s must be a finite number >= 0"):
            warning_config_from_table({"converged_hold_s": bad})


# ----------------------------------------------------------------------------- the node
def test_node_sends_at_50_hz_with_valid_crc_and_counter():
    node = WarningNode(WarningPolicy(), WarningNodeConfig(period_s=0.02, max_prediction_age_s=10.0))
    frames = []
    a = assessment(t0_ns=0)
    for t in range(0, 1000 * MS, MS):
        frames += node.handle(t, a if t == 0 else None)
    assert len(frames) == 50
    assert [round(f.timestamp * 1e3) for f in frames[:3]] == [0, 20, 40]
    for f in frames:
        assert f.arbitration_id == 0x080 and f.dlc == 8
        assert f.data[0] == crc8_j1850(bytes(f.data[1:]))
    samples, dec = decode(frames)
    assert len(samples) == 50 and dec.total_rejected == 0
    counters = [int(s.fields["warning_counter"]) for s in samples]
    assert counters == [k % 16 for k in range(50)]
    assert all(s.valid and s.fields["warning_level"] == 0 for s in samples)
    assert math.isinf(samples[0].fields["warning_time_to_rollover_s"])  # none predicted


def test_level_change_is_sent_at_once_and_held():
    node = WarningNode(WarningPolicy(hold_s=0.5), WarningNodeConfig(period_s=0.02))
    sent = {}
    for t in range(0, 2000 * MS, MS):
        a = None
        if t == 0:
            a = assessment(0)
        elif t == 505 * MS:  # 5 ms after a periodic frame at 500 ms
            a = assessment(t, ttr=1.2, peak_ltr=-1.0, roll=-0.8)
        elif t == 700 * MS:
            a = assessment(t)  # the danger is gone ...
        for m in node.handle(t, a):
            sent[t] = m
    assert 505 * MS in sent  # at once, not at the next 20 ms tick
    samples, dec = decode([sent[t] for t in sorted(sent)])
    assert dec.total_rejected == 0
    by_t = {s.t_ns: s for s in samples}
    s = by_t[505 * MS]
    assert s.fields["warning_level"] == WarningLevel.WARNING
    assert s.fields["warning_time_to_rollover_s"] == pytest.approx(1.2)
    assert s.fields["warning_ltr"] == pytest.approx(-1.0) and s.fields["warning_peak_roll_rad"] == pytest.approx(-0.8)
    # ... but the level is held 0.5 s after it was last confirmed (699 ms, the last call before the
    # all-clear) and drops at 1199 ms, sent at once
    assert by_t[1185 * MS].fields["warning_level"] == WarningLevel.WARNING
    assert 1199 * MS in sent and by_t[1199 * MS].fields["warning_level"] == WarningLevel.NONE
    # the TTR in the frames counts down while the level is held
    assert by_t[605 * MS].fields["warning_time_to_rollover_s"] == pytest.approx(1.1)


def test_status_field():
    pol, cfg = WarningPolicy(), WarningNodeConfig(period_s=0.02, max_prediction_age_s=0.5)
    node = WarningNode(pol, cfg)
    f0 = node.handle(0, None)  # nothing predicted yet: not converged
    f1 = node.handle(20 * MS, assessment(20 * MS), WarningStatus.NOT_CONVERGED)
    f2 = node.handle(40 * MS, None, WarningStatus.SENSOR_MISSING)
    f3 = node.handle(60 * MS, None)
    f4 = node.handle(600 * MS, None)  # prediction 580 ms old -> fault
    samples, dec = decode(f0 + f1 + f2 + f3 + f4)
    assert dec.total_rejected == 0
    assert [int(s.fields["warning_status"]) for s in samples] == [1, 1, 2, 0, 3]
    assert [s.valid for s in samples] == [False, False, False, True, False]


# ----------------------------------------------------------------------------- on the simulator
def run_chain(name, model):
    """Truth simulation, then the warning chain fed with the truth-initialised state at 100 Hz
    (every snapshot), true parameters, the configured predictor (10 Hz cadence) and policy."""
    sc = load_scenario(name)
    sim = Simulator(scenario=sc)
    sim.run()
    pred = Predictor(load_vehicle(model).with_params(**sc.vehicle.params.as_dict()), load_predictor_config())
    chain = WarningChain(pred, *load_warning_config())
    for s in sim.truth:
        chain.handle(s["t_ns"], initial_state_from_truth(s))
    return sim, chain, evaluate_warning_frames(chain.frames, sim.events)


def test_fishhook_suv_rollover_warned_with_lead_time():
    """Truth: tip-up 2.21 s, point of no return 3.72 s. Measured: first warning 1.22 s (lead
    2.50 s; the linear-tire model foresees a rollover during the first steer), first warning
    with the truth's roll direction 1.92 s (lead 1.80 s), lead to tip-up 0.99 s."""
    sim, chain, o = run_chain("fishhook-suv", "suv-model")
    assert o.truth_point_of_no_return_t_s == pytest.approx(3.72)
    assert o.lead_time_s >= 1.0
    assert o.lead_time_matched_side_s >= 1.0
    assert o.false_alarms == 0 and o.frames_rejected == 0
    assert o.max_gap_s <= 0.02 + 1e-9  # 50 Hz, never a gap
    assert not math.isnan(o.first_imminent_t_s) and o.first_imminent_t_s < o.truth_point_of_no_return_t_s
    # the level follows the time to rollover in the frames (T_w = 1.5 s, imminent 0.5 s); while the
    # steering crosses zero (1.6-1.9 s) no rollover is predicted and the warning is held
    valid = [r for r in o.decoded if r["valid"]]
    assert all(r["level"] >= WarningLevel.WARNING for r in valid if r["ttr_s"] <= 1.5)
    assert all(r["level"] == WarningLevel.IMMINENT for r in valid if r["ttr_s"] <= 0.5)
    assert any(math.isinf(r["ttr_s"]) and r["level"] == WarningLevel.WARNING for r in valid)


@pytest.mark.parametrize("name", ["paper-left-turn", "lane-change-iso3888", "sine-sweep", "circle-iso4138"])
def test_no_false_alarms_on_normal_driving(name):
    """The sedan on the paper's left turn and the test-track scenarios: no warning at all.
    Measured peak predicted |LTR|: 0.51, 0.47, 0.21, 0.65 (truth: 0.42, 0.41, 0.20, 0.50)."""
    sim, chain, o = run_chain(name, "sedan-model")
    assert sim.events == []
    assert o.false_alarms == 0 and o.warning_episodes == []
    assert o.frames_rejected == 0 and o.frames_accepted > 45 * sim.t_s
    # nothing close either: the highest level sent is "none"
    assert max(r["level"] for r in o.decoded) == WarningLevel.NONE


def test_replay_with_another_policy_reproduces_the_chain():
    sim, chain, o = run_chain("fishhook-suv", "suv-model")
    pol, nc = load_warning_config()
    frames = replay_assessments(chain.assessments, [s["t_ns"] for s in sim.truth], pol, nc)
    assert [bytes(f.data) for f in frames] == [bytes(f.data) for f in chain.frames]
    # a shorter warning time warns later
    late = evaluate_warning_frames(replay_assessments(chain.assessments, [s["t_ns"] for s in sim.truth],
                                                      WarningPolicy(reaction_time_s=0.4, margin_s=0.1,
                                                                    imminent_time_s=0.2), nc), sim.events)
    assert late.lead_time_s < o.lead_time_s


def test_a_bounded_chain_sends_the_same_frames_and_keeps_only_a_recent_window():
    """``keep`` bounds what the chain stores (a system's chain over a long drive), never what it
    sends: same frames as the chain that keeps everything, counts over the whole run, the last
    ``keep`` frames and assessments kept."""
    sc = load_scenario("fishhook-suv")
    sim = Simulator(scenario=sc)
    sim.run()
    pred = Predictor(load_vehicle("suv-model").with_params(**sc.vehicle.params.as_dict()), load_predictor_config())
    full = WarningChain(pred, *load_warning_config())
    small = WarningChain(pred, *load_warning_config(), keep=7)
    for s in sim.truth[:250]:  # 2.5 s at 100 Hz: 25 predictions, ~125 frames, level changes
        init = initial_state_from_truth(s)
        assert [bytes(f.data) for f in small.handle(s["t_ns"], init)] == \
            [bytes(f.data) for f in full.handle(s["t_ns"], init)]
    assert len(full.assessments) >= 20 and len(full.frames) >= 100
    assert (small.frames_total, small.assessments_total) == (len(full.frames), len(full.assessments))
    assert len(small.frames) == len(small.assessments) == 7
    assert [bytes(f.data) for f in small.frames] == [bytes(f.data) for f in full.frames[-7:]]
    assert list(small.assessments) == full.assessments[-7:] and small.last_assessment == full.assessments[-1]
    with pytest.raises(ValueError, match="keep"):
        WarningChain(pred, keep=-1)


# ----------------------------------------------------------------------------- codec boundary
from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from vdps_hil.codecs.can_encode import quantize  # noqa: E402


@settings(max_examples=200, deadline=None)
@given(ttr=st.one_of(st.none(), st.floats(0.0, 100.0)), ltr=st.floats(-2.0, 2.0),
       roll=st.floats(-4.0, 4.0), status=st.sampled_from(list(WarningStatus)))
def test_node_frames_round_trip_through_the_codec(ttr, ltr, roll, status):
    """Whatever the assessment, the frame decodes (CRC, counter) to the DBC-quantised values."""
    node = WarningNode(WarningPolicy(), WarningNodeConfig())
    a = RolloverAssessment(0, ttr, None, ltr, 0.0, roll, 5.0, "horizon")
    frames = node.handle(0, a, status) + node.handle(20 * MS, None, status)
    samples, dec = decode(frames)
    assert dec.total_rejected == 0 and len(samples) == 2
    s = samples[0]
    assert s.fields["warning_ltr"] == quantize("warning_ltr", ltr)
    assert s.fields["warning_peak_roll_rad"] == quantize("warning_peak_roll_rad", roll)
    assert s.fields["warning_time_to_rollover_s"] == quantize("warning_time_to_rollover_s", ttr)
    assert int(s.fields["warning_status"]) == status and s.valid == (status == WarningStatus.VALID)
    assert int(s.fields["warning_level"]) == WarningPolicy().level(a, 0)


def test_a_diverging_prediction_is_a_counted_fault_not_a_crash():
    """An absurd estimate (suspension compressed 2 m: eq 14's exponential spring overflows)
    must not stop the warning path: the chain counts the failure and sends status 3 (fault) at
    the prediction's deadline (t0 + prediction_latency_s, when its result would have been used)."""
    chain = WarningChain(Predictor(load_vehicle("sedan-model")))
    bad = PredictorInitialState(t_ns=0, pos_g_m=(0.0, 0.0, 0.5), vel_g_mps=(25.0, 0.0, 0.0),
                                euler_g_rad=(0.0, 0.0, 0.0), road_bank_rad=0.0, road_grade_rad=0.0,
                                rate_b_radps=(0.0, 0.0, 0.0), wheel_speed_radps=(80.0,) * 4,
                                susp_deflection_m=(2.0e3,) * 4, susp_deflection_rate_mps=(0.0,) * 4)
    chain.handle(0, bad)
    assert chain.prediction_failures == 0  # not before its deadline
    frames = chain.handle(20 * MS, None)
    assert chain.prediction_failures == 1 and chain.last_failure
    dec = VdpsCanDecoder()
    decoded = [s for f in frames for s in dec.decode(0, f.arbitration_id, bytes(f.data))]
    assert decoded and all(s.fields["warning_status"] == WarningStatus.FAULT for s in decoded)


def test_a_nan_prediction_is_sent_as_a_fault_not_a_crash():
    """A prediction whose wheel loads went NaN (an estimate diverged on a starved live run) gave
    a NaN LTR the encoder refuses: ``vdps log --pipeline``'s tap died on it. The frame goes out
    with status 3 (fault), LTR and roll 0."""
    nan = float("nan")
    a = RolloverAssessment(0, None, None, nan, 0.0, nan, 1.0, "horizon")
    frames = WarningNode().handle(0, a)
    decoded = [s for f in frames for s in VdpsCanDecoder().decode(0, f.arbitration_id, bytes(f.data))]
    assert len(decoded) == 1
    assert decoded[0].fields["warning_status"] == WarningStatus.FAULT
    assert decoded[0].fields["warning_ltr"] == 0.0 and decoded[0].fields["warning_peak_roll_rad"] == 0.0


def test_importing_the_chain_leaves_python_can_unimported():
    """python-can imports asammdf and pandas (about 0.3 s of start-up); a replay without
    predictions and the workbench never send a frame, so importing the warning module and the
    system node must not import it (the frames' encoder imports it when it makes one)."""
    import subprocess
    import sys
    from pathlib import Path

    code = ("import sys; import vdps_hil.prediction.warning, vdps_hil.pipeline.node, vdps_hil.workbench.dataset; "
            "print('can' in sys.modules, 'pandas' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True,
                         cwd=Path(__file__).resolve().parents[1])
    assert out.stdout.split() == ["False", "False"], out.stdout + out.stderr


def test_a_replay_that_sends_warnings_imports_neither_python_can_nor_cantools(tmp_path):
    """The warning frames are packed by the DBC's compiled layout into ``Frame`` objects
    (``codecs.can_encode``): a complete-chain replay writes its /est/can/vdps frames without
    importing cantools or python-can (with asammdf and pandas, about 0.45 s of every replay's
    start-up), in one process and with the decoding child."""
    import subprocess
    import sys
    from pathlib import Path

    from vdps_hil.sim.drive import Drive

    rec = tmp_path / "d.mcap"
    Drive("paper", profile="table1", seed=3, duration_s=1.0).run(str(rec))
    for jobs in (1, 2):
        code = ("import sys; from vdps_hil.app.replay import replay_file; "
                f"doc = replay_file({str(rec)!r}, output={str(tmp_path / f'o{jobs}.mcap')!r}, jobs={jobs}); "
                "print(doc['prediction']['frames_sent'], *(m in sys.modules for m in ('can', 'cantools', 'pandas')))")
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=True,
                             cwd=Path(__file__).resolve().parents[1])
        sent, *imported = out.stdout.split()
        assert int(sent) >= 40 and imported == ["False", "False", "False"], out.stdout + out.stderr
