"""Every CLI command that acts on the arm is a layer over an `Arm` method: the table below names, per
command of the typer app, the method it calls, or why it does not act on the arm. The table is checked
both ways against the app, and each wired command is run on the simulator with every `Arm` method
spied, so a command that reaches past the API (straight into ops/) fails here."""

from __future__ import annotations

import inspect
import shutil
from collections.abc import Callable
from pathlib import Path

import pytest

from sherpa_cli.api import Arm

ROOT = Path(__file__).resolve().parent.parent
MATCH = "tests/data/match-pair.yaml"
DIFF = "tests/data/diffdrive-arm.yaml"
FT = "tests/data/ft-arm.yaml"

# command -> (the Arm method it calls, a command line that reaches it on the simulator; {tmp} is a
# fresh directory)
WIRED: dict[str, tuple[str, tuple[str, ...]]] = {
    "scan": ("scan", ("--sim", "scan", "--bus", "can1")),
    "identify": ("identify", ("--sim", "identify", "elbow_pitch")),
    "monitor": ("monitor", ("--sim", "monitor", "--once", "elbow_pitch")),
    "cmd": ("command", ("--sim", "cmd", "elbow_1a", "PX")),
    "jog": ("move", ("--sim", "jog", "elbow_pitch", "--by", "0.02", "--apply")),
    "stop": ("stop", ("--sim", "stop", "elbow_pitch")),
    "recover": ("recover", ("--sim", "recover", "elbow_pitch", "--check-drives")),
    "home": ("home", ("--sim", "home", "elbow_pitch")),
    "dump-params": ("dump_params", ("--sim", "dump-params", "elbow_pitch", "-o", "{tmp}/dump.yaml")),
    "program-limits": ("program_limits", ("--sim", "program-limits", "elbow_pitch")),
    "doctor": ("doctor", ("--sim", "doctor", "--window", "0")),
    "params diff": ("dump_params", ("--sim", "params", "diff", "config", "live", "-t", "elbow_pitch")),
    "params restore": ("restore", ("--sim", "params", "restore", "{tmp}/dump.yaml")),
    "diffdrive match": ("match_pair", ("--config", MATCH, "--sim", "diffdrive", "match", "diff", "--measure")),
    "diffdrive move": ("diffdrive_move", ("--config", DIFF, "--sim", "diffdrive", "move", "diff", "--sigma", "0.2",
                                          "--apply")),
    "ft show": ("wrenches", ("--config", FT, "--sim", "ft", "show", "--for", "0.1")),
    "ft bias": ("ft_bias", ("--config", FT, "--sim", "ft", "bias")),
    "log record": ("record", ("--sim", "log", "record", "elbow_pitch", "--rate", "50", "--for", "0.1",
                              "-o", "{tmp}/r.csv")),
    "log step": ("log_step", ("--sim", "log", "step", "elbow_pitch", "--velocity", "0.1", "--for", "0.3",
                              "--rate", "200", "-o", "{tmp}/step", "--apply")),
    "tune show": ("tune_show", ("--sim", "tune", "show", "elbow_pitch")),
    "tune set": ("tune_set", ("--sim", "tune", "set", "elbow_pitch", "KP[2]=0.6")),
    "move": ("run_pose", ("--sim", "move", "transport", "--joints", "elbow_pitch,wrist_1", "--apply")),
    "pose diff": ("pose_diff", ("--sim", "pose", "diff", "transport")),
    "pose save": ("save_pose", ("--config", "{tmp}/arm.yaml", "--sim", "pose", "save", "dock", "--joints",
                                "elbow_pitch")),
    "tune step": ("tune_step", ("--sim", "tune", "step", "elbow_pitch", "--velocity", "0.1", "KP[2]=0.6",
                                "--for", "0.3", "--rate", "200", "--apply")),
}

# an option that takes a command down another path: that path's Arm method
VARIANTS: dict[str, tuple[str, tuple[str, ...]]] = {
    "log record --source drive": ("record_drives", ("--sim", "log", "record", "elbow_pitch", "--source", "drive",
                                                    "--for", "0.05", "-o", "{tmp}/d.csv")),
    "log step --source drive": ("log_step_with_drive", ("--sim", "log", "step", "elbow_pitch", "--velocity", "0.1",
                                                        "--for", "0.3", "--rate", "200", "--source", "drive",
                                                        "-o", "{tmp}/ds", "--apply")),
}

