"""``vdps batch``: the same question for many drives (replay, diagnose) or many seeds (studies),
as tasks on a local Dask cluster, an existing Dask cluster, a process pool or inline
(``vdps_hil.batch``)."""

from __future__ import annotations

import glob
import os
from pathlib import Path

import click

from vdps_hil.cli.common import UserError, write_json

_ENGINE_HELP = """\b
Engine: by default a local Dask cluster (one worker process per core; scheduler, workers and
dashboard on 127.0.0.1 only). --scheduler tcp://HOST:8786 submits to an existing Dask
cluster instead (its workers must see the files at the same paths and have vdps-hil
installed); --backend processes uses a plain process pool, --backend inline runs here.

\b
Results: OUT/drives/<drive>.json per task as it finishes, OUT/batch.json at the end. A rerun
reuses every result whose key (hash of the input file, the options, the vehicle/config files,
the effect list and the tool version) is unchanged, so an interrupted batch resumes; failed
tasks are tried again. Exit status: 0 all ok, 3 finished with failed tasks (reported, the
others' results written), 2 usage error."""

_REPLAY_EXAMPLE = """\b
Examples:
  vdps batch replay 'drives/*.mcap' --out results/replay --report results/report
  vdps batch replay 'drives/**/*.mcap' --workers 2 --json -
  vdps batch replay 'drives/*.mcap' --scheduler tcp://10.0.0.5:8786 --out results/replay

""" + _ENGINE_HELP


def engine_options(f):
    """Options shared by every batch subcommand."""
    opts = [
        click.option("--workers", type=int, default=None, metavar="N",
                     help="Worker processes [default: one per core]."),
        click.option("--scheduler", default=None, metavar="ADDRESS",
                     help="Existing Dask scheduler, e.g. tcp://host:8786."),
        click.option("--backend", type=click.Choice(["dask", "processes", "inline"]), default=None,
                     help="Engine [default: dask when installed, else processes]."),
        click.option("--allowed-failures", "allowed_failures", type=click.IntRange(0, None),
                     default=None, metavar="N",
                     help="Times a task may be on a worker that dies before it is reported as "
                          "failed [default: 2]."),
        click.option("--no-dashboard", "no_dashboard", is_flag=True,
                     help="Do not start the local cluster's dashboard."),
        click.option("--out", "out_dir", default=None, metavar="DIR",
                     help="Result directory [default: ./batch-<command>]."),
        click.option("--json", "json_out", metavar="FILE", default=None,
                     help="Write the aggregate document to FILE ('-' for stdout)."),
        click.option("--report", "report_dir", default=None, metavar="DIR",
                     help="Write the fleet report (DIR/index.html)."),
        click.option("--force", is_flag=True, help="Recompute every task (ignore stored results)."),
        click.option("--rehash", is_flag=True,
                     help="Hash every input file again (ignore OUT/.digests.json)."),
        click.option("--quiet", "-q", is_flag=True, help="No progress output."),
    ]
    for o in reversed(opts):
        f = o(f)
    return f


def expand_inputs(patterns: tuple[str, ...], suffix: str = ".mcap") -> list[str]:
    """Shell-style globs (``**`` recursive), directories (every ``*<suffix>`` below them) and
    plain paths -> sorted unique paths. A pattern that matches nothing is a usage error (a
    plain path that does not exist is kept: it is reported as a failed task)."""
    out: list[str] = []
    for pat in patterns:
        if os.path.isdir(pat):
            hits = sorted(glob.glob(os.path.join(glob.escape(pat), "**", f"*{suffix}"), recursive=True))
            if not hits:
                raise UserError(f"no *{suffix} file under {pat}")
        elif glob.has_magic(pat):
            hits = sorted(p for p in glob.glob(pat, recursive=True) if not os.path.isdir(p))
            if not hits:
                raise UserError(f"no file matches {pat!r}")
        else:
            hits = [pat]
        out += hits
    seen, unique = set(), []
    for p in out:
        a = os.path.abspath(p)
        if a not in seen:
            seen.add(a)
            unique.append(p)
    return unique


