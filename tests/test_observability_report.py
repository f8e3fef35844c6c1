"""The observability report is computed (null spaces and the generic rank of a sensor set:
``test_observability_explain``): on a simulated Table-1 drive (vdps_hil.sim.drive.Drive, decoded from /raw/ only) dropping sensors
by configuration changes the filter's windows exactly as the generic rank analysis predicts,
never crashes the pipeline, and the identification report says why a problem learns nothing
(inputs missing, not excited); a straight-line drive reports cornering stiffness as not excited."""

from __future__ import annotations

import dataclasses
import io

import pytest

from vdps_hil.estimation.ekf_config import EkfConfig, SensorSet
from vdps_hil.estimation.observability_explain import structural_report
from vdps_hil.estimation.pipeline_config import PipelineConfig
from vdps_hil.geodesy import DEFAULT_ORIGIN
from vdps_hil.identification.observability_report import IdentificationMonitor, input_dependencies, observability_report
from vdps_hil.model.params import load_vehicle
from vdps_hil.pipeline.node import SystemConfig, VdpsSystem
from vdps_hil.realdata.runs import run_pipeline
from vdps_hil.record.decode import decode_recording
from vdps_hil.record.reader import RecordingReader
from vdps_hil.sim.drive import Drive
from vdps_hil.sim.scenarios import parse_scenario

VEH = load_vehicle("sedan-model")


@pytest.fixture(scope="module")
def table1_drive():
    buf = io.BytesIO()
    Drive("paper", profile="table1", seed=1, duration_s=8.0).run(buf)
    buf.seek(0)
    return list(decode_recording(RecordingReader(buf)))


SENSOR_DROPS = {
    "table1": SensorSet(),
    "no suspension": SensorSet(suspension=False),
    "single antenna": SensorSet(gnss="single_antenna"),
    "ESC cluster (esc3)": SensorSet(imu="esc3"),
    "no wheel speeds": SensorSet(wheel_speeds=False),
    "no GNSS": SensorSet(gnss="none"),
}


def _drop_for(ss: SensorSet):
    def drop(s):
        k = s.kind
        return ((k == "suspension" and not ss.suspension) or (k == "wheel_speed" and not ss.wheel_speeds)
                or (k.startswith("gnss") and ss.gnss == "none") or (k == "gnss_att" and ss.gnss == "single_antenna"))
    return drop


def test_dropping_sensors_changes_the_windows_as_the_rank_analysis_predicts(table1_drive):
    print("\nsimulated Table-1 drive (paper scenario, 8 s), analysis layout (road angles estimated), windows of 3 s:")
    for name, ss in SENSOR_DROPS.items():
        cfg = PipelineConfig(ekf=EkfConfig(sensors=ss, estimate_road=True), observability_window_s=3.0)
        r = run_pipeline(VEH, cfg, table1_drive, drop=_drop_for(ss), origin=DEFAULT_ORIGIN)
        st = structural_report(cfg.ekf, VEH.mounting.gnss_lever_arm_m)
        wins = r.pipeline.observability_reports
        doc = observability_report(r.pipeline)
        print(f"  {name:20s} predicted rank {st.rank}/{st.n_states} unobservable {list(st.unobservable)}; windows "
              f"{[(w.rank, list(w.unobservable)) for _, _, w in wins]}; initialised {r.pipeline.ekf.initialized}")
        assert r.pipeline.counters["ekf"]["nan_resets"] == 0
        if ss.gnss == "none":  # positions unobservable: the filter cannot start, and says nothing else
            assert {"x_g_m", "y_g_m"} <= set(st.unobservable)
            assert not r.pipeline.ekf.initialized and wins == () and doc.windows == ()
            continue
        assert len(wins) == 2
        for _, _, w in wins:
            assert w.rank == st.rank and set(w.unobservable) == set(st.unobservable)
        assert all(w.not_excited == () for w in doc.windows)


