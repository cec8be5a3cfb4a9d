"""`sherpa jog --interactive` headless: textual's pilot drives the view (cli/jog_view.py) on the
simulated arm (in-process, real time: the guard's heartbeat thread runs on the wall clock)."""

from __future__ import annotations

import asyncio
import math
import time
from pathlib import Path

import pytest
from motion_helpers import view_config

from sherpa_cli.bus.session import ArmSession
from sherpa_cli.cli.jog_view import HomeConfirm, JogView, bar
from sherpa_cli.config import load_config
from sherpa_cli.ops.live_jog import LiveJog, resolve_axes
from sherpa_cli.sim.arm import SimArm
from tests.test_home import physical, px

# the interactive view runs on textual's event loop in real time, its ticks feeding the guard's
# liveness watch: beside other workers on a loaded machine the watch took the starved loop for a hung
# command (2026-11-29, 4 workers and 2 busy processes). .ci/run runs `serial` tests alone
pytestmark = pytest.mark.serial



@pytest.fixture
def cfg():
    return view_config()


def cpr_of(cfg, joint: str) -> int:
    return cfg.joints[joint].cpr


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
                await pilot.press("right")  # position step: +0.05 rad = 29 counts (the default increment)
                # the view refreshes its state every tick (0.25 s): wait for the step, do not guess its time
                await wait_until(pilot, lambda: abs(live.state["j2"].counts - start - 29) <= 1, 10)
                seen["stepped"] = live.state["j2"].counts - start
                await pilot.press("m")  # velocity mode
                assert live.state["j2"].mode == "velocity"
                await pilot.press("right", "right")  # set point 2 x 0.1 rad/s = 115 counts/s, running
                await pilot.pause(0.2)
                seen["running"] = dict(live.running)
                seen["msg1"] = (app.message, list(live.messages), live.state["j2"])
                seen["on_while_running"] = motors_on(session)
                await pilot.press("space")  # stops everything
                await pilot.pause(0.2)
                seen["after_space"] = dict(live.running)
                seen["setpoint"] = app.setpoint["j2"]
                seen["status"] = str(app.query_one("#status").render())
                await pilot.press("left")  # velocity -0.1 rad/s again
                await pilot.pause(0.1)
                seen["running_again"] = dict(live.running)
                seen["msg"] = app.message
                await pilot.press("q")
            seen["report"] = live.report
        return seen

    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        seen = asyncio.run(scenario(s))
        assert abs(seen["stepped"] - 29) <= 1
        assert set(seen["running"]) == {"j2"}, seen["msg1"]
        assert seen["running"]["j2"].motors == {"elbow": 115}
        assert seen["on_while_running"] == {"elbow"}
        assert seen["after_space"] == {} and seen["setpoint"] == 0.0 and "every joint stopped" in seen["status"]
        assert seen["running_again"]["j2"].motors == {"elbow": -57}, seen["msg"]
        # q left with every motor stopped and off: the guard's report and the simulator's record
        assert motors_on(s) == set()
        assert {d.drive for d in seen["report"].drives} == {"yaw", "elbow"}
        assert all(d.stopped_by != "not stopped" for d in seen["report"].drives)
        events = motor_events(s)["elbow"]
        assert any("motor on" in e for e in events) and any("motor off" in e for e in events)
        assert s.sim.errors == []


def test_uncalibrated_steps_are_refused_and_calibrate_says_why_a_joint_cannot_be_homed(cfg):
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
        assert cal == "calibrate: j1: cannot be homed: no calibration speed (calibration: {speed: ...})"
        assert "calibrated" in refused and running == 0
        assert motors_on(s) == set()
        assert not any("BG" in e for e in motor_events(s)["yaw"])  # nothing moved


# -- the calibrate key: `home` from inside the view (tests/data/home-arm.yaml) -----------------------

HOME_ARM = Path(__file__).resolve().parent / "data" / "home-arm.yaml"
CONSUMER = (0x1016, 1)


