"""``vdps replay``: run the vehicle dynamic prediction system on a recording's ``/raw/`` topics
(``vdps_hil.app.replay.replay_file``) and write the estimates, innovations, identified parameters,
predictions and warning frames."""

from __future__ import annotations

import os
from pathlib import Path

import click

from vdps_hil.cli.common import (UserError, eprint, json_option, live_server, quiet_option, recording_span_s,
                                require_file, serve_option, write_json)

_EXAMPLE = """\b
Examples:
  vdps sim paper -o paper.mcap && vdps replay paper.mcap -o paper-est.mcap --json -
  vdps replay drive.mcap --vehicle configs/vehicles/sedan-model.toml --save-params sedan.json
  vdps replay drive.mcap --params sedan.json --no-predict --json summary.json
  vdps replay rav4.mcap --vehicle rav4-model --signalmap toyota_rav4_2017 --dbc toyota.dbc \\
      --sensorset rav4-can-ublox
  vdps replay paper.mcap --paper-faithful all --no-identify --no-predict --json -
  vdps replay paper.mcap --serve 8765     # watch it live in Foxglove (ws://127.0.0.1:8765)

\b
Only /raw/ topics are read (never /truth/; /decoded/ only with --input-order recorded).
Output topics: the /raw/ topics copied, /est/state (12 states of eq 7 + road-relative angles, with sigmas),
/est/innovation/<kind> (innovation, sigma, NIS, status), /est/filtered (alpha-beta),
/est/ident (identified parameters, sigmas), /est/prediction (rollover assessment),
/est/can/vdps (the VDPS_Warning frames the system sent); the Foxglove view (unless --no-view):
/decoded/<source>/<kind> (the decoded inputs), /gnss/fix and /est/fix (foxglove.LocationFix),
/est/tf (foxglove.FrameTransform enu -> vehicle), /est/pose (foxglove.PoseInFrame), /est/warning.
A recording made by vdps import/log with a signal map is decoded with the signal map and DBC its
metadata names (found by path and content hash) unless --signalmap/--dbc are given."""

