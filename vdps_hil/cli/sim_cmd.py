"""``vdps sim``: simulate a scenario with the sensors on their real wire formats and write a
recording (``vdps_hil.sim.drive``)."""

from __future__ import annotations

import math
from pathlib import Path

import click

from vdps_hil.cli.common import UserError, json_option, quiet_option, write_json

_EXAMPLE = """\b
Examples:
  vdps sim paper -o paper.mcap --json -
  vdps sim paper --seed 3 --profile table1 --effect imu_bias -o biased.mcap
  vdps sim paper --fault gnss_outage:t_s=4,duration_s=3 --fault dropped_frames:fraction=0.02
  vdps sim cr-sine-accel --truth commonroad-mb:1 -o cr1-sine.mcap

\b
Truth (--truth): ours (default, this project's physics core) or commonroad-mb:1 / :3
(CommonRoad's multibody model, parameter set 1 or 3; flat road only, no wheel lift-off:
see vdps_hil/sim/truth_cr.py); commonroad-mb:N:linear-lateral is the same vehicle with its
tires' lateral law linear (no saturation), to measure what saturation costs a model.

\b
Faults (NAME or NAME:key=value,...): gnss_outage, gyro_spike, frozen_can_signal,
dropped_frames, serial_disconnect, clock_jump (see vdps_hil/sim/faults.py).
Without -o the recording is written to ./<scenario>.mcap."""


@click.command("sim", epilog=_EXAMPLE)
@click.argument("scenario")
@click.option("--duration", "duration_s", type=float, default=None, metavar="S",
              help="Simulated seconds (default: the scenario's).")
@click.option("--seed", type=click.IntRange(0, None), default=0, show_default=True,
              help="Seed of every sensor's random streams.")
@click.option("--profile", default=None, metavar="NAME",
              help="Sensor profile (configs/profiles/NAME.toml or a .toml path) "
                   "[default: table1-susp1k].")
@click.option("--vehicle", default=None, metavar="FILE",
              help="Truth vehicle file or name (default: the scenario's).")
@click.option("--effect", "effects", multiple=True, metavar="NAME",
              help="Switch on an effect (NAME or NAME:param=value,...); repeatable.")
@click.option("--fault", "faults", multiple=True, metavar="NAME",
              help="Inject a fault (NAME or NAME:key=value,...); repeatable.")
@click.option("--truth", default=None, metavar="SPEC",
              help="Truth backend: ours (default) or commonroad-mb:1 / commonroad-mb:3.")
@click.option("--flat-road", is_flag=True, default=False,
              help="With a flat-road truth backend: drive a banked or graded scenario level (warned).")
@click.option("-o", "--output", default=None, metavar="FILE.mcap",
              help="Recording to write [default: ./<scenario>.mcap].")
@json_option
@quiet_option
def sim(scenario, duration_s, seed, profile, vehicle, effects, faults, truth, flat_road, output, json_out, quiet):
    """Simulate SCENARIO (a name in configs/scenarios/ or a .toml path) and write its recording:
    /raw/can/vdps, /raw/serial/imu, /raw/serial/gnss, /gnss/fix (foxglove.LocationFix of the GNSS
sentences) and /truth/state (100 Hz), /truth/events."""
    from vdps_hil.sim.drive import CONFIG_ERRORS, DEFAULT_PROFILE, Drive

    try:
        drive = Drive(scenario, profile=profile or DEFAULT_PROFILE, seed=seed, vehicle=vehicle,
                      effects=effects, faults=faults, duration_s=duration_s, truth=truth, flat_road=flat_road)
    except CONFIG_ERRORS as e:
        raise UserError(str(e).splitlines()[0] if str(e) else type(e).__name__) from None
    if output is None:
        output = f"{drive.scenario.name}.mcap"
    out = Path(output)
    if out.is_dir():
        raise UserError(f"-o {output}: is a directory")
    if not out.parent.exists():
        raise UserError(f"-o {output}: directory {out.parent} does not exist")
    from vdps_hil.batch.progress import ProgressBar

    try:
        with ProgressBar(None, f"vdps sim {drive.scenario.name}", unit="s", quiet=quiet) as bar:
            summary = drive.run(out, progress=bar.callback())
    except OSError as e:
        raise UserError(f"cannot write {output}: {e.strerror or e}") from None
    doc = summary.to_json()
    _print_summary(doc)
    write_json(doc, json_out)


def _print_summary(doc: dict) -> None:
    # the human summary goes to stderr when the JSON goes to stdout
    ctx = click.get_current_context()
    err = ctx.params.get("json_out") == "-"
    say = (lambda s: click.echo(s, err=True)) if err else click.echo
    say(f"vdps sim: {doc['scenario']}: {doc['duration_s']:.2f} s simulated in "
        f"{doc['wall_time_s']:.2f} s ({doc['real_time_factor']:.1f}x real time), "
        f"profile {doc['profile']}, seed {doc['seed']}"
        + (f", stopped at the {doc['stop_reason'].replace('_', ' ')}" if doc["stop_reason"] != "duration" else ""))
    truth = doc.get("truth", {})
    if truth.get("backend", "ours") != "ours":
        say(f"  truth: {truth['backend']} ({truth['package']} {truth['package_version']}, {truth['integrator']} "
            f"{truth['dt_s'] * 1e3:g} ms, up to {truth['max_substeps']} sub-steps)")
        for note in truth.get("notes", []):
            say(f"  warning: {note}")
        if truth.get("steer_rate_limited_steps"):
            lag = math.degrees(truth["steer_lag_max_rad"]) * truth["steer_ratio"]
            say(f"  note: the model's steering-rate limit held the road wheels back on "
                f"{truth['steer_rate_limited_steps']} steps (largest lag {lag:.2f} deg at the steering wheel)")
        if truth.get("accel_limited_steps"):
            say(f"  warning: the model's acceleration limits cut the wheel torques on "
                f"{truth['accel_limited_steps']} steps")
    if doc["effects"]:
        say(f"  effects: {', '.join(doc['effects'])}")
    if doc["faults"]:
        say(f"  faults: {'; '.join(doc['faults'])}")
    say(f"  wrote {doc['output']}: {doc['messages_total']} messages")
    width = max((len(t) for t in doc["messages"]), default=0)
    for topic, n in doc["messages"].items():
        say(f"    {topic:<{width}}  {n}")
    speed = doc["final_speed_mps"]
    say(f"  final speed {speed:.2f} m/s ({speed * 3.6:.1f} km/h), max roll "
        f"{doc['max_abs_roll_deg']:.2f} deg ({doc['max_abs_roll_rel_road_deg']:.2f} deg relative to the road)"
        if speed is not None and math.isfinite(speed) else "  no truth sample")
    if doc["rollover_events"]:
        for ev in doc["rollover_events"]:
            say(f"  rollover event: {ev['kind'].replace('_', ' ')} at {ev['t_s']:.2f} s ({ev['side']} side)")
    else:
        say("  no rollover event")
    if doc["time_backwards"]:
        say(f"  time stamps going back (clock jump): {doc['time_backwards']}")
