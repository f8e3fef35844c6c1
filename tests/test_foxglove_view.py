"""Tests of vdps_hil.app.foxglove_view: the quaternion is the orientation of eq 1 (rotating a
vector by it equals (C_g^v)^T, the vehicle axes in ENU); the view writes /decoded/, /gnss/fix,
/est/fix (the estimate's position back in WGS-84 about the origin), /est/tf, /est/pose and
/est/warning into a real MCAP read back with the mcap library; the sample bytes are
write_sample's."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader

from vdps_hil.app.foxglove_view import WARNING_TOPIC, FoxgloveView, sample_payload, vehicle_quaternion
from vdps_hil.bus.samples import Sample
from vdps_hil.codecs.can_e2e import crc8_j1850
from vdps_hil.estimation.estimates import Estimate
from vdps_hil.geodesy import EnuOrigin
from vdps_hil.model.frames import dcm_gv
from vdps_hil.pipeline.outputs import CanFrame
from vdps_hil.record import schemas as S
from vdps_hil.record.writer import RecordingWriter

ANGLE = st.floats(-1.4, 1.4)


def _rotate(q, v):
    x, y, z, w = q
    u = np.array([x, y, z])
    v = np.asarray(v, float)
    return v + 2.0 * np.cross(u, np.cross(u, v) + w * v)


@settings(max_examples=200, deadline=None)
@given(phi=ANGLE, theta=ANGLE, psi=st.floats(-3.1, 3.1))
def test_quaternion_is_the_transpose_of_eq_1(phi, theta, psi):
    q = vehicle_quaternion(phi, theta, psi)
    assert math.fsum(c * c for c in q) == pytest.approx(1.0, abs=1e-12)
    c_vg = dcm_gv(phi, theta, psi).T  # vehicle -> ENU
    for axis in np.eye(3):
        np.testing.assert_allclose(_rotate(q, axis), c_vg @ axis, atol=1e-12)


def test_signs_nose_up_and_right_side_down():
    nose = _rotate(vehicle_quaternion(0.0, 0.1, 0.0), (1, 0, 0))
    assert nose[2] > 0  # pitch nose-up positive (eq 1 as printed)
    left = _rotate(vehicle_quaternion(0.1, 0.0, 0.0), (0, 1, 0))
    assert left[2] > 0  # roll right-side-down positive: the left side rises
    heading = _rotate(vehicle_quaternion(0.0, 0.0, math.pi / 2), (1, 0, 0))
    np.testing.assert_allclose(heading, (0, 1, 0), atol=1e-12)  # yaw CCW from East: north


def _read(path):
    out = {}
    with open(path, "rb") as f:
        for schema, channel, msg in make_reader(f).iter_messages():
            out.setdefault(channel.topic, []).append((schema.name, msg.log_time, json.loads(msg.data)))
    return out


def _warning_frame(t_ns, level, counter):
    body = bytes([(counter & 0xF) | (level << 4), 0xFF, 0xFF, 0x10, 0x00, 0x20, 0x00])
    return CanFrame(t_ns, "vdps", 0x80, bytes([crc8_j1850(body)]) + body)


def test_view_topics_in_a_real_mcap(tmp_path):
    origin = EnuOrigin(24.7869, 120.9975, 100.0)
    epoch = S.DEFAULT_SIM_EPOCH_NS
    view = FoxgloveView(lambda: origin, epoch_ns=epoch)
    gnss = Sample(1_000_000, "gnss", "gnss_pos", {"gnss_lat_deg": 24.7869, "gnss_lon_deg": 120.9975,
                                                 "gnss_alt_m": 100.0}, 0, True)
    imu = Sample(2_000_000, "imu", "imu", {"specific_force_mps2_z": 9.81, "angular_rate_radps_x": math.nan}, 0, True)
    x = (100.0, -50.0, 2.0, 25.0, 0.0, 0.0, 0.02, -0.01, 0.3, 0.0, 0.0, 0.3)
    est = Estimate(3_000_000, x, (0.5, 0.6, 1.0) + (0.1,) * 9, (0.0, 0.0, 0.3), (0.0,) * 3)
    path = tmp_path / "view.mcap"
    with RecordingWriter(path, sim_epoch_ns=epoch) as w:
        view.samples([gnss, imu], w)
        view.outputs([est, _warning_frame(4_000_000, 2, 1), _warning_frame(4_020_000, 3, 2)], w)
    got = _read(path)
    assert set(got) == {"/decoded/gnss/gnss_pos", "/decoded/imu/imu", S.GNSS_FIX_TOPIC, S.EST_FIX_TOPIC,
                        S.EST_TF_TOPIC, S.EST_POSE_TOPIC, WARNING_TOPIC}
    for topic, msgs in got.items():
        for name, log_time, doc in msgs:
            assert S.validate(doc, S.SCHEMAS[name]) == [], topic
            if "timestamp" in doc:  # the Foxglove stamp is the message's log time
                assert doc["timestamp"]["sec"] * 10**9 + doc["timestamp"]["nsec"] == log_time
    (_, log_time, tf), = got[S.EST_TF_TOPIC]
    assert log_time == epoch + 3_000_000
    assert (tf["parent_frame_id"], tf["child_frame_id"]) == ("enu", "vehicle")
    assert tf["translation"] == {"x": 100.0, "y": -50.0, "z": 2.0}
    assert list(tf["rotation"].values()) == pytest.approx(vehicle_quaternion(0.02, -0.01, 0.3))
    (_, _, fix), = got[S.EST_FIX_TOPIC]
    np.testing.assert_allclose(origin.to_enu(fix["latitude"], fix["longitude"], fix["altitude"]), x[:3], atol=1e-6)
    assert fix["position_covariance"][0] == pytest.approx(0.25) and fix["position_covariance_type"] == 2
    levels = [d["fields"]["warning_level"] for _, _, d in got[WARNING_TOPIC]]
    assert levels == [2.0, 3.0]
    (_, _, imu_doc), = got["/decoded/imu/imu"]
    assert imu_doc["fields"]["angular_rate_radps_x"] is None  # NaN -> null
    assert view.refused == 0


def test_no_fix_without_an_origin_and_nothing_for_non_finite_states(tmp_path):
    view = FoxgloveView(epoch_ns=0)
    x = (math.nan,) * 12
    path = tmp_path / "v.mcap"
    with RecordingWriter(path, sim_epoch_ns=0) as w:
        view.outputs([Estimate(5, (0.0,) * 12, (1.0,) * 12, (0.0,) * 3, (0.0,) * 3),
                      Estimate(6, x, x, (0.0,) * 3, (0.0,) * 3)], w)
    got = _read(path)
    assert set(got) == {S.EST_TF_TOPIC, S.EST_POSE_TOPIC}
    assert len(got[S.EST_TF_TOPIC]) == 1


def test_sample_payload_is_write_sample_s(tmp_path):
    s = Sample(7, "can.vdps", "steer", {"steer_wheel_angle_rad": 0.25, "seq_counter": math.inf}, 9, False)
    assert sample_payload(s) == json.dumps(s.to_json(), separators=(",", ":"), allow_nan=False).encode()
    assert json.loads(sample_payload(s))["fields"]["seq_counter"] is None


def test_samples_into_a_recording_writer_are_those_written_one_by_one(tmp_path):
    """The view writes a batch of samples into a RecordingWriter as one run per topic
    (``write_encoded_run``): per topic the same messages as one write_encoded per sample (a
    writer without runs: the live server's); a sample with a time out of range refused and
    counted, the others written."""
    rng = np.random.default_rng(5)
    samples = []
    for k in range(300):
        kind = ("imu", "steer", "gnss_pos")[k % 3]
        f = {"gnss_lat_deg": 24.0 + rng.normal(0, 1e-4), "gnss_lon_deg": 121.0, "gnss_alt_m": 10.0} \
            if kind == "gnss_pos" else {"v": float(rng.normal()), "w": math.nan}
        samples.append(Sample(k * 1_000_000, "src", kind, f, 0, bool(k % 7)))
    samples.append(Sample(-5, "src", "imu", {"v": 1.0}, 0, True))
    got, refused = [], []
    for runs in (True, False):
        view = FoxgloveView(epoch_ns=S.DEFAULT_SIM_EPOCH_NS)
        path = tmp_path / f"{runs}.mcap"
        with RecordingWriter(path, sim_epoch_ns=S.DEFAULT_SIM_EPOCH_NS) as w:
            view.samples(samples, w if runs else _OneByOne(w))
        got.append(_read(path))
        refused.append(view.refused)
    assert got[0] == got[1]
    assert len(got[0]["/decoded/src/imu"]) == 100 and len(got[0][S.GNSS_FIX_TOPIC]) == 100
    assert refused == [1, 1]


class _OneByOne:
    """A writer without write_encoded_run (the view then writes sample by sample)."""

    def __init__(self, w):
        self.write_encoded, self.write_json = w.write_encoded, w.write_json