# commands that do not act on the arm's drives, and why
NOT_THE_ARM: dict[str, str] = {
    "bus up": "brings a CAN interface up (netlink); no drive is addressed",
    "bus down": "takes a CAN interface down (netlink)",
    "bus status": "the interfaces' state and error counters",
    "bus watch": "watches the interfaces' state and load; sends nothing",
    "log capture": "listens to raw frames on the buses; sends nothing",
    "log decode": "reads a capture file",
    "log plot": "reads a recording file",
    "log section9": "summarises recording files",
    "config check": "reads a config file",
    "config convert": "converts a config file",
    "limits show": "derives the limits from the config",
    "diffdrive convert": "pure Σ/Δ arithmetic",
    "diffdrive limits": "derives the pair's limits from the config",
    "recipe check": "reads a recipe file",
    "recipe run": "runs other commands (each in this table) through the boundary",
    "commission": "runs the commissioning recipe's commands (each in this table)",
    "sim": "manages the simulated arm's saved state",
    "pose list": "reads the config's poses",
    "pose show": "reads one pose of the config",
}

# commands another change builds (the motion session and pose moves): they come with their Arm call
PENDING: dict[str, str] = {}


def _commands() -> list[str]:
    import typer

    from sherpa_cli.cli.app import app

    def walk(cmd: object, prefix: tuple[str, ...]) -> list[str]:
        subs = getattr(cmd, "commands", None)
        if subs is None:
            return [" ".join(prefix)]
        return [name for key, sub in sorted(subs.items()) for name in walk(sub, (*prefix, key))]

    return walk(typer.main.get_command(app), ())


def test_every_command_is_in_the_table_and_every_entry_is_a_command():
    commands = set(_commands())
    listed = set(WIRED) | set(NOT_THE_ARM)
    assert not set(WIRED) & set(NOT_THE_ARM)
    assert sorted(commands - listed - set(PENDING)) == [], "a command the table does not say anything about"
    assert sorted(listed - commands) == [], "an entry for a command the app does not have"
    arrived = sorted(commands & set(PENDING))
    assert arrived == [], f"{arrived}: in the app now; move it from PENDING to WIRED with the Arm method it calls"


def test_every_method_named_is_a_public_method_of_arm():
    for command, (method, _) in {**WIRED, **VARIANTS}.items():
        assert not method.startswith("_") and callable(getattr(Arm, method, None)), f"{command}: Arm.{method}"


def _spy_every_method(monkeypatch: pytest.MonkeyPatch, calls: list[str]) -> None:
    for name, member in vars(Arm).items():
        if name.startswith("_") or not inspect.isfunction(member):  # not the static/class methods, properties
            continue

        def spy(self: Arm, *args: object, _real: Callable[..., object] = member, _name: str = name,
                **kw: object) -> object:
            calls.append(_name)
            return _real(self, *args, **kw)

        monkeypatch.setattr(Arm, name, spy)


@pytest.mark.parametrize("command", [*sorted(WIRED), *sorted(VARIANTS)])
def test_the_command_calls_its_arm_method_on_the_simulator(cli, monkeypatch, tmp_path, command):
    method, argv = {**WIRED, **VARIANTS}[command]
    import sherpa_cli.cli.ft_cmd as ft_cmd

    monkeypatch.setattr(ft_cmd, "sleep", lambda s: None)  # the stream's pacing: no wall time
    if command == "params restore":  # a dump to restore, written first
        assert cli("--sim", "dump-params", "elbow_pitch", "-o", f"{tmp_path}/dump.yaml").exit_code == 0
    if command == "pose save":  # it writes into the config: a copy of the shipped one
        shutil.copy(Path(__file__).resolve().parent.parent / "configs" / "sherpa-arm.yaml", tmp_path / "arm.yaml")
    calls: list[str] = []
    _spy_every_method(monkeypatch, calls)
    result = cli(*(a.replace("{tmp}", str(tmp_path)) for a in argv))
    # scan, doctor and params diff report what they find with exit 1; a refusal would be 2 or more
    assert result.exit_code in (0, 1), result.transcript()
    assert method in calls, f"{command}: Arm.{method} not called (called: {calls})\n{result.transcript()}"