def test_default_layout_report_explains_what_it_does_not_estimate(table1_drive):
    ss = SensorSet(suspension=False)
    cfg = PipelineConfig(ekf=EkfConfig(sensors=ss), observability_window_s=4.0)
    r = run_pipeline(VEH, cfg, table1_drive, drop=_drop_for(ss), origin=DEFAULT_ORIGIN)
    doc = observability_report(r.pipeline).to_json()
    assert all(w["rank"] == w["n_states"] == 9 for w in doc["windows"])
    assert doc["structural"]["not_estimated"][0]["names"] == ["phi_r_rad", "theta_r_rad"]
    assert "phi_v" in {e["names"][0] for e in doc["structural"]["not_estimated"]}


def _system(samples, ss: SensorSet):
    pc = dataclasses.replace(PipelineConfig(ekf=EkfConfig(sensors=ss), observability_window_s=None),
                             emit_estimates=False)
    system = VdpsSystem(VEH, SystemConfig(pipeline=pc, predict=False, ident_period_s=0.02), DEFAULT_ORIGIN)
    system.identifier = IdentificationMonitor(system.identifier)
    drop = _drop_for(ss)
    for s in samples:
        if not drop(s):
            system.handle(s)
    system.finish()
    return observability_report(system.pipeline, system.identifier).identification


def test_identification_report_says_why(table1_drive):
    full = _system(table1_drive, SensorSet())
    no_susp = _system(table1_drive, SensorSet(suspension=False))
    no_wheels = _system(table1_drive, SensorSet(wheel_speeds=False))
    print("\nidentification on the simulated paper drive (8 s):")
    for label, rep in (("table1", full), ("no suspension", no_susp), ("no wheel speeds", no_wheels)):
        print(f"  {label:16s} " + ", ".join(f"{k} {p.status} ({p.identified}/{len(p.params)})" for k, p in rep.items()))
    print("  " + no_susp["mass"].explanations[0].text)
    print("  " + no_wheels["tracking"].explanations[0].text)
    assert full["mass"].status == "identified" and full["tracking"].status == "identified"
    # Table 1 prints the suspension at 1 Hz: the roll and pitch rows (strut forces) are refused and
    # named as such; I_z, from the yaw row, still learns
    inertia = full["inertia"]
    print("  " + inertia.explanations[0].text)
    assert inertia.status == "partially_identified" and inertia.identified == 1
    assert {e.names[0] for e in inertia.explanations} == {"inertia_x_kgm2", "inertia_y_kgm2"}
    assert "refused as 'suspension too slow'" in inertia.explanations[0].text
    assert no_susp["mass"].status == "inputs_missing" and "susp_deflection_m" in no_susp["mass"].explanations[0].text
    assert no_wheels["tracking"].status == "inputs_missing"
    assert "wheel_speed_radps" in no_wheels["tracking"].explanations[0].text or \
        "slip_ratio" in no_wheels["tracking"].explanations[0].text
    deps = input_dependencies(VEH)
    assert "susp_deflection_m" in deps["mass"] and "slip_angle_rad" in deps["cornering"]
    assert "susp_deflection_m" not in deps["cornering"]


def test_straight_line_drive_reports_cornering_stiffness_not_excited():
    sc = parse_scenario('name = "straight"\nvehicle = "sedan-truth"\nduration_s = 8.0\n[initial]\nspeed_mps = 20.0\n')
    buf = io.BytesIO()
    Drive(sc, profile="table1", seed=2).run(buf)
    buf.seek(0)
    rep = _system(list(decode_recording(RecordingReader(buf))), SensorSet())
    c = rep["cornering"]
    print(f"\nstraight line, all sensors: cornering {c.status}, gains {c.gains}: {c.explanations[0].text}")
    assert c.status == "not_excited" and c.identified == 0
    assert "row 1 max |A| 0 < 0.0002" in c.explanations[0].text  # no steering at all
    assert rep["mass"].status == "identified"
