"""``vdps``: the root command group. Subcommands are imported only when invoked, so ``vdps
--help`` stays fast and a broken optional dependency only affects its own command."""

from __future__ import annotations

import importlib
import sys

import click

from vdps_hil import __version__
from vdps_hil.cli.common import UserError

# name -> (module, attribute, one-line help). Explicit registry, no import side effects.
COMMANDS: dict[str, tuple[str, str, str]] = {
    "sim": ("vdps_hil.cli.sim_cmd", "sim", "Simulate a scenario and write a recording."),
    "bench": ("vdps_hil.cli.bench_cmd", "bench",
              "Hardware-in-the-loop bench: simulated vehicle on live CAN/serial, pipeline, ECU."),
    "log": ("vdps_hil.cli.log_cmd", "log",
            "Record live CAN buses and serial devices into one MCAP."),
    "import": ("vdps_hil.cli.import_cmd", "import_",
               "Import CAN logs (asc, blf, log, trc, mf4) and NMEA/IMU logs into a recording."),
    "info": ("vdps_hil.cli.info_cmd", "info",
             "Topics, rates, gaps, per-source health and fields of a recording."),
    "recover": ("vdps_hil.cli.recover_cmd", "recover_",
                "Rescue every complete record of a recording cut off by a crash."),
    "replay": ("vdps_hil.cli.replay_cmd", "replay",
               "Run estimator, identifier, predictor and warning on a recording's /raw/ topics."),
    "batch": ("vdps_hil.cli.batch_cmd", "batch",
              "Replay/diagnose many drives or run Monte Carlo studies on a local or Dask cluster."),
    "diagnose": ("vdps_hil.cli.diagnose_cmd", "diagnose",
                 "Model workbench: where the model fails, which effect is missing, add it."),
    "export": ("vdps_hil.cli.export_cmd", "export", "Export topics of a recording as CSV files (flattened columns)."),
    "monitor": ("vdps_hil.cli.monitor_cmd", "monitor",
                "Watch decoded CAN signals by message, live (a bus or a recording), changes highlighted."),
    "plot": ("vdps_hil.cli.plot_cmd", "plot", "Plot signals of a recording against time (PNG or HTML)."),
    "paper": ("vdps_hil.cli.paper_cmd", "paper",
              "Run the paper's experiments through the real chain; print ours next to the paper's."),
}


class LazyGroup(click.Group):
    def list_commands(self, ctx):
        return sorted(COMMANDS)

    def get_command(self, ctx, name):
        if name not in COMMANDS:
            return None
        module, attr, _ = COMMANDS[name]
        return getattr(importlib.import_module(module), attr)

    def format_commands(self, ctx, formatter):
        rows = [(n, COMMANDS[n][2]) for n in self.list_commands(ctx)]
        with formatter.section("Commands"):
            formatter.write_dl(rows)


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.option("--debug", is_flag=True, help="Show full tracebacks instead of one-line errors.")
@click.version_option(__version__, prog_name="vdps")
@click.pass_context
def cli(ctx, debug):
    """vdps-hil: vehicle dynamics prediction (Hsu & Chen 2012) as a logger, estimator,
    simulator, model workbench and HIL bench.

    Example: vdps sim paper --duration 15 -o paper.mcap --json -
    """
    ctx.ensure_object(dict)
    ctx.obj["debug"] = debug


def main(argv=None) -> int:
    """Entry point with the project's error policy: a person's mistake prints one line and
    exits 2; an internal error prints one line (full traceback with --debug) and exits 1."""
    argv = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in argv
    try:
        cli.main(args=argv, prog_name="vdps", standalone_mode=False)
    except click.exceptions.Abort:
        click.echo("vdps: aborted", err=True)
        return 130
    except UserError as e:
        e.show()
        return 2
    except click.ClickException as e:  # usage errors: unknown option, bad value
        click.echo(f"vdps: error: {e.format_message()}", err=True)
        return 2
    except SystemExit as e:
        return int(e.code or 0)
    except Exception as e:  # noqa: BLE001 - the last line of defence
        if debug:
            raise
        click.echo(f"vdps: internal error: {e.__class__.__name__}: {e} (rerun with --debug)", err=True)
        return 1
    return 0


def entry() -> None:
    sys.exit(main())
