"""Issue 17: does a chain whose identification is mismatched or unexcited ever send a *valid*
warning? The whole chain as ``vdps replay`` runs it by default (identification from the model
file's priors; a frame is valid only once the problems of ``require_converged`` have converged,
``configs/prediction``) on drives of CommonRoad's multibody truth, the vehicle that is not the
model.

Per drive it prints the VDPS_Warning frames by level and status (0 valid, 1 not converged, 2
sensor missing, 3 fault), the valid frames of level >= 2 (a warning a driver or ECU would act on;
none of these drives rolls over: CommonRoad's model has no wheel lift-off) and each
identification problem's status at the end.

Usage::

    .venv/bin/python tools/warning_validity.py [--sets 1 3] [--seeds 102] [--scenario NAME ...]
                                               [--jobs 2] [--json FILE]
"""

from __future__ import annotations

import argparse
import collections
import io
import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from vdps_hil.experiments.ident_study import CR_SCENARIOS, STUDY_SEEDS  # noqa: E402

STATUS = {0: "valid", 1: "not converged", 2: "sensor missing", 3: "fault"}


def run_drive(job: tuple[str, int, int]) -> dict:
    """One drive through the default chain: frames by (level, status), problem statuses."""
    from vdps_hil.codecs.can_decode import VdpsCanDecoder
    from vdps_hil.experiments.workbench_study import model_file
    from vdps_hil.geodesy import DEFAULT_ORIGIN
    from vdps_hil.model.params import load_vehicle
    from vdps_hil.pipeline.node import SystemConfig, VdpsSystem
    from vdps_hil.pipeline.outputs import CanFrame
    from vdps_hil.record.decode import decode_recording
    from vdps_hil.record.reader import RecordingReader
    from vdps_hil.sim.drive import Drive

    scenario, set_id, seed = job
    t0 = time.process_time()
    buf = io.BytesIO()
    truth = f"commonroad-mb:{set_id}"
    Drive(scenario, profile="table1-susp1k", seed=seed, truth=truth).run(buf)
    buf.seek(0)
    system = VdpsSystem(load_vehicle(model_file(truth), "model"), SystemConfig.for_profile(1000.0, 0.001),
                        origin=DEFAULT_ORIGIN)
    dec, frames = VdpsCanDecoder(), collections.Counter()
    for s in decode_recording(RecordingReader(buf)):  # /raw/ topics only, as vdps replay
        for o in system.handle(s):
            if isinstance(o, CanFrame):
                for d in dec.decode(o.t_ns, o.arbitration_id, o.data):
                    frames[(int(d.fields["warning_level"]), int(d.fields["warning_status"]))] += 1
        system.clear_input_log()
    problems = {name: st.status for name, st in system.identifier.problem_status.items()}
    return {"scenario": scenario, "set": set_id, "seed": seed,
            "frames": {f"{lv}/{st}": n for (lv, st), n in sorted(frames.items())},
            "valid_warnings": sum(n for (lv, st), n in frames.items() if lv >= 2 and st == 0),
            "problems": problems, "cpu_s": time.process_time() - t0}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sets", type=int, nargs="+", default=[1, 3], choices=[1, 3])
    ap.add_argument("--seeds", type=int, nargs="+", default=list(STUDY_SEEDS[:1]))
    ap.add_argument("--scenario", action="append", default=None, choices=CR_SCENARIOS)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    jobs = [(sc, s, seed) for seed in a.seeds for s in a.sets for sc in (a.scenario or CR_SCENARIOS)]
    with ProcessPoolExecutor(max_workers=max(1, a.jobs)) as ex:
        rows = list(ex.map(run_drive, jobs))
    print("| drive | frames level/status: count | valid level >= 2 | problems at the end |\n|---|---|---|---|")
    for r in rows:
        fr = ", ".join(f"{k}: {n}" for k, n in r["frames"].items())
        pr = ", ".join(f"{k} {v}" for k, v in r["problems"].items())
        print(f"| {r['scenario']} cr{r['set']} seed {r['seed']} | {fr} | {r['valid_warnings']} | {pr} |")
    total = sum(r["valid_warnings"] for r in rows)
    print(f"\n{len(rows)} drives, {total} valid frames of level >= 2 (status: {STATUS})")
    if a.json:
        Path(a.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
