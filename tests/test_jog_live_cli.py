"""The CLI of `sherpa jog --interactive / --joystick / --list-joysticks` (cli/jog_live_cmd.py):
golden dry runs and refusals, and the interactive view run headless through the real command."""

from __future__ import annotations

import pytest

from tests.test_jog_view import wait_until

# the interactive view through the command, on textual's real-time event loop (see
# tests/test_jog_view.py): .ci/run runs `serial` tests alone
pytestmark = pytest.mark.serial

FAST = "tests/data/jog-fast-arm.yaml"
JOY = "tests/data/joystick-arm.yaml"
F = ["--config", FAST, "--sim"]
J = ["--config", JOY, "--sim"]
CASES = [
    ("jog-interactive-dry-run", [*F, "jog", "--interactive", "j1", "diff"], 0),
    ("jog-joystick-dry-run", [*J, "jog", "--joystick"], 0),
    ("jog-joystick-no-device", [*J, "jog", "--joystick", "--device", "/nonexistent/event9", "--apply"], 2),
    ("jog-joystick-unmapped", [*F, "jog", "--joystick", "--apply"], 2),
    ("jog-joystick-with-joint", [*J, "jog", "--joystick", "j1"], 2),
    ("jog-interactive-with-values", [*F, "jog", "--interactive", "--velocity", "1"], 2),
    ("jog-interactive-and-joystick", [*F, "jog", "--interactive", "--joystick"], 2),
    ("jog-interactive-no-terminal", [*F, "jog", "--interactive", "j1", "--apply"], 2),
    ("jog-no-joint", [*F, "jog", "--to", "1"], 2),
    ("jog-two-joints", [*F, "jog", "j1", "j2", "--to", "1"], 2),
]


@pytest.mark.golden
@pytest.mark.parametrize("name,args,code", CASES, ids=[c[0] for c in CASES])
def test_jog_live_golden(cli, golden, name, args, code):
    result = cli(*args)
    assert "Traceback" not in result.stderr
    assert result.exit_code == code, result.transcript()
    golden(f"{name}.txt", result.transcript())


def test_interactive_view_through_the_command_leaves_every_motor_off(cli, monkeypatch):
    """`sherpa --sim jog --interactive j2 --apply`, the view headless: step j2, then q."""
    from sherpa_cli.cli.jog_view import JogView
    from sherpa_cli.ops import live_jog

    seen = {}
    original_run = JogView.run
    original_exit = live_jog.LiveJog.__exit__

    async def auto(pilot):
        await pilot.pause(0.2)
        seen["start"] = pilot.app.live.state["j2"].counts
        await pilot.press("right")  # j2 has an absolute encoder: calibrated, a +0.05 rad (29 counts) step
        state = pilot.app.live.state
        # the view refreshes its state every tick: wait for the step (bounded)
        await wait_until(pilot, lambda: abs(state["j2"].counts - seen["start"] - 29) <= 1, 10)
        seen["j2"] = state["j2"].counts
        await pilot.press("q")

    def headless(self, *a, **kw):
        return original_run(self, headless=True, auto_pilot=auto, size=(120, 30))

    def record(self, *exc):
        try:
            return original_exit(self, *exc)
        finally:
            with self.session.sim.lock:
                seen["on"] = [n for n, d in self.session.sim.drives.items() if d.motor_on]

    monkeypatch.setattr(JogView, "run", headless)
    monkeypatch.setattr("sherpa_cli.cli.jog_live_cmd.have_terminal", lambda: True)
    monkeypatch.setattr(live_jog.LiveJog, "__exit__", record)
    result = cli(*F, "jog", "--interactive", "j2", "--apply")
    assert result.exit_code == 0, result.transcript()
    assert abs(seen["j2"] - seen["start"] - 29) <= 1
    assert seen["on"] == []
    assert "stop: elbow (can0:6): stopped; motor off; settings put back" in result.stdout


def test_sigterm_during_the_view_ends_with_the_interrupted_exit_code(cli, monkeypatch):
    """Review note: a SIGTERM while the view runs may be caught inside textual (the app ends with
    its own return code, no error of ours): the command still exits 130, after the guard's stop."""
    import os
    import signal

    from sherpa_cli.cli.jog_view import JogView

    original_run = JogView.run

    async def auto(pilot):
        await pilot.pause(0.2)
        # delivered while one of textual's own handlers runs: textual catches what the guard raises
        pilot.app.call_later(os.kill, os.getpid(), signal.SIGTERM)
        await pilot.pause(0.5)

    def headless(self, *a, **kw):
        return original_run(self, headless=True, auto_pilot=auto, size=(120, 30))

    monkeypatch.setattr(JogView, "run", headless)
    monkeypatch.setattr("sherpa_cli.cli.jog_live_cmd.have_terminal", lambda: True)
    result = cli(*F, "jog", "--interactive", "j2", "--apply")
    assert result.exit_code == 130, result.transcript()
    assert "SIGTERM" in result.stderr
    assert "stop: elbow (can0:6):" in result.stdout + result.stderr