def _engine_config(workers, scheduler, backend, allowed_failures, no_dashboard):
    from vdps_hil.batch.engine import DEFAULT_ALLOWED_FAILURES, EngineConfig, EngineError

    if scheduler and backend not in (None, "dask"):
        raise UserError(f"--scheduler needs the dask backend, not --backend {backend}")
    if workers is not None and workers < 1:
        raise UserError(f"--workers must be at least 1, got {workers}")
    if scheduler and workers is not None:
        raise UserError("--workers sizes a local cluster; with --scheduler the cluster has its own")
    cfg = EngineConfig(backend=backend, workers=workers, scheduler=scheduler,
                       allowed_failures=DEFAULT_ALLOWED_FAILURES if allowed_failures is None
                       else allowed_failures, dashboard=not no_dashboard)
    try:
        cfg.resolved_backend()
    except EngineError as e:
        raise UserError(str(e)) from None
    return cfg


def _run(kind: str, tasks, cfg, out_dir: Path, *, force: bool, quiet: bool, options: dict,
         json_out: str | None, report_dir: str | None, digests=None) -> None:
    from vdps_hil.batch.engine import EngineError
    from vdps_hil.batch.runner import run_batch
    from vdps_hil.batch.progress import Progress

    if digests is not None:
        digests.save()
    progress = Progress(f"vdps batch {kind}", enabled=not quiet)
    try:
        res = run_batch(tasks, cfg, out_dir=out_dir, kind=kind, force=force, progress=progress,
                        options=options)
    except EngineError as e:
        raise UserError(str(e)) from None
    c = res.counts
    say = (lambda s: click.echo(s, err=True)) if json_out == "-" else click.echo
    if not quiet:
        run = res.aggregate["run"]
        say(f"vdps batch {kind}: {c['ok']} ok, {c['failed']} failed of {c['total']} "
            f"({run['computed']} computed, {run['reused']} reused) in {run['wall_s']:.1f} s; "
            f"results in {out_dir}")
        for f in res.aggregate["failed"]:
            err = f.get("error") or {}
            say(f"  failed {f['id']}: {err.get('type', '')}: {err.get('message', '')}")
    write_json(res.aggregate, json_out)
    if report_dir:
        from vdps_hil.batch.report import write_report
        path = write_report(res.aggregate, report_dir)
        if not quiet:
            say(f"  report: {path}")
    if c["failed"]:
        raise SystemExit(3)


def _out(out_dir: str | None, kind: str) -> Path:
    p = Path(out_dir or f"batch-{kind}")
    if p.exists() and not p.is_dir():
        raise UserError(f"--out {p}: not a directory")
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise UserError(f"--out {p}: {e.strerror or e}") from None
    return p


def _vehicle_file(vehicle: str) -> str:
    from vdps_hil.model.params import resolve_vehicle_path

    p = resolve_vehicle_path(vehicle)
    if not p.is_file():
        raise UserError(f"--vehicle {vehicle}: no such vehicle file ({p})")
    return vehicle


@click.group("batch", context_settings={"help_option_names": ["-h", "--help"]})
def batch():
    """Replay or diagnose many recordings, or run Monte Carlo studies, as batch tasks on a
    local or remote Dask cluster, with resume and a fleet report."""


PAPER_SWITCHES = ("a_psi_v_zero_rate", "b_y2_gps", "c_y2_sus_single_plane", "d_accel_as_acceleration", "all")


@batch.command("replay", epilog=_REPLAY_EXAMPLE)
@click.argument("patterns", nargs=-1, required=True, metavar="GLOB...")
@click.option("--vehicle", default="sedan-model", show_default=True, metavar="MODEL_FILE",
              help="Model vehicle file or name (a truth file is refused).")
@click.option("--model", "model_file", default=None, metavar="FILE",
              help="A saved workbench model (effects + identified parameters).")
@click.option("--params", default=None, metavar="FILE",
              help="Start every drive's identifier from these saved parameters.")
@click.option("--dbc", default=None, metavar="FILE", help="DBC of the car's bus (with --signalmap).")
@click.option("--signalmap", default=None, metavar="FILE",
              help="Signal map (configs/signalmaps/NAME or a .toml path) for a foreign DBC.")