async def wait_until(pilot, cond, timeout: float = 60.0) -> bool:
    """Let the view run until ``cond()`` holds (bounded: the simulated homing runs in real time)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return True
        await pilot.pause(0.1)
    return cond()


def home_arm(tmp_path, *replace: tuple[str, str]):
    """tests/data/home-arm.yaml with a patient dead-man: the view ticks from textual's event loop,
    which a loaded machine can hold up for a second (the guard would rightly give up)."""
    text = HOME_ARM.read_text(encoding="utf-8").replace(
        "motion: {consumer_time_ms: 300}", "motion: {consumer_time_ms: 1000, liveness_timeout: 5.0}")
    for old, new in replace:
        assert old in text
        text = text.replace(old, new)
    path = tmp_path / "arm.yaml"
    path.write_text(text, encoding="utf-8")
    return load_config(path)


def consumer_writes(session, drive: str) -> list[int]:
    with session.sim.lock:
        return [v for _, i, sub, v in session.sim.drives[drive].od_writes if (i, sub) == CONSUMER]


def test_calibrate_shows_the_plan_cancel_moves_nothing_confirm_homes_and_the_jog_resumes(tmp_path):
    cfg = home_arm(tmp_path)

    async def scenario(session) -> dict:
        seen: dict = {}
        with LiveJog(session, resolve_axes(cfg, ["yaw"]), keepalive=30.0) as live:
            app = JogView(live, tick_period=0.2)
            async with app.run_test(size=(130, 40)) as pilot:
                await pilot.pause(0.1)
                assert not live.state["yaw"].calibrated
                await pilot.press("right")  # a position step: refused, the joint is not homed
                seen["refused"] = str(app.query_one("#detail").render())
                # velocity mode, -200 counts/s (away from the home switch above): the live guard switches
                # the motor on; Space stops it (it stays on, holding)
                await pilot.press("m", "left")
                seen["jogging"] = dict(live.running)
                await pilot.press("space")
                await pilot.press("c")
                await wait_until(pilot, lambda: isinstance(app.screen, HomeConfirm), 10)
                seen["screen"] = app.screen
                seen["plan"] = "\n".join(app.screen.lines)
                await pilot.press("n")  # cancel: nothing homed, the jog goes on
                seen["cancelled"] = (app.message, type(app.screen).__name__, dict(live.running))
                await pilot.press("c")
                await wait_until(pilot, lambda: isinstance(app.screen, HomeConfirm), 10)
                await pilot.press("enter")
                seen["done"] = await wait_until(pilot, lambda: app.homing is None and "homed" in app.message)
                seen["message"] = app.message
                seen["calibrated"] = live.state["yaw"].calibrated
                seen["on_after_home"] = motors_on(session)
                await pilot.pause(0.3)
                seen["detail_after"] = str(app.query_one("#detail").render())
                # the jog resumes on the calibrated joint: a position step is accepted now
                await pilot.press("m", "m")  # velocity -> torque -> position
                start = live.state["yaw"].counts
                await pilot.press("right")
                await wait_until(pilot, lambda: "yaw" not in live.running, 10)
                step = round(0.05 * cpr_of(cfg, "yaw") / (2 * math.pi))
                await wait_until(pilot, lambda: abs(live.state["yaw"].counts - start - step) <= 1, 10)
                seen["stepped"] = live.state["yaw"].counts - start
                seen["note"] = live.state["yaw"].note
                await pilot.press("q")
            seen["report"] = live.report
            seen["log"] = list(app.home_log)
        return seen

    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        seen = asyncio.run(scenario(s))
        assert seen["done"], seen["message"]
        assert seen["jogging"]["yaw"].motors == {"yaw_drive": -round(0.1 * cpr_of(cfg, "yaw") / (2 * math.pi))}
        assert isinstance(seen["screen"], HomeConfirm)
        assert "search: yaw up at 1000 counts/s, at most 820 counts" in seen["plan"]
        assert "uses input 1: home switch" in seen["plan"]
        msg, screen, _running = seen["cancelled"]
        assert msg == "calibrate yaw: cancelled, nothing moved" and screen != "HomeConfirm"
        assert seen["done"], seen["message"]
        assert seen["message"].startswith("calibrate: yaw: homed (home switch): set yaw = 0"), seen["message"]
        assert seen["calibrated"] and seen["on_after_home"] == set()  # home's guard switched it off again
        # the "not homed" refusal was shown, and is gone once homed (no stale message)
        assert "position steps need a calibrated joint" in seen["refused"]
        assert "calibrated joint" not in seen["detail_after"] and "NOT calibrated" not in seen["detail_after"]
        assert abs(seen["stepped"] - round(0.05 * cpr_of(cfg, "yaw") / (2 * math.pi))) <= 1, seen["note"]
        assert abs(physical(s, "yaw_drive") - px(s, "yaw_drive")) <= 1  # the counter means the joint now
        # the simulator's record: the jog's motor on, its stop and motor off before homing; the homing
        # (home event); home's own motor off; the step's motor on; q's motor off
        events = motor_events(s)["yaw_drive"]
        first_home = next(i for i, e in enumerate(events) if e.startswith("home event"))
        assert "motor off: MO=0" in events[:first_home]
        assert events[:first_home].index("motor off: MO=0") > events.index("motor on: MO=1")
        assert events[-1] == "motor off: MO=0" and motors_on(s) == set()
        # one motion guard at a time on the drive: the dead-man is armed and put back in turn
        # (live guard, home's guard, live guard again), never armed twice over
        writes = consumer_writes(s, "yaw_drive")
        assert len(writes) == 6 and writes[1::2] == [0, 0, 0] and all(w for w in writes[0::2]), writes
        assert any(line.startswith("stop: yaw_drive") and "motor off" in line for line in seen["log"])
        assert all(d.stopped_by != "not stopped" for d in seen["report"].drives)
        assert s.sim.errors == []


def test_calibrate_homes_a_pair_as_one_unit_from_its_sigma_joint(tmp_path):
    cfg = home_arm(tmp_path)

    async def scenario(session) -> dict:
        seen: dict = {}
        with LiveJog(session, resolve_axes(cfg, ["diff"])) as live:
            app = JogView(live, tick_period=0.2)
            async with app.run_test(size=(130, 40)) as pilot:
                await pilot.pause(0.1)
                assert app.current == "pitch"
                await pilot.press("c")
                await wait_until(pilot, lambda: isinstance(app.screen, HomeConfirm), 10)
                seen["plan"] = "\n".join(app.screen.lines)
                await pilot.press("y")
                seen["done"] = await wait_until(pilot, lambda: app.homing is None and app.message.startswith(
                    "calibrate"), 90)
                seen["message"] = app.message
                seen["calibrated"] = (live.state["pitch"].calibrated, live.state["roll"].calibrated)
                await pilot.press("q")
        return seen

    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        seen = asyncio.run(scenario(s))
        assert "diff (differential pair; drives pair_a, pair_b)" in seen["plan"]
        assert "search: roll down" in seen["plan"]
        assert seen["done"] and seen["message"].startswith("calibrate: diff: homed (differential pair)"), seen
        assert seen["calibrated"] == (True, True)
        for d in ("pair_a", "pair_b"):
            assert any(e.startswith("home event") for e in motor_events(s)[d])
        assert motors_on(s) == set() and s.sim.errors == []


def test_calibrate_failure_leaves_the_motor_stopped_and_off_and_the_joint_uncalibrated(tmp_path):
    # the home switch never triggers: the search stops at its bound (820 counts up from -400)
    cfg = home_arm(tmp_path, ("power_up: {yaw: -150,", "power_up: {yaw: -400,"),
                   ("buses:", "  wiring: {yaw_drive: {swap: [[1, 2]]}}\nbuses:"))

    async def scenario(session) -> dict:
        seen: dict = {}
        with LiveJog(session, resolve_axes(cfg, ["yaw"])) as live:
            app = JogView(live, tick_period=0.2)
            async with app.run_test(size=(130, 40)) as pilot:
                await pilot.press("c")
                await wait_until(pilot, lambda: isinstance(app.screen, HomeConfirm), 10)
                await pilot.press("enter")
                seen["done"] = await wait_until(pilot, lambda: app.homing is None and app.message.startswith(
                    "calibrate"), 60)
                seen["message"] = app.message
                seen["calibrated"] = live.state["yaw"].calibrated
                seen["on"] = motors_on(session)
                seen["events"] = motor_events(session)["yaw_drive"]
                seen["log"] = list(app.home_log)
                await pilot.pause(0.6)  # ticks: the limit watch must not move a joint whose homing failed
                seen["events_later"] = motor_events(session)["yaw_drive"]
                await pilot.press("m", "left")  # a command to it is refused
                seen["refused"] = app.message
                await pilot.press("q")
        return seen

    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        seen = asyncio.run(scenario(s))
        assert seen["done"] and "never triggered: stopped at the search bound" in seen["message"], str(seen)
        assert not seen["calibrated"] and seen["on"] == set()
        assert seen["events"] == ["motor on: MO=1", "BG: UM=5, PR=820", "motor off: MO=0"]  # home's guard
        assert seen["events_later"] == seen["events"]
        assert "not commanded again" in seen["refused"] and "homing failed" in seen["refused"]
        assert motors_on(s) == set()
        assert consumer_writes(s, "yaw_drive")[-1] == 0  # the dead-man put back on the way out


def test_space_aborts_a_running_homing_and_its_guard_stops_the_motor(tmp_path):
    # a slow search (40 counts/s: about 4 s to the switch), so Space comes while it runs
    cfg = home_arm(tmp_path, ("calibration: {speed: 1000, position: 0}", "calibration: {speed: 40, position: 0}"))

    async def scenario(session) -> dict:
        seen: dict = {}
        with LiveJog(session, resolve_axes(cfg, ["yaw"])) as live:
            app = JogView(live, tick_period=0.2)
            async with app.run_test(size=(130, 40)) as pilot:
                await pilot.press("c")
                await wait_until(pilot, lambda: isinstance(app.screen, HomeConfirm), 10)
                await pilot.press("enter")
                await wait_until(pilot, lambda: motors_on(session) == {"yaw_drive"}, 20)
                await pilot.press("space")
                seen["done"] = await wait_until(pilot, lambda: app.homing is None, 20)
                seen["message"] = app.message
                seen["on"] = motors_on(session)
                seen["calibrated"] = live.state["yaw"].calibrated
                await pilot.press("q")
        return seen

    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        seen = asyncio.run(scenario(s))
        assert seen["done"] and "homing aborted" in seen["message"], seen
        assert seen["on"] == set() and not seen["calibrated"]
        with s.sim.lock:
            assert s.sim.drives["yaw_drive"].ram.get("UI[3]", 0) == 0
        events = motor_events(s)["yaw_drive"]
        assert events == ["motor on: MO=1", "BG: UM=5, PR=820", "motor off: MO=0"]  # no home event
        assert motors_on(s) == set() and s.sim.errors == []
