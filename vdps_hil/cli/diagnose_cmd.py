"""``vdps diagnose``: compare the model with a drive, see where it fails, learn which physical
effect is missing, add it and watch the error fall (``vdps_hil.workbench``)."""

from __future__ import annotations

from pathlib import Path

import click

from vdps_hil.cli.common import UserError, debug_enabled, recorded_decoding, require_file, write_json

_EXAMPLE = """\b
Examples:
  vdps diagnose drive.mcap
  vdps diagnose drive.mcap --report out/ --json diag.json
  vdps diagnose drive.mcap --add aero_drag --save-model sedan-drag.toml
  vdps diagnose drive.mcap --effect-file my_effect.py
  vdps diagnose rav4.mcap --vehicle configs/vehicles/rav4-model.toml \\
      --dbc toyota.dbc --signalmap configs/signalmaps/toyota_rav4_2017.toml --sensorset rav4-can-ublox

\b
Only the recording's /raw/ topics and the model vehicle file are read. --effect-file and
--effect-entry load Python code: only from the file or entry point you name."""


@click.command("diagnose", epilog=_EXAMPLE)
@click.argument("recording", metavar="FILE.mcap")
@click.option("--vehicle", default="sedan-model", show_default=True, metavar="MODEL_FILE",
              help="Model vehicle file or name (configs/vehicles/NAME.toml); never a truth file.")
@click.option("--model", "model_file", default=None, metavar="FILE",
              help="A model written by --save-model (identified parameters and effects, .toml or .json).")
@click.option("--dbc", default=None, metavar="FILE", help="DBC of a foreign CAN bus (with --signalmap).")
@click.option("--signalmap", default=None, metavar="FILE", help="Signal map of the CAN frames to bus fields.")
@click.option("--sensorset", default=None, metavar="NAME",
              help="Sensor set (configs/sensorsets/NAME or a .toml path) [default: inferred from the recording's "
                   "fields, as vdps replay].")
@click.option("--report", "report_dir", default=None, metavar="DIR", help="Write DIR/report.html (self-contained).")
@click.option("--json", "json_out", default=None, metavar="FILE", help="Write the JSON result to FILE ('-' stdout).")
@click.option("--add", "add", multiple=True, metavar="NAME",
              help="Add an effect, re-identify and show before/after; repeatable.")
@click.option("--save-model", default=None, metavar="FILE", help="Write the identified model (.toml or .json).")
@click.option("--effect-file", "effect_files", multiple=True, metavar="FILE",
              help="Load your own effect classes from this Python file (runs its code); repeatable.")
@click.option("--effect-entry", "effect_entries", multiple=True, metavar="NAME",
              help="Load the named entry point of group vdps_hil.effects; repeatable.")
@click.option("--no-simulation", is_flag=True, help="Skip the predictor runs (simulation error).")
@click.option("--quiet", is_flag=True, help="No progress bar on the terminal.")
def diagnose(recording, vehicle, model_file, dbc, signalmap, sensorset, report_dir, json_out, add, save_model,
             effect_files, effect_entries, no_simulation, quiet):
    """Diagnose the model on RECORDING: residual of every equation of eq 13, where it fails,
    which effect is missing (ranked by held-out explained fraction, with equivalence groups),
    and with --add the before/after of adding it."""
    from vdps_hil.model.params import VehicleFileError, load_vehicle
    from vdps_hil.workbench.dataset import DatasetError
    from vdps_hil.workbench.model_file import ModelFileError
    from vdps_hil.workbench.user_effects import UserEffectError, load_effect_file, load_entry_point_effects

    require_file(recording)
    if (dbc is None) != (signalmap is None) and dbc is not None:
        raise UserError("--dbc needs --signalmap (which frames feed which fields)")
    if save_model and Path(save_model).suffix.lower() not in (".toml", ".json"):
        raise UserError(f"--save-model {save_model}: the file must end in .toml or .json")
    try:
        veh = load_vehicle(vehicle)
    except VehicleFileError as e:
        raise UserError(str(e)) from None
    if veh.kind != "model":
        raise UserError(f"--vehicle {vehicle}: is a {veh.kind} file; the workbench reads only model files")
    user = []
    try:
        for f in effect_files:
            user += load_effect_file(f)
        if effect_entries:
            user += load_entry_point_effects(effect_entries)
    except UserEffectError as e:
        raise UserError(str(e)) from None
    dbc, signalmap = recorded_decoding(recording, dbc, signalmap)  # what the recording names, unless given
    from vdps_hil.batch.progress import ProgressBar
    from vdps_hil.workbench.dataset import DatasetConfig
    from vdps_hil.workbench.diagnosis import diagnose as run

    stages = 3 + (0 if no_simulation else 1) + (5 if add else 0)  # the stages the workbench names
    try:
        with ProgressBar(stages, "vdps diagnose", unit="stage", quiet=quiet) as bar:
            dg = run(recording, veh, model=model_file, dbc=dbc, signalmap=signalmap, add=add, user_effects=user,
                     save_model=save_model, with_simulation=not no_simulation, progress=bar.stage_callback(),
                     dataset_config=DatasetConfig(sensorset=sensorset))
    except (DatasetError, ModelFileError, ValueError) as e:
        if debug_enabled():
            raise
        msg = str(e).splitlines()[0] if str(e) else type(e).__name__
        if isinstance(e, DatasetError):  # "no IMU" from a damaged file is the file, not the car
            from vdps_hil.record.reader import damage_note, scan_damage

            msg += damage_note(scan_damage(recording), recording)
        raise UserError(msg) from None
    out = (lambda s: click.echo(s, err=True)) if json_out == "-" else click.echo
    for line in dg.summary_lines():
        out(line)
    if report_dir:
        from vdps_hil.workbench.report import write_report

        try:
            p = write_report(dg, report_dir)
        except OSError as e:
            raise UserError(f"cannot write the report into {report_dir}: {e.strerror or e}") from None
        out(f"report written to {p}")
    write_json(dg.to_json(), json_out)