@click.option("--bus", "bus_map", multiple=True, metavar="REC=MAP",
              help="Decode recording bus REC with the signal map's bus MAP; repeatable.")
@click.option("--sensorset", default=None, metavar="NAME",
              help="Sensor set (configs/sensorsets/NAME or a .toml path) for every drive [default: inferred "
                   "from each recording's fields].")
@click.option("--no-identify", is_flag=True, help="Do not run the parameter identifier.")
@click.option("--no-predict", is_flag=True, help="Do not run the predictor and the rollover warning.")
@click.option("--susp-sigma", "susp_sigma_m", type=float, default=0.001, show_default=True,
              metavar="M", help="Suspension sensor noise (1-sigma) [m].")
@click.option("--paper-faithful", "paper_faithful", multiple=True, type=click.Choice(PAPER_SWITCHES),
              help="EKF correction switched to the paper as printed (repeatable; 'all').")
@click.option("--effect", "effects", multiple=True, metavar="NAME",
              help="Effect the model carries (repeatable); part of the resume key.")
@click.option("--est-dir", default=None, metavar="DIR",
              help="Also write each drive's estimate recording (raw + /est/ topics) to "
                   "DIR/<drive>.mcap.")
@engine_options
def replay(patterns, vehicle, model_file, params, dbc, signalmap, bus_map, sensorset, no_identify, no_predict,
           susp_sigma_m, paper_faithful, effects, est_dir, workers, scheduler, backend,
           allowed_failures, no_dashboard, out_dir, json_out, report_dir, force, rehash, quiet):
    """Replay every recording matching GLOB... (one task per recording, as ``vdps replay``):
    estimates, identified parameters with sigmas, innovations, counters; one JSON per drive
    plus an aggregate."""
    from vdps_hil.batch.keys import DigestCache
    from vdps_hil.batch.tasks import replay_tasks

    cfg = _engine_config(workers, scheduler, backend, allowed_failures, no_dashboard)
    paths = expand_inputs(patterns)
    out = _out(out_dir, "replay")
    for name, f in (("--model", model_file), ("--params", params), ("--dbc", dbc)):
        if f is not None and not os.path.isfile(f):
            raise UserError(f"{name} {f}: no such file")
    buses = {}
    for spec in bus_map:
        rec, eq, mp = spec.partition("=")
        if not eq or not rec or not mp:
            raise UserError(f"--bus {spec!r}: expected REC=MAP")
        buses[rec] = mp
    if not (susp_sigma_m > 0):
        raise UserError(f"--susp-sigma must be positive, got {susp_sigma_m}")
    options = {k: v for k, v in {
        "model": model_file, "params": params, "dbc": dbc, "signalmap": signalmap,
        "bus_map": buses or None, "paper_faithful": sorted(paper_faithful) or None, "sensorset": sensorset}.items()
        if v is not None}
    if no_identify:
        options["identify"] = False
    if no_predict:
        options["predict"] = False
    if susp_sigma_m != 0.001:
        options["susp_sigma_m"] = susp_sigma_m
    if est_dir is not None:
        os.makedirs(est_dir, exist_ok=True)
        est_dir = os.path.abspath(est_dir)
    digests = DigestCache(out / ".digests.json", enabled=not rehash)
    tasks = replay_tasks(paths, vehicle=_vehicle_file(vehicle), options=options, effects=effects,
                         est_dir=est_dir, digests=digests)
    _run("replay", tasks, cfg, out, force=force, quiet=quiet, json_out=json_out,
         report_dir=report_dir, digests=digests,
         options={"vehicle": vehicle, **options, "effects": list(effects), "inputs": len(paths)})


@batch.command("diagnose", epilog=_ENGINE_HELP)
@click.argument("patterns", nargs=-1, required=True, metavar="GLOB...")
@click.option("--vehicle", default="sedan-model", show_default=True, metavar="MODEL_FILE",
              help="Model vehicle file or name (never a truth file).")
@click.option("--model", "model_file", default=None, metavar="FILE",
              help="A model written by vdps diagnose --save-model (parameters and effects).")
