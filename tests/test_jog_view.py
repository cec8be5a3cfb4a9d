"""`sherpa jog --interactive` headless: textual's pilot drives the view (cli/jog_view.py) on the
simulated arm (in-process, real time: the guard's heartbeat thread runs on the wall clock)."""

from __future__ import annotations

import asyncio

import pytest

from sherpa_cli.cli.jog_view import JogView, bar
from sherpa_cli.config import load_config
from sherpa_cli.ops.live_jog import LiveJog, resolve_axes
from sherpa_cli.ops.session import ArmSession
from sherpa_cli.sim.arm import SimArm
from motion_helpers import JOG_CONFIG

CONFIG = JOG_CONFIG


@pytest.fixture
def cfg():
    return load_config(CONFIG)


def motor_events(session):
    with session.sim.lock:
        return {name: [text for _, text in d.events] for name, d in session.sim.drives.items()}


def motors_on(session):
    with session.sim.lock:
        return {name for name, d in session.sim.drives.items() if d.motor_on}


def test_bar_marks_the_normal_range_and_the_position():
    assert bar(0, (-100, 100), (-50, 50), width=11) == "[··───●───··]"
    assert bar(-500, (-100, 100), (-50, 50), width=11) == "[◀·───────··]"


def test_select_step_switch_mode_space_stops_and_q_leaves_with_every_motor_stopped(cfg):
    async def scenario(session) -> dict:
        seen: dict = {}
        with LiveJog(session, resolve_axes(cfg, ["j1", "j2"]), keepalive=30.0) as live:
            app = JogView(live, tick_period=0.25)
            async with app.run_test(size=(120, 30)) as pilot:
                await pilot.pause(0.1)
                assert app.current == "j1"
                await pilot.press("down")  # select j2 (absolute encoder: calibrated)
                assert app.current == "j2"
                start = live.state["j2"].counts
                await pilot.press("right")  # position step: +50 counts (the default increment)
                await pilot.pause(0.4)
                seen["stepped"] = live.state["j2"].counts - start
                await pilot.press("m")  # velocity mode
                assert live.state["j2"].mode == "velocity"
                await pilot.press("right", "right")  # set point 2 x 200 counts/s, running
                await pilot.pause(0.2)
                seen["running"] = dict(live.running)
                seen["msg1"] = (app.message, list(live.messages), live.state["j2"])
                seen["on_while_running"] = motors_on(session)
                await pilot.press("space")  # stops everything
                await pilot.pause(0.2)
                seen["after_space"] = dict(live.running)
                seen["setpoint"] = app.setpoint["j2"]
                seen["status"] = str(app.query_one("#status").render())
                await pilot.press("left")  # velocity -200 again
                await pilot.pause(0.1)
                seen["running_again"] = dict(live.running)
                seen["msg"] = app.message
                await pilot.press("q")
            seen["report"] = live.report
        return seen

    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        seen = asyncio.run(scenario(s))
        assert abs(seen["stepped"] - 50) <= 1
        assert set(seen["running"]) == {"j2"}, seen["msg1"]
        assert seen["running"]["j2"].motors == {"elbow": 400}
        assert seen["on_while_running"] == {"elbow"}
        assert seen["after_space"] == {} and seen["setpoint"] == 0.0 and "every joint stopped" in seen["status"]
        assert seen["running_again"]["j2"].motors == {"elbow": -200}, seen["msg"]
        # q left with every motor stopped and off: the guard's report and the simulator's record
        assert motors_on(s) == set()
        assert {d.drive for d in seen["report"].drives} == {"yaw", "elbow"}
        assert all(d.stopped_by != "not stopped" for d in seen["report"].drives)
        events = motor_events(s)["elbow"]
        assert any("motor on" in e for e in events) and any("motor off" in e for e in events)
        assert s.sim.errors == []


def test_calibrate_says_honestly_when_home_is_missing_and_uncalibrated_steps_are_refused(cfg):
    async def scenario(session) -> tuple[str, str, int]:
        with LiveJog(session, resolve_axes(cfg, ["j1"])) as live:
            app = JogView(live, tick_period=0.25)
            async with app.run_test(size=(120, 30)) as pilot:
                await pilot.press("c")
                cal = app.message
                await pilot.press("right")
                await pilot.pause(0.1)
                refused = live.state["j1"].note
                running = len(live.running)
                await pilot.press("ctrl+c")
        return cal, refused, running

    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        cal, refused, running = asyncio.run(scenario(s))
        assert cal == "calibrate: not available yet (sherpa home)"
        assert "calibrated" in refused and running == 0
        assert motors_on(s) == set()
