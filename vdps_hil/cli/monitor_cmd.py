"""``vdps monitor``: decoded CAN signals by message, live in the terminal (``app.can_monitor``)."""

from __future__ import annotations

import click

from vdps_hil.cli.common import UserError

_EXAMPLE = """\b
Examples:
  vdps monitor virtual:hil                         # the bench's bus, dbc/vdps.dbc
  vdps monitor socketcan:can0 --dbc car.dbc --id 0x1AA,0x1AB
  vdps monitor rav4.mcap --signal 'WHEEL_SPEED*'    # a recording, at its own pace
  vdps monitor paper.mcap --once --id VDPS_SteerAngle   # the table at the end, printed once
  candump -L can0 | vdps monitor - --dbc car.dbc    # candump -L lines on standard input"""


@click.command("monitor", epilog=_EXAMPLE)
@click.argument("source", metavar="SOURCE")
@click.option("--dbc", metavar="FILE", default=None,
              help="DBC to decode with (live default dbc/vdps.dbc; a recording: the one its metadata names).")
@click.option("--signalmap", metavar="FILE", default=None, help="A recording's signal map, if not the recorded one.")
@click.option("--id", "ids", multiple=True, metavar="ID[,ID...]",
              help="Only these frames: IDs (0x100, 256) or message names; repeatable.")
@click.option("--signal", "signals", multiple=True, metavar="PATTERN",
              help="Only signals matching this shell pattern (case-insensitive); repeatable.")
@click.option("--once", is_flag=True, help="No live screen: print the table once at the end.")
@click.option("--duration", "duration_s", type=click.FloatRange(min=0, min_open=True), default=None, metavar="S",
              help="Stop after S seconds of the source's time.")
@click.option("--speed", type=float, default=1.0, show_default=True,
              help="A recording's pace (1: as recorded, 0: at once).")
def monitor(source, dbc, signalmap, ids, signals, once, duration_s, speed):
    """Watch the decoded CAN signals of SOURCE (a python-can interface string such as virtual:hil
    or socketcan:can0, a recording FILE.mcap, or - for candump -L lines on standard input) by
    message; changed values highlighted."""
    from vdps_hil.app.can_monitor import MonitorError, run_monitor

    try:
        run_monitor(source, dbc=dbc, signalmap=signalmap, ids=ids, signals=signals, once=once,
                    duration_s=duration_s, speed=speed)
    except MonitorError as e:
        raise UserError(str(e)) from None