@click.option("--dbc", default=None, metavar="FILE", help="DBC of a foreign CAN bus (with --signalmap).")
@click.option("--signalmap", default=None, metavar="FILE", help="Signal map of the CAN frames to bus fields.")
@click.option("--add", "add", multiple=True, metavar="NAME",
              help="Add an effect on every drive, re-identify, before/after; repeatable.")
@click.option("--sensorset", default=None, metavar="NAME",
              help="Sensor set (configs/sensorsets/NAME or a .toml path) for every drive [default: inferred "
                   "from each recording's fields].")
@click.option("--no-simulation", is_flag=True, help="Skip the predictor runs (simulation error).")
@engine_options
def diagnose(patterns, vehicle, model_file, dbc, signalmap, add, sensorset, no_simulation, workers, scheduler,
             backend, allowed_failures, no_dashboard, out_dir, json_out, report_dir, force, rehash, quiet):
    """Diagnose every recording matching GLOB... with the model workbench (one task per
    recording, as vdps diagnose): which effects each drive recommends, identified parameters,
    residuals; the fleet report counts the recommendations across the drives."""
    from vdps_hil.batch.keys import DigestCache
    from vdps_hil.batch.tasks import diagnose_tasks

    cfg = _engine_config(workers, scheduler, backend, allowed_failures, no_dashboard)
    paths = expand_inputs(patterns)
    out = _out(out_dir, "diagnose")
    for name, f in (("--model", model_file), ("--dbc", dbc)):
        if f is not None and not os.path.isfile(f):
            raise UserError(f"{name} {f}: no such file")
    if (dbc is None) != (signalmap is None) and dbc is not None:
        raise UserError("--dbc needs --signalmap (which frames feed which fields)")
    options = {k: v for k, v in {"model": model_file, "dbc": dbc, "signalmap": signalmap,
                                 "add": list(add) or None, "sensorset": sensorset}.items() if v is not None}
    if no_simulation:
        options["with_simulation"] = False
    digests = DigestCache(out / ".digests.json", enabled=not rehash)
    tasks = diagnose_tasks(paths, vehicle=_vehicle_file(vehicle), options=options, effects=add,
                           digests=digests)
    _run("diagnose", tasks, cfg, out, force=force, quiet=quiet, json_out=json_out,
         report_dir=report_dir, digests=digests,
         options={"vehicle": vehicle, **options, "inputs": len(paths)})


@batch.command("report")
@click.argument("out_dir", metavar="OUT")
@click.option("--report", "report_dir", default=None, metavar="DIR",
              help="Where to write index.html [default: OUT/report].")
def report(out_dir, report_dir):
    """(Re)write the fleet report of a finished or interrupted batch from OUT's result files."""
    from vdps_hil.batch.report import aggregate_from_dir, write_report

    try:
        agg = aggregate_from_dir(out_dir)
    except (OSError, ValueError) as e:
        raise UserError(f"{out_dir}: {e}") from None
    path = write_report(agg, report_dir or os.path.join(out_dir, "report"))
    click.echo(f"vdps batch report: {path} ({agg['counts']['total']} tasks)")


_STUDY_EXAMPLE = """\b
Examples:
  vdps batch study snr --seeds 10 --out results/snr
  vdps batch study weighting --seeds 5 --noise-scale 0 --noise-scale 1 --duration 40
  vdps batch study effects --seeds 20 --null straight --json -

\b
snr: the paper's Table 2 (|rel err| of Ix Iy Iz at 10.25 s vs the measured SNR; stage 1
finds the noise scale of each target SNR). weighting: Table 3 (time for the inertias to come
within 10 % for Q4 = diag(q,q,q)). effects: hit rate of the workbench's diagnosis per hidden
effect. Mean +- sd over the seeds, the paper's figures beside. Trials in OUT/trials/, the
study in OUT/study.json; a rerun reuses finished trials.

""" + _ENGINE_HELP


@batch.command("study", epilog=_STUDY_EXAMPLE)
@click.argument("study", type=click.Choice(["snr", "weighting", "effects"]))
@click.option("--seeds", type=click.IntRange(1, None), default=5, show_default=True,
              help="Trials (seeds) per row.")
