"""``vdps export``: chosen topics of a recording as CSV files (``app.export_topics``)."""

from __future__ import annotations

import click

from vdps_hil.cli.common import UserError, json_option, write_json

_EXAMPLE = """\b
Examples:
  vdps export paper-est.mcap --csv out/ --topic '/est/*'
  vdps export rav4.mcap --csv out/ --topic /raw/can/pt --topic /gnss/fix

\b
One CSV per topic (/est/state -> out/est.state.csv): t_ns, then the JSON keys as dotted paths
(values.phi_v_rad); a /raw/ topic is exported decoded (fields.<name>, SI)."""


@click.command("export", epilog=_EXAMPLE)
@click.argument("recording", metavar="FILE.mcap", type=click.Path(dir_okay=False))
@click.option("--csv", "csv_dir", required=True, metavar="DIR", help="Directory for the CSV files (created).")
@click.option("--topic", "topics", multiple=True, metavar="TOPIC",
              help="A topic or shell pattern; repeatable (default: every topic but /raw/).")
@json_option
def export(recording, csv_dir, topics, json_out):
    """Export topics of FILE.mcap, flattened to columns, as one CSV file per topic."""
    from vdps_hil.app.export_topics import ExportError, export_csv

    try:
        done = export_csv(recording, csv_dir, topics)
    except ExportError as e:
        raise UserError(str(e)) from None
    for topic, d in done.items():
        click.echo(f"vdps export: {topic}: {d['rows']} rows, {len(d['columns'])} columns -> {d['file']}",
                   err=json_out == "-")
    write_json({"input": recording, "topics": done}, json_out)
