"""``vdps paper``: the paper's experiments on the simulator through the real chain, printed next
to the paper's published values (``vdps_hil.experiments.paper_run``)."""

from __future__ import annotations

import click

from vdps_hil.cli.common import UserError, json_option, quiet_option, write_json

_EXAMPLE = """\b
Examples:
  vdps paper --quick                          # 3 seeds, both profiles, a few minutes
  vdps paper --profile table1-susp1k --json paper.json
  vdps paper --seeds 20 --workers 2           # the full run (tools/paper_full.py does this)

\b
The chain (EKF, alpha-beta, identifier, predictor, warning) sees only the /raw/ topics of each
simulated drive and the model vehicle file; /truth/ is read by the harness only to score.
JSON: identification.<param>.{median_rel_err_pct,p90_rel_err_pct,within_2_sigma},
prediction.left_turn.{position_err_m,yaw_err_deg,inaccuracy_pct},
prediction.rollover.{predicted,inaccuracy_pct}, warning.{lead_time_s,lead_to_tipup_s,false_alarms},
snr_table, weighting_table (one profile: at the top level; both: under profiles.<name>)."""


@click.command("paper", epilog=_EXAMPLE)
@click.option("--quick", is_flag=True, help="3 seeds, shortened long runs (stated in the output).")
@click.option("--profile", "profiles", multiple=True, metavar="NAME",
              help="Sensor profile (repeatable; default: table1-susp1k and table1).")
@click.option("--seeds", type=int, default=None, metavar="N", help="Seeds per profile (default 20, --quick 3).")
@click.option("--seed0", type=click.IntRange(0, None), default=1, show_default=True, help="First seed.")
@click.option("--workers", type=int, default=2, show_default=True, help="Processes running drives in parallel.")
@json_option
@quiet_option
def paper(quick, profiles, seeds, seed0, workers, json_out, quiet):
    """Run the paper's experiments (Hsu & Chen 2012, sections 7-8) and print ours next to the
    paper's figures: fusion errors, identification at 10.25 s, left-turn and rollover
    predictions, warning lead time and false alarms, Tables 2 and 3."""
    from vdps_hil.experiments.paper_report import format_report
    from vdps_hil.experiments.paper_run import PROFILES, PaperOptions, run_paper
    from vdps_hil.sim.profiles import ProfileError, load_profile

    profs = tuple(profiles) or PROFILES
    for p in profs:
        try:
            load_profile(p)
        except ProfileError as e:
            raise UserError(str(e)) from None
    if seeds is not None and seeds < 1:
        raise UserError("--seeds must be at least 1")
    if workers < 1:
        raise UserError("--workers must be at least 1")
    kw = {"profiles": profs, "seed0": seed0, "workers": workers}
    if seeds is not None:
        kw["seeds"] = seeds
    opt = PaperOptions.quick(**kw) if quick else PaperOptions(**kw)

    from vdps_hil.batch.progress import ProgressBar

    with ProgressBar(None, "vdps paper", unit="run", quiet=quiet) as bar:
        doc = run_paper(opt, progress=bar.callback())
    click.echo(format_report(doc), err=json_out == "-")  # stdout stays pure JSON with --json -
    write_json(doc, json_out)
