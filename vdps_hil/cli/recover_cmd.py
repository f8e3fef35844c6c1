"""``vdps recover``: write a closed copy of a recording cut off by a crash or a full disk, or
damaged in the middle."""

from __future__ import annotations

import click

from vdps_hil.cli.common import UserError, json_option, write_json

__all__ = ["recover_"]


@click.command("recover")
@click.argument("broken", metavar="BROKEN.mcap")
@click.option("-o", "--output", required=True, metavar="FIXED.mcap",
              help="New file to write (never the broken one).")
@json_option
def recover_(broken, output, json_out):
    """Rescue every complete record of a recording cut off by a crash, a kill -9 or a full
    disk, or damaged in the middle (the scan resynchronises after a bad record), into a new,
    properly closed file.

    Example: vdps recover track.mcap -o track-fixed.mcap
    """
    from vdps_hil.record.recover import RecoverError, recover

    try:
        rep = recover(broken, output)
    except RecoverError as e:
        raise UserError(str(e)) from None
    state = "was closed properly" if rep["properly_closed"] else f"stopped: {rep['stop']}"
    click.echo(f"{broken}: {rep['messages']} messages rescued into {output} ({state}; "
               f"{rep['complete_bytes']} of {rep['input_bytes']} bytes complete, "
               f"{rep['chunks_ok']} chunks, {rep['chunks_damaged']} damaged)")
    for t, n in rep["topics"].items():
        last = rep["last_t_ns"].get(t)
        click.echo(f"  {t}: {n}" + ("" if last is None else f" (last t_ns {last})"))
    for d in rep["damaged"]:
        click.echo(f"  damaged: {d}")
    for r in rep["resynchronised"]:
        click.echo(f"  bad record (opcode {r['opcode']}) at byte {r['bad_record_at']}: "
                   f"{r['skipped_bytes']} bytes skipped, resumed at byte {r['resumed_at']}")
    write_json(rep, json_out)
