"""Root of the ``sherpa`` command: global options and the command list (the error boundary, `run`
and `main`, is cli/boundary.py; they are re-exported here for the console script and the tests).

Command modules are imported here, but they import the CAN stack (python-can, canopen)
only inside the functions that need it, so ``sherpa --help`` stays fast.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import typer

from sherpa_cli.cli import context
from sherpa_cli.cli.boundary import RootGroup, install, main, run
from sherpa_cli.cli.context import AppState
from sherpa_cli.version import __version__

DEFAULT_CONFIG = Path("configs/sherpa-arm.yaml")
CONFIG_NAME = "sherpa-arm.yaml"

app = typer.Typer(
    name="sherpa",
    cls=RootGroup,  # Ctrl-C reported as one line whatever typer is installed (cli/boundary.py)
    help="Commission and diagnose the SHERPA arm's Elmo SimplIQ Whistle drives over CAN.\n\n"
    "Exit codes: 0 ok, 1 problem found, 2 usage/config error, 3 bus error, "
    "4 drive refused, 5 drive busy (another command moves it), 6 privilege missing (bus up/down), "
    "130 interrupted (docs/exit-codes.md).",
    no_args_is_help=True,
    add_completion=True,  # --install-completion / --show-completion (typer's)
    rich_markup_mode=None,  # plain click help: rich's help formatter doubles start-up time
    pretty_exceptions_enable=False,
    context_settings={"help_option_names": ["-h", "--help"]},
)


def _version_callback(value: bool) -> None:
    if value:
        typer.echo(f"sherpa-cli {__version__}")
        raise typer.Exit()


def config_candidates() -> list[tuple[Path, str]]:
    """Where the default config is looked for, in order: $SHERPA_CONFIG (when set, the only place),
    the user config directory (platformdirs), then ./configs/sherpa-arm.yaml."""
    env = os.environ.get("SHERPA_CONFIG")
    if env:
        return [(Path(env), "$SHERPA_CONFIG")]
    return [(_user_config_dir() / CONFIG_NAME, "the user config directory"),
            (DEFAULT_CONFIG, "the working directory")]


def _user_config_dir() -> Path:
    """platformdirs' user config directory; on Linux its XDG rule without importing it, since every
    command (`scan --help` too) looks here first (~7 ms of start-up)."""
    if sys.platform.startswith("linux"):
        base = os.environ.get("XDG_CONFIG_HOME", "")
        return Path(base if base.strip() else os.path.expanduser("~/.config")) / "sherpa-cli"
    from platformdirs import user_config_dir

    return Path(user_config_dir("sherpa-cli"))


def default_config_path() -> tuple[Path, tuple[str, ...]]:
    """The first candidate that exists (else the last), and every place looked at, for the error."""
    candidates = config_candidates()
    looked = tuple(f"{path} ({why})" for path, why in candidates)
    for path, _ in candidates:
        if path.is_file():
            return path, looked
    return candidates[-1][0], looked


@app.callback()
def root(
    ctx: typer.Context,
    config: Path | None = typer.Option(
        None, "--config", "-c", metavar="FILE",
        help="Arm configuration (native YAML or the seed's rosparam format). Default: $SHERPA_CONFIG, "
        "else sherpa-arm.yaml in the user config directory, else ./configs/sherpa-arm.yaml.",
    ),
    json_out: bool = typer.Option(False, "--json", help="Print results as JSON on stdout."),
    debug: bool = typer.Option(False, "--debug", help="Show tracebacks for errors."),
    verbose: bool = typer.Option(False, "--verbose", "-v", help="Show the details: each drive's identity in "
                                 "`identify`, the objects a motion's guard put back at its end."),
    no_color: bool = typer.Option(False, "--no-color", help="No colour (NO_COLOR is honoured too)."),
    sim: bool = typer.Option(False, "--sim", help="Run against the simulated arm, in this process "
                             "(python-can virtual buses; the drives' flash persists in the state dir)."),
    bus_map: list[str] | None = typer.Option(
        None, "--bus-map", metavar="BUS=INTERFACE:CHANNEL",
        help="Point configured buses elsewhere, e.g. can0=socketcan:vcan0 or can0=remote:127.0.0.1:54701 "
        "(repeat or comma-separate; default $SHERPA_BUS_MAP). `sherpa sim --serve` prints the one to use."),
    recover: bool = typer.Option(False, "--recover", help="A motion command puts back what a killed command "
                                 "left on its drives (the journal, `sherpa recover`) instead of refusing."),
    version: bool = typer.Option(False, "--version", callback=_version_callback, is_eager=True,
                                 help="Print the version and exit."),
    allow_user_program: bool = typer.Option(
        False, "--allow-user-program", help="Let moving commands move a drive whose user program runs (PS=1); "
        "without it they refuse (SV is refused either way)."),
) -> None:
    # the journal (and the state-file modules under it) only when it is asked for or already loaded
    # (an earlier in-process run): `sherpa scan --help` passes here too (start-up time)
    if recover or "sherpa_cli.bus.journal" in sys.modules:
        from sherpa_cli.bus import journal

        journal.set_auto_recover(recover)
    config_path, looked = (config, ()) if config is not None else default_config_path()
    ctx.obj = context.CURRENT = AppState.create(
        config_path=config_path,
        config_given=config is not None,
        config_looked=looked,
        json_mode=json_out,
        debug=debug,
        no_color=no_color,
        sim=sim,
        bus_map=bus_map if bus_map else ([os.environ["SHERPA_BUS_MAP"]] if os.environ.get("SHERPA_BUS_MAP") else []),
        bus_map_from_env=not bus_map and bool(os.environ.get("SHERPA_BUS_MAP")),
        verbose=verbose,
    )
    ctx.obj.allow_user_program = allow_user_program


def _register() -> None:
    # In the order a technician meets them at the arm: find, look, back up, program, commission.
    from sherpa_cli.cli import (
        bus_cmd,
        cmd_cmd,
        config_cmd,
        diffdrive_cmd,
        doctor_cmd,
        ft_cmd,
        home_cmd,
        identify_cmd,
        jog_cmd,
        limits_cmd,
        monitor_cmd,
        move_cmd,
        params_cmd,
        pose_cmd,
        program_cmd,
        recipe_cmd,
        recover_cmd,
        scan_cmd,
        sim_cmd,
        stop_cmd,
    )

    app.command("scan")(scan_cmd.scan)
    app.command("identify")(identify_cmd.identify)
    app.command("monitor")(monitor_cmd.monitor)
    app.command("cmd")(cmd_cmd.cmd)
    app.command("jog")(jog_cmd.jog)
    app.command("move")(move_cmd.move)
    app.command("stop")(stop_cmd.stop)
    app.command("recover")(recover_cmd.recover)
    app.command("home")(home_cmd.home)
    app.command("dump-params")(params_cmd.dump_params)
    app.command("program-limits")(program_cmd.program_limits)
    app.command("commission")(recipe_cmd.commission)
    app.command("sim")(sim_cmd.sim)
    app.command("doctor")(doctor_cmd.doctor)
    app.add_typer(params_cmd.app, name="params")
    app.add_typer(limits_cmd.app, name="limits")
    app.add_typer(diffdrive_cmd.app, name="diffdrive")
    app.add_typer(recipe_cmd.app, name="recipe")
    app.add_typer(config_cmd.app, name="config")
    app.add_typer(bus_cmd.app, name="bus")
    app.add_typer(ft_cmd.app, name="ft")
    app.add_typer(pose_cmd.app, name="pose")

    from sherpa_cli.cli import log_cmd, tune_cmd

    app.add_typer(log_cmd.app, name="log")
    app.add_typer(tune_cmd.app, name="tune")


_register()


install(app)

__all__ = ["app", "main", "run"]
