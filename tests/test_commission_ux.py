"""A `commission` a technician reads in one screen,
a dry run that exits 0 on a fresh arm, and recipes that run in one session."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from contextlib import contextmanager

import pytest

EXAMPLE3 = "configs/appendix-c/example3.yaml"


@pytest.fixture(autouse=True)
def stable_durations(monkeypatch):
    monkeypatch.setenv("SHERPA_FAKE_STEP_SECONDS", "0.5")


@pytest.fixture
def session_opens(monkeypatch):
    """How many times a command opened the arm's buses (ArmSession.open)."""
    from sherpa_cli.bus.session import ArmSession

    opens: list[int] = []
    original = ArmSession.open

    @contextmanager
    def counting(cls, *args, **kwargs):
        opens.append(1)
        with original(*args, **kwargs) as session:
            yield session

    monkeypatch.setattr(ArmSession, "open", classmethod(counting))
    return opens


def test_readme_main_command_fits_one_screen(cli, tmp_path, session_opens):
    # README: `sherpa --sim commission --apply --yes` on the whole arm prints at most 60 lines
    r = cli("--sim", "commission", "--apply", "--yes", "--set", f"backup={tmp_path / 'b.yaml'}",
            "--report", str(tmp_path / "r.json"))
    assert r.exit_code == 0, r.stdout + r.stderr
    lines = (r.stdout + r.stderr).splitlines()
    assert len(lines) <= 60, f"{len(lines)} lines:\n" + "\n".join(lines)
    assert "every drive is programmed, verified and saved (14 drives)" in r.stdout
    # one line per step, no raw JSON, every warning once
    assert not any(line.lstrip().startswith(("{", "}", '"')) for line in lines)
    warnings = [line for line in r.stderr.splitlines() if line.startswith("warning:")]
    assert len(warnings) == len(set(warnings))
    # eight steps, one session: the config loaded and the buses opened once
    assert session_opens == [1]
    # the steps' full output is in the report
    report = json.loads((tmp_path / "r.json").read_text())
    save = next(s for s in report["steps"] if s["name"] == "save")
    assert json.loads(save["stdout"])["drives"]


def test_recipe_run_opens_the_buses_once(cli, tmp_path, session_opens):
    recipe = tmp_path / "r.yaml"
    recipe.write_text("steps:\n  - run: scan\n  - run: identify\n  - run: cmd shoulder_1a PX\n"
                      "  - run: limits show elbow_pitch\n")
    r = cli("--sim", "recipe", "run", str(recipe))
    assert r.exit_code == 0, r.stdout
    assert session_opens == [1]


def test_ram_survives_between_steps_with_sim(cli, tmp_path):
    # one simulated arm for the whole recipe: what a step wrote to RAM is there at the next step
    recipe = tmp_path / "r.yaml"
    recipe.write_text("steps:\n  - run: cmd shoulder_1a AC=123456 --apply\n"
                      "  - {run: cmd shoulder_1a AC, expect: {stdout_contains: '123456'}}\n")
    r = cli("--sim", "recipe", "run", str(recipe), "--apply")
    assert r.exit_code == 0, r.stdout


def test_readme_junit_dry_run_is_green_on_a_fresh_arm(cli, tmp_path):
    # README: `sherpa --sim commission --junit commission.xml` (CI) on a fresh simulated arm
    junit = tmp_path / "commission.xml"
    r = cli("--sim", "commission", "--junit", str(junit), "--set", f"backup={tmp_path / 'b.yaml'}")
    assert r.exit_code == 0, r.stdout + r.stderr
    suite = ET.parse(junit).getroot().find("testsuite")
    assert suite.get("failures") == "0" and suite.get("errors") in (None, "0")
    assert "commissioning plan (dry run)" in r.stdout


def test_verbose_shows_the_steps_output(cli, tmp_path):
    r = cli("--config", EXAMPLE3, "--sim", "commission", "--verbose", "--set", f"backup={tmp_path / 'b.yaml'}")
    assert r.exit_code == 0, r.stdout
    assert "[3/9] plan: sherpa program-limits" in r.stdout
    assert "    -> passed (exit 0, 0.5 s)" in r.stdout
    assert "(JSON output," in r.stdout  # the save step's JSON is not dumped on the terminal
    assert not any(line.strip().startswith('"drives"') for line in r.stdout.splitlines())