def _usable_cpus() -> int:
    """CPUs this process may run on (its affinity mask where the system has one)."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


PAPER_SWITCHES = ("a_psi_v_zero_rate", "b_y2_gps", "c_y2_sus_single_plane", "d_accel_as_acceleration", "all")


@click.command("replay", epilog=_EXAMPLE)
@click.argument("recording", metavar="FILE.mcap")
@click.option("--vehicle", default="sedan-model", show_default=True, metavar="MODEL_FILE",
              help="Model vehicle file or name (a truth file is refused).")
@click.option("--model", "model_file", default=None, metavar="FILE",
              help="A saved workbench model (effects + identified parameters).")
@click.option("--dbc", default=None, metavar="FILE", help="DBC of the car's bus (with --signalmap).")
@click.option("--signalmap", default=None, metavar="FILE",
              help="Signal map (configs/signalmaps/NAME or a .toml path) for a foreign DBC.")
@click.option("--bus", "bus_map", multiple=True, metavar="REC=MAP",
              help="Decode recording bus REC with the signal map's bus MAP; repeatable.")
@click.option("--sensorset", default=None, metavar="NAME",
              help="Sensor set (configs/sensorsets/NAME or a .toml path) [default: inferred from "
                   "the recording's fields].")
@click.option("-o", "--output", default=None, metavar="OUT.mcap",
              help="Write a complete recording: the raw topics plus the /est/ topics.")
@click.option("--no-view", is_flag=True,
              help="Leave the Foxglove view out of -o (/decoded/, /gnss/fix, /est/fix, /est/tf, /est/pose, "
                   "/est/warning): a smaller, faster output.")
@json_option
@click.option("--params", default=None, metavar="FILE",
              help="Start the identifier from parameters saved by an earlier drive.")
@click.option("--save-params", default=None, metavar="FILE",
              help="Save the identified parameters (JSON) for the next drive.")
@click.option("--no-identify", is_flag=True, help="Do not run the parameter identifier.")
@click.option("--no-predict", is_flag=True, help="Do not run the predictor and the rollover warning.")
@click.option("--susp-sigma", "susp_sigma_m", type=float, default=0.001, show_default=True, metavar="M",
              help="Suspension sensor noise (1-sigma) [m] (Table 1: 1 mm).")
@click.option("--paper-faithful", "paper_faithful", multiple=True, type=click.Choice(PAPER_SWITCHES),
              help="EKF correction switched to the paper as printed (repeatable; 'all').")
@click.option("--input-order", "input_order", type=click.Choice(("time", "recorded")), default="time",
              show_default=True,
              help="time: the /raw/ topics decoded, in time order; recorded: the /decoded/ samples in the "
                   "order the live system received them (a vdps bench -o recording), reproducing its estimates.")
@click.option("--jobs", type=click.IntRange(1, 2), default=None, metavar="N",
              help="2: decode the recording and write the output in a second process while this one runs "
                   "the system (same output, less wall time) [default: 2 when this process may use two or "
                   "more cores, else 1].")
@serve_option
@quiet_option
def replay(recording, vehicle, model_file, dbc, signalmap, bus_map, sensorset, output, no_view, json_out, params,
           save_params, no_identify, no_predict, susp_sigma_m, paper_faithful, input_order, jobs, serve_port, quiet):
    """Replay FILE.mcap through the estimator, identifier, predictor and warning (the paper's
    Figure 2) using only its /raw/ topics; print a one-line summary."""
    from vdps_hil.app.replay import ReplayError, replay_file

    src = Path(recording)
    require_file(recording)
    if output is not None:
        out = Path(output)
        if out.resolve() == src.resolve():
            raise UserError("-o must not overwrite the input recording")
        if out.is_dir():
            raise UserError(f"-o {output}: is a directory")
        if not out.parent.exists():
            raise UserError(f"-o {output}: directory {out.parent} does not exist")
    buses = {}
    for spec in bus_map:
        rec, eq, mp = spec.partition("=")
        if not eq or not rec or not mp:
            raise UserError(f"--bus {spec!r}: expected REC=MAP")
        buses[rec] = mp
    from vdps_hil.batch.progress import ProgressBar

    try:
        with live_server(serve_port, wait=True) as live, \
                ProgressBar(recording_span_s(recording), "vdps replay", unit="s", quiet=quiet) as bar:
            doc = replay_file(recording, vehicle=vehicle, output=output, model=model_file, dbc=dbc,
                              signalmap=signalmap, bus_map=buses or None, params=params, save_params=save_params,
                              identify=not no_identify, predict=not no_predict, susp_sigma_m=susp_sigma_m,
                              paper_faithful=paper_faithful or None, sensorset=sensorset, input_order=input_order,
                              jobs=jobs if jobs is not None else (2 if _usable_cpus() >= 2 else 1),
                              foxglove=not no_view, progress=bar.callback(), serve=live)
    except ReplayError as e:
        raise UserError(str(e)) from None
    for note in undecoded_notes(doc):
        eprint(f"vdps replay: warning: {note}")
    problems = doc.get("decode", {}).get("reader", {}).get("problems") or []
    if problems:  # skipped parts of a damaged file are said without --json too
        more = f" (and {len(problems) - 1} more: see --json decode.reader.problems)" if len(problems) > 1 else ""
        eprint(f"vdps replay: warning: parts of {recording} skipped: {problems[0]}{more}")
    click.echo(summary_line(doc, output), err=bool(json_out == "-"))
    from vdps_hil.estimation.sensorsets import not_used_note

    sset = doc.get("sensor_set") or {}
    unused = not_used_note(sset.get("not_used"), sset.get("kind_map"))
    if unused:  # a sensor in the recording the sensor set does not name (estimation.sensorsets.KindMap)
        click.echo("  " + unused, err=bool(json_out == "-"))
    for name, st in doc.get("identification", {}).get("status", {}).items():
        if st["status"] != "converged":  # never a silent "identified": say which and why
            why = [f"{p} {v['status']}" for p, v in st["params"].items() if v["status"] != "identified"]
            rows = f" (rows: {', '.join(st['mismatch_rows'])})" if st["mismatch_rows"] else ""
            click.echo(f"  {name}: {st['status']}{rows}: {'; '.join(why)}", err=bool(json_out == "-"))
    for line in (warning_line(doc), predictor_params_line(doc)):
        if line:
            click.echo(line, err=bool(json_out == "-"))
    line = params_line(doc)
    if line:
        click.echo(line, err=bool(json_out == "-"))
    write_json(doc, json_out)


def params_line(doc: dict) -> str | None:
    """What a ``--params`` file had not settled (per parameter where it says, else per problem) and
    what the warning waited for here, or None."""
    un = doc.get("params_unsettled")
    if not un:
        return None
    per = doc.get("params_not_identified") or un
    waits = (doc.get("prediction") or {}).get("require_converged") or []
    tail = (f"; the warning waited for {', '.join(waits)} to be identified here" if waits
            else "; the warning did not wait for them (its validity rule, [warning] require_converged, "
                 "does not name them)")
    return "  --params: not identified when saved: " + ", ".join(_by_problem(per)) + tail


def _by_problem(per: dict) -> list[str]:
    """"name status" per entry, a problem's parameters that share one status said once as
    "problem (all n) status" (the entries are parameters or problems)."""
    from vdps_hil.identification.config import PROBLEM_PARAMS

    out, done = [], set()
    for k, v in per.items():
        if k in done:
            continue
        prob = next((p for p, names in PROBLEM_PARAMS.items() if k in names), None)
        names = PROBLEM_PARAMS.get(prob, ())
        if len(names) > 1 and all(per.get(n) == v for n in names):
            out.append(f"{prob} (all {len(names)}) {v}")
            done.update(names)
        else:
            out.append(f"{k} {v}")
    return out


def summary_line(doc: dict, output=None) -> str:
    """The one-line summary of a replay: duration, messages, estimates, speed, and the identified
    mass only where the identifier says it converged (``identification.converged``), else "not
    converged" (the number would be the model file's prior)."""
    es = doc["estimates_summary"]
    rtf = doc.get("realtime_factor")
    line = (f"vdps replay: {doc['duration_s']:.1f} s, {doc['messages_read']['raw_records']} raw messages, "
            f"{es['count']} estimates, {doc['wall_time_s']:.1f} s wall"
            + (f" ({rtf:.1f}x real time)" if rtf else ""))
    ident = doc.get("identification")
    if ident:
        conv = ident.get("converged") or {}
        if conv.get("mass"):
            sig = (ident.get("sigmas") or {}).get("mass_kg")
            line += f", mass {ident['params']['mass_kg']:.0f}" + (f" +- {sig:.0f}" if sig else "") + " kg"
        waiting = sorted(n for n, c in conv.items() if not c)
        if waiting:
            line += f"{';' if conv.get('mass') else ','} not converged: {', '.join(waiting)}"
    if output:
        line += f" -> {output}"
    return line


