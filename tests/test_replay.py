"""Tests of vdps_hil.app.replay: file replay with a saved workbench model (--model), the
sensor-set probe (``sample_stats``)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from vdps_hil.app.replay import sample_stats
from vdps_hil.bus.samples import Sample
from vdps_hil.model.params import load_vehicle
from vdps_hil.sim.drive import Drive


def test_replay_with_a_saved_model(tmp_path):
    """``replay_file(model=...)`` reads a ``vdps diagnose --save-model`` file: its parameters
    start the identifier, its effects join the predictor, the JSON says so; --params with
    --model and a broken model file are one-line errors."""
    from vdps_hil.model.effects import REGISTRY, EffectSet
    from vdps_hil.app.replay import ReplayError, replay_file
    from vdps_hil.workbench.model_file import save_model

    drive = tmp_path / "paper.mcap"
    Drive("paper", seed=5, duration_s=2.0).run(drive)
    veh = load_vehicle("sedan-model", "model")
    m = save_model(tmp_path / "m.toml", veh.with_params(inertia_x_kgm2=1400.0),
                   EffectSet([REGISTRY["aero_drag"](cda_m2=0.7), REGISTRY["imu_bias"]()]))
    doc = replay_file(drive, model=m, predict=False)
    assert doc["model"]["predictor_effects"] == ["aero_drag"]
    assert doc["model"]["imu_corrected"] == ["imu_bias"]
    # the file's parameters are the identifier's start (the vehicle file's prior Ix is 715)
    from vdps_hil.app.replay import _load_workbench_model

    start, effects, _ = _load_workbench_model(m, veh)
    assert start.inertia_x_kgm2 == 1400.0 and veh.params.inertia_x_kgm2 == 715.0
    assert [e.name for e in effects] == ["aero_drag", "imu_bias"]
    with pytest.raises(ReplayError, match="not both"):
        replay_file(drive, model=m, params=m)
    bad = tmp_path / "bad.toml"
    bad.write_text(Path(m).read_text().replace('"aero_drag"', '"no_such_effect"'))
    with pytest.raises(ReplayError) as e:
        replay_file(drive, model=bad)
    assert len(str(e.value).splitlines()) == 1 and "no_such_effect" in str(e.value)


def test_saved_imu_bias_is_taken_out_of_the_readings(tmp_path):
    """A drive whose IMU has a large hidden bias (0.3 m/s^2 on x and y, 0.01 rad/s on z: a
    badly calibrated unit; lane change, seed 3, 12 s): without the model the EKF's GNSS
    innovations are inconsistent (measured before the aiding monitor: 32/60 positions, 7/60
    velocities accepted; with it 60/60, 53/63 attitudes, 42/68 velocities); with a saved
    model naming that bias, ``VdpsSystem`` removes it from every IMU reading and >= 95 % of
    the GNSS position and attitude updates pass the chi-square gate."""
    from vdps_hil.model.effects import REGISTRY, EffectSet
    from vdps_hil.app.replay import replay_file
    from vdps_hil.workbench.model_file import save_model

    drive = tmp_path / "biased.mcap"
    Drive("lane-change-iso3888", seed=3, duration_s=12.0,
          effects=["imu_bias:accel_bias_x_mps2=0.3,accel_bias_y_mps2=0.3,gyro_bias_z_radps=0.01"]).run(drive)
    bias = REGISTRY["imu_bias"](accel_bias_x_mps2=0.3, accel_bias_y_mps2=0.3, accel_bias_z_mps2=0.0,
                                gyro_bias_x_radps=0.0, gyro_bias_y_radps=0.0, gyro_bias_z_radps=0.01)
    m = save_model(tmp_path / "m.toml", load_vehicle("sedan-model", "model"), EffectSet([bias]))
    plain = replay_file(drive, identify=False, predict=False)["innovations"]
    fixed = replay_file(drive, model=m, identify=False, predict=False)["innovations"]
    for kind in ("gnss_pos", "gnss_att"):
        assert fixed[kind]["accepted"] >= 0.95 * fixed[kind]["updates"], fixed[kind]
    # without the model the bias shows: since the aiding monitor re-acquires after 3 gated
    # fixes (issue 20) the positions pass again, but the GNSS innovations are not consistent
    # (gated fixes): over the three kinds, the accepted fractions sum to 0.3 less than with it
    kinds = ("gnss_pos", "gnss_att", "gnss_vel")
    assert sum(plain[k]["accepted"] / plain[k]["updates"] for k in kinds) < \
        sum(fixed[k]["accepted"] / fixed[k]["updates"] for k in kinds) - 0.3, (plain, fixed)


def test_a_saved_steering_offset_is_taken_out_of_the_steering_before_the_identifier(tmp_path):
    """A drive whose steering-angle sensor reads 0.05 rad (2.9 deg) high (lane change, seed 3,
    12 s): the identifier's slip angles take the reading as the road wheels' angle. With a saved
    model naming the offset, ``VdpsSystem`` takes it out of every steering sample: the cornering
    problem is identified and both axle stiffnesses are within issue 17's 15 % of the truth file's
    (measured -8.4 % / -7.1 %); without it the front stiffness is further off (measured -16 %,
    not converged)."""
    from vdps_hil.model.effects import REGISTRY, EffectSet
    from vdps_hil.app.replay import replay_file
    from vdps_hil.workbench.model_file import save_model

    drive = tmp_path / "offset.mcap"
    Drive("lane-change-iso3888", seed=3, duration_s=12.0, effects=["steering_offset:offset_rad=0.05"]).run(drive)
    m = save_model(tmp_path / "m.toml", load_vehicle("sedan-model", "model"),
                   EffectSet([REGISTRY["steering_offset"](offset_rad=0.05)]))
    truth = load_vehicle("sedan-truth").params
    plain = replay_file(drive, identify=True, predict=False)["identification"]
    fixed = replay_file(drive, model=m, identify=True, predict=False)["identification"]
    err = {}
    for name, r in (("plain", plain), ("fixed", fixed)):
        err[name] = {p: r["params"][p] / getattr(truth, p) - 1.0
                     for p in ("cornering_stiffness_front_nprad", "cornering_stiffness_rear_nprad")}
    assert fixed["converged"]["cornering"], fixed["status"]
    assert all(abs(e) <= 0.15 for e in err["fixed"].values()), err
    assert abs(err["plain"]["cornering_stiffness_front_nprad"]) > abs(err["fixed"]["cornering_stiffness_front_nprad"]), err


def test_sample_stats_takes_the_first_seconds_and_leaves_the_rest():
    """``sample_stats`` (the replay's sensor-set probe, run on the decoder the replay then goes on
    reading): the samples it takes plus those left in the iterator are the whole stream, in order;
    rates count one instant of one kind once (two wheel half-frames at 1 kHz -> 1000 Hz, not
    2000); fields are those with a finite value."""
    stream = []
    for i in range(5000):  # 5 s: IMU at 1 kHz, wheel half-frames at 1 kHz, suspension at 10 Hz
        t = i * 1_000_000
        stream.append(Sample(t, "imu", "imu", {"angular_rate_radps_z": 0.1, "specific_force_mps2_x": 0.2,
                                               "specific_force_mps2_y": 0.0, "specific_force_mps2_z": math.nan}))
        stream.append(Sample(t, "can", "wheel_speed", {"wheel_speed_radps_1": 1.0, "wheel_speed_radps_2": 1.0}))
        stream.append(Sample(t, "can", "wheel_speed", {"wheel_speed_radps_3": 1.0, "wheel_speed_radps_4": 1.0}))
        if i % 100 == 0:
            stream.append(Sample(t, "can", "suspension", {"susp_deflection_m_1": 0.0}))
    it = iter(stream)
    taken, rates, fields = sample_stats(it, 3.0)
    assert taken + list(it) == stream
    assert taken[-1].t_ns > 3_000_000_000 >= taken[-2].t_ns  # the window ends with the first sample after it
    assert rates["imu"] == pytest.approx(1000.0, rel=1e-9) and rates["wheel_speed"] == pytest.approx(1000.0, rel=1e-9)
    assert rates["suspension"] == pytest.approx(10.0, rel=1e-9)
    assert fields["imu"] == {"angular_rate_radps_z", "specific_force_mps2_x", "specific_force_mps2_y"}
    assert fields["wheel_speed"] == {f"wheel_speed_radps_{i}" for i in range(1, 5)}


def _gnss_then_imu(imu_from_s: float | None, duration_s: float = 40.0) -> list:
    """GNSS at 4 Hz from 0 s, an IMU at 100 Hz from ``imu_from_s`` (None: never)."""
    out = []
    for i in range(int(duration_s * 100)):
        t = i * 10_000_000
        if i % 25 == 0:
            out.append(Sample(t, "gnss", "gnss_pos", {"gnss_lat_deg": 40.0, "gnss_lon_deg": -105.0}))
        if imu_from_s is not None and t >= imu_from_s * 1e9:
            out.append(Sample(t, "imu", "imu", {"specific_force_mps2_x": 0.1, "specific_force_mps2_y": 0.0,
                                                 "specific_force_mps2_z": 9.8, "angular_rate_radps_x": 0.0,
                                                 "angular_rate_radps_y": 0.0, "angular_rate_radps_z": 0.01}))
    return out


def test_sample_stats_waits_for_an_imu_that_starts_after_the_gnss():
    """A real drive may start its IMU after its GNSS (the rtklibexplorer drive: 3.4 s later): the
    probe then runs 3 s from the first IMU sample, so the IMU is found and its rate measured;
    without any IMU it stops 30 s after the first sample (``PROBE_MAX_SECONDS``), not at the end
    of the file. An IMU within the first 3 s leaves the window at 3 s."""
    stream = _gnss_then_imu(5.0)
    it = iter(stream)
    taken, rates, fields = sample_stats(it, 3.0)
    assert taken + list(it) == stream
    assert 8.0e9 < taken[-1].t_ns <= 8.0e9 + 1e7  # 3 s after the IMU's first sample at 5 s
    assert rates["imu"] == pytest.approx(100.0, rel=1e-9) and rates["gnss_pos"] == pytest.approx(4.0, rel=1e-9)
    assert "angular_rate_radps_z" in fields["imu"]
    taken, rates, fields = sample_stats(iter(_gnss_then_imu(None)), 3.0)
    assert 30.0e9 < taken[-1].t_ns <= 30.0e9 + 2.5e8 and "imu" not in fields
    taken, _, _ = sample_stats(iter(_gnss_then_imu(1.0)), 3.0)
    assert 3.0e9 < taken[-1].t_ns <= 3.0e9 + 1e7