def test_a_failed_step_shows_why_in_the_short_output(cli, tmp_path):
    recipe = tmp_path / "r.yaml"
    recipe.write_text("steps:\n  - run: cmd nowhere PX\n  - run: scan\n")
    r = cli("--sim", "recipe", "run", str(recipe))
    assert r.exit_code == 1
    assert "[1/2] step-1  FAILED" in r.stdout
    assert "error: unknown target 'nowhere'" in r.stdout
    assert "[2/2] step-2  skipped (step 1 (step-1) failed)" in r.stdout


def test_fake_step_seconds_must_be_a_number(cli, tmp_path, monkeypatch):
    monkeypatch.setenv("SHERPA_FAKE_STEP_SECONDS", "soon")
    r = cli("--sim", "commission")
    assert r.exit_code == 2 and "SHERPA_FAKE_STEP_SECONDS" in r.stderr and "Traceback" not in r.stderr


class _Terminal(__import__("io").StringIO):
    def isatty(self) -> bool:
        return True


def _run_at_terminal(monkeypatch, args, answer):
    import io
    from contextlib import redirect_stderr, redirect_stdout

    from sherpa_cli.cli.app import run

    monkeypatch.setattr("sys.stdin", _Terminal(answer))
    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        code = run(list(args))
    return code, out.getvalue(), err.getvalue()


def test_the_save_question_goes_to_the_terminal_and_lists_the_drives(cli, monkeypatch, tmp_path):
    cli("--version")  # the cli fixture's environment: repo root, fixed width, own state dir
    code, out, err = _run_at_terminal(monkeypatch, ["--config", EXAMPLE3, "--sim", "commission", "--apply",
                                                    "--set", f"backup={tmp_path / 'b.yaml'}"], "n\n")
    assert code == 1
    question = "Save the verified limits to flash (SV) on every drive that changed? (would save: drive1, drive2)"
    assert f"{question} [y/N]" in err, err
    assert "Save the verified" not in out  # `| tee log` shows results; the question stays on the terminal
    assert "[6/9] confirm-save  declined (answer: no)" in out


def test_program_limits_save_question_goes_to_stderr(cli, monkeypatch):
    cli("--version")
    code, out, err = _run_at_terminal(monkeypatch, ["--config", EXAMPLE3, "--sim", "program-limits", "--apply",
                                                    "--save"], "n\n")
    assert "Write and save to flash (SV): drive1, drive2? [y/N]" in err
    assert "[y/N]" not in out and code != 0


def test_progress_only_on_a_terminal_and_never_with_json(monkeypatch):
    from sherpa_cli.cli.context import AppState
    from sherpa_cli.cli.recipe_cmd import _progress

    def app_state(json_mode: bool) -> AppState:
        return AppState.create(config_path=ROOT_CONFIG, config_given=True, json_mode=json_mode, debug=False,
                               no_color=True)

    class Tty(__import__("io").StringIO):
        def isatty(self) -> bool:
            return True

    monkeypatch.setattr("sys.stderr", __import__("io").StringIO())
    assert _progress(app_state(False)) is None  # stderr is not a terminal: silent
    monkeypatch.setattr("sys.stderr", Tty())
    assert _progress(app_state(True)) is None  # --json: silent
    live = _progress(app_state(False))
    assert live is not None and live.console.file is not None


ROOT_CONFIG = __import__("pathlib").Path("configs/sherpa-arm.yaml")


@pytest.mark.golden
@pytest.mark.realbus
def test_commission_whole_arm_dry_run_golden(arm_cli, golden, tmp_path):
    # the dry run on a fresh arm: one line per step, the plan per drive, exit 0
    r = arm_cli("commission", "--set", f"backup={tmp_path / 'b.yaml'}")
    golden("commission-arm-dry-run.txt", r.transcript().replace(str(tmp_path), "<tmp>"))
    assert r.exit_code == 0, r.stdout
    assert len((r.stdout + r.stderr).splitlines()) <= 60
