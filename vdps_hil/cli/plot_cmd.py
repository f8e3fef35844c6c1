"""``vdps plot``: signals of a recording against time, as PNG or HTML (``app.plot_signals``)."""

from __future__ import annotations

import click

from vdps_hil.cli.common import UserError, json_option, write_json

_EXAMPLE = """\b
Examples:
  vdps plot paper-est.mcap /est/state.phi_v_rad /est/prediction.values.peak_ltr -o roll.png
  vdps plot paper.mcap wheel_speed_radps_1 steer_wheel_angle_rad -o inputs.html
  vdps plot rav4.mcap /decoded/can.pt/wheel_speed.wheel_speed_radps_1 -o ws.png

\b
SIGNAL: TOPIC.KEY (KEY in the message's values, fields, or a dotted path such as
/est/tf.translation.x) or a decoded field name (the /raw/ topics decoded with the signal map
and DBC the recording names)."""


@click.command("plot", epilog=_EXAMPLE)
@click.argument("recording", metavar="FILE.mcap", type=click.Path(dir_okay=False))
@click.argument("signals", nargs=-1, required=True, metavar="SIGNAL...")
@click.option("-o", "--output", required=True, metavar="OUT.png|OUT.html", help="Figure to write.")
@json_option
def plot(recording, signals, output, json_out):
    """Plot SIGNAL... of FILE.mcap against time into a PNG or a self-contained HTML page."""
    from vdps_hil.app.plot_signals import PlotError, plot_signals

    try:
        counts = plot_signals(recording, list(signals), output)
    except PlotError as e:
        raise UserError(str(e)) from None
    click.echo(f"vdps plot: {', '.join(f'{s} ({n} points)' for s, n in counts.items())} -> {output}",
               err=json_out == "-")
    write_json({"input": recording, "output": output, "points": counts}, json_out)