@click.option("--seed0", type=click.IntRange(0, None), default=1, show_default=True, help="First seed.")
@click.option("--profile", default="table1-susp1k", show_default=True, metavar="NAME",
              help="Sensor profile (the data sheet the chain is configured from).")
@click.option("--target-snr", "targets", type=float, multiple=True, metavar="DB",
              help="snr: target SNRs [dB] (repeatable) [default: 30 20 10].")
@click.option("--noise-scale", "noise_scales", type=float, multiple=True, metavar="K",
              help="weighting: sensor noise scale (repeatable) [default: 0 1].")
@click.option("--duration", "duration_s", type=float, default=40.0, show_default=True, metavar="S",
              help="weighting: drive length [s].")
@click.option("--q", "qs", type=float, multiple=True, metavar="Q",
              help="weighting: Q4 = diag(q,q,q) values (repeatable) [default: the paper's four].")
@click.option("--effect", "effects", multiple=True, metavar="NAME",
              help="effects: hidden effect to test (repeatable) [default: all].")
@click.option("--null", "null_maneuvers", multiple=True, metavar="MANEUVER",
              help="effects: also drive MANEUVER with nothing hidden (false alarms); repeatable.")
@click.option("--vehicle", default="sedan-model", show_default=True, metavar="MODEL_FILE",
              help="effects: model vehicle the workbench diagnoses with.")
@engine_options
def study(study, seeds, seed0, profile, targets, noise_scales, duration_s, qs, effects, null_maneuvers,
          vehicle, workers, scheduler, backend, allowed_failures, no_dashboard, out_dir, json_out,
          report_dir, force, rehash, quiet):
    """Run a Monte Carlo STUDY over seeds as batch tasks: snr (Table 2), weighting (Table 3) or
    effects (hidden-effect hit rates)."""
    from vdps_hil.batch.engine import EngineError
    from vdps_hil.batch.progress import Progress
    from vdps_hil.batch.studies import SNR_TARGETS_DB, StudyOptions, format_study, run_study

    cfg = _engine_config(workers, scheduler, backend, allowed_failures, no_dashboard)
    try:
        opt = StudyOptions(seeds=seeds, seed0=seed0, profile=profile,
                           snr_targets_db=tuple(targets) or SNR_TARGETS_DB,
                           noise_scales=tuple(noise_scales) or (0.0, 1.0), duration_s=duration_s,
                           qs=tuple(qs) or StudyOptions.qs, effects=tuple(effects) or None,
                           null_maneuvers=tuple(null_maneuvers), vehicle=_vehicle_file(vehicle))
    except ValueError as e:
        raise UserError(str(e)) from None
    from vdps_hil.sim.profiles import ProfileError, load_profile
    try:
        load_profile(profile)
    except ProfileError as e:
        raise UserError(str(e).splitlines()[0]) from None
    out = _out(out_dir, f"study-{study}")
    try:
        doc = run_study(study, opt, cfg, out_dir=out, force=force,
                        progress=None if quiet else (lambda label: Progress(f"vdps batch {label}")))
    except EngineError as e:
        raise UserError(str(e)) from None
    except (ValueError, ImportError) as e:
        raise UserError(str(e).splitlines()[0] if str(e) else type(e).__name__) from None
    text = format_study(doc)
    say = (lambda s: click.echo(s, err=True)) if json_out == "-" else click.echo
    if not quiet:
        say(text)
        say(f"  study in {out / 'study.json'}")
    write_json(doc, json_out)
    if report_dir:
        import html as _html
        os.makedirs(report_dir, exist_ok=True)
        path = os.path.join(report_dir, "index.html")
        Path(path).write_text(f"<!doctype html><html><head><meta charset=\"utf-8\"><title>vdps batch study "
                              f"{study}</title></head><body><h1>vdps batch study {study}</h1><pre>"
                              f"{_html.escape(text)}</pre></body></html>\n", encoding="utf-8")
    if any(st["counts"]["failed"] for st in doc["stages"]):
        raise SystemExit(3)