def warning_line(doc: dict) -> str | None:
    """One line on the rollover warning frames the replay sent: how many were valid (status 0),
    from when, the highest valid level, what the others said, and, when none was valid for want of
    convergence, what the warning waits for (``require_converged`` held ``converged_hold_s``), or
    for want of inputs, what the predictor needs (whichever status the most frames said)."""
    from vdps_hil.prediction.warning import WarningLevel

    p = doc.get("prediction")
    if not p or not p.get("frames_sent") or "frames_by_status" not in p:
        return None
    by = p["frames_by_status"]
    line = f"  warning: {by['valid']} of {p['frames_sent']} frames valid"
    if by["valid"]:
        line += f" from {p['first_valid_s']:.2f} s, highest valid level {WarningLevel(p['max_level_valid']).name.lower()}"
    others = [f"{k.replace('_', ' ')} {by[k]}" for k in ("not_converged", "sensor_missing", "fault") if by[k]]
    if others:
        line += f" (the others: {', '.join(others)})"
    if not by["valid"] and by["not_converged"] >= by["sensor_missing"] and p.get("require_converged"):
        unsettled = bool(doc.get("params_unsettled"))  # from a --params file that had not settled them
        line += (f"; {'' if unsettled else 'from the priors '}a frame is valid once {', '.join(p['require_converged'])}"
                 f" has converged and stayed so {p['converged_hold_s']:g} s ([warning] of the prediction config)"
                 + ("; the --params file had not settled it" if unsettled else "; --params starts from saved parameters"))
    elif not by["valid"] and by["sensor_missing"]:
        line += "; sensor missing: the predictor needs the steering, the wheel torques, the IMU rates and the wheel speeds"
    return line


def predictor_params_line(doc: dict) -> str | None:
    """One line on the parameters the predictor used at the end (``identification.trusted``): how
    many were identified then, held from an earlier identification, or still their start values
    (named)."""
    src = (doc.get("prediction") or {}).get("param_sources")
    if not src:
        return None
    n = {k: sum(1 for v in src.values() if v == k) for k in ("identified", "held", "start")}
    line = f"  predictor parameters at the end: {n['identified']} identified, {n['held']} held from earlier"
    if n["start"]:
        line += f", {n['start']} at the run's start values ({', '.join(k for k, v in src.items() if v == 'start')})"
    return line


def undecoded_notes(doc: dict) -> list[str]:
    """One line per ``/raw/can/`` topic whose frames were not decoded (the decoder's counters
    ``decode.reader.undecoded``), with the reason and the options that decode it."""
    notes = []
    undecoded = (doc.get("decode", {}).get("reader") or {}).get("undecoded") or {}
    for topic, n in sorted(undecoded.items()):
        if not topic.startswith("/raw/can/") or not n:
            continue
        bus = topic[len("/raw/can/"):]
        reason = (doc.get("decoding", {}).get(f"can.{bus}") or {}).get("reason", "no decoder")
        notes.append(f"{n} CAN frames on {topic} were not decoded ({reason}): give --signalmap NAME --dbc FILE "
                     "(configs/signalmaps/)")
    return notes
