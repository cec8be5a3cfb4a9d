"""The seed's test GUI (Appendix E) in the terminal, headless at 80x24:
the selected joint and the key help always on screen, typed set points in joint units with
Start/Stop, the set point shown equal to what was sent, Get Status with details on request, Calibrate
(the home plan fits the screen, the joint is homed); and
the shipped config's `joystick:` section (the seed's Z axis and XY+/XY-) with a scripted device.

The simulated arm runs in-process in real time (the guard's heartbeat thread runs on the wall
clock); every wait is bounded and polls for its condition."""

from __future__ import annotations

import asyncio
import time
from pathlib import Path

import pytest
from motion_helpers import stepped_session, view_config

from sherpa_cli.bus.session import ArmSession
from sherpa_cli.cli.jog_view import KEY_HELP, HomeConfirm, JogView, SetPointDialog
from sherpa_cli.joints import units
from sherpa_cli.ops import joystick
from sherpa_cli.ops.joystick import ScriptedSource, run_joystick
from sherpa_cli.ops.live_jog import LiveJog, resolve_axes
from sherpa_cli.sim.arm import SimArm
from tests.test_jog_view import home_arm, wait_until

# the interactive view on textual's real-time event loop (see tests/test_jog_view.py):
# .ci/run runs `serial` tests alone, after the parallel run
pytestmark = pytest.mark.serial

SHIPPED = Path(__file__).resolve().parent.parent / "configs" / "sherpa-arm.yaml"
SIZE = (80, 24)


def text_of(app, widget: str) -> str:
    return str(app.screen_stack[0].query_one(widget).render())


def on_screen(app, widget: str) -> bool:
    region = app.screen_stack[0].query_one(widget).region
    return region.height > 0 and region.y >= 0 and region.y + region.height <= SIZE[1]


def motors_on(session):
    with session.sim.lock:
        return {name for name, d in session.sim.drives.items() if d.motor_on}


async def until(pilot, cond, timeout: float = 10.0) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return True
        await pilot.pause(0.05)
    return cond()


async def type_set_point(pilot, app, text: str) -> None:
    await pilot.press("t")
    assert await until(pilot, lambda: isinstance(app.screen, SetPointDialog))
    await pilot.press(*text)
    await pilot.press("enter")


def test_every_joint_of_the_shipped_arm_is_reachable_at_80x24_with_the_key_help_visible(cli_windows):
    cfg = view_config(SHIPPED)
    cli_windows(True)  # short MO windows in the simulator and the session

    async def scenario(session) -> list[str]:
        problems = []
        with LiveJog(session, resolve_axes(cfg, None)) as live:
            app = JogView(live, tick_period=0.3)
            async with app.run_test(size=SIZE) as pilot:
                await pilot.pause(0.3)
                for i, name in enumerate(app.names):
                    if i:
                        await pilot.press("down")
                    listing = text_of(app, "#list")
                    row = next((line for line in listing.splitlines() if line.startswith("▶ ")), "")
                    if not row.startswith(f"▶ {name} "):
                        problems.append(f"{name} not the marked row: {row!r}")
                    if not text_of(app, "#detail").startswith(name):
                        problems.append(f"{name}: the panel shows {text_of(app, '#detail')[:30]!r}")
                    for w in ("#list", "#detail", "#status", "#keys"):
                        if not on_screen(app, w):
                            problems.append(f"{name}: {w} off screen")
                    if max(len(line) for line in listing.splitlines()) > SIZE[0] - 2:
                        problems.append(f"{name}: a list line is wider than the screen")
                keys = text_of(app, "#keys")
                if keys != KEY_HELP or "c calibrate" not in keys or "q quit" not in keys:
                    problems.append(f"key help: {keys!r}")
                await pilot.press("q")
        return problems

    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        assert asyncio.run(scenario(s)) == []
        assert motors_on(s) == set()


def test_typed_targets_start_stop_and_get_status_in_joint_units():
    cfg = view_config()
    cpr = cfg.joints["j2"].cpr

    async def scenario(session) -> dict:
        seen: dict = {}
        with LiveJog(session, resolve_axes(cfg, ["j1", "j2", "diff"]), keepalive=30.0) as live:
            app = JogView(live, tick_period=0.2)
            async with app.run_test(size=SIZE) as pilot:
                await pilot.pause(0.2)
                await pilot.press("down")  # j2: absolute encoder, calibrated
                # a typed position target in rad, then in deg; Enter starts
                await type_set_point(pilot, app, "0.1")
                seen["typed"] = app.typed["j2"]["position"]
                await pilot.press("enter")
                seen["at_rad"] = await until(pilot, lambda: "j2" not in live.running
                                             and abs(live.state["j2"].counts - units.rad_to_counts(0.1, cpr)) <= 1)
                await type_set_point(pilot, app, "-5deg")
                await pilot.press("enter")
                seen["at_deg"] = await until(pilot, lambda: "j2" not in live.running
                                             and abs(live.state["j2"].counts - units.deg_to_counts(-5, cpr)) <= 1)
                # a bad set point: one message in the dialog, which stays open; Esc leaves it unchanged
                await pilot.press("t")
                await until(pilot, lambda: isinstance(app.screen, SetPointDialog))
                await pilot.press(*"fast", "enter")
                seen["bad"] = (type(app.screen).__name__, str(app.screen.query_one("#error").render()))
                await pilot.press("escape")
                seen["after_bad"] = app.typed["j2"]["position"]
                # velocity: typed in rad/s, Start runs it, the panel shows what was sent; Stop stops
                await pilot.press("m")
                await type_set_point(pilot, app, "0.2")
                await pilot.press("enter")
                seen["vel_running"] = dict(live.running["j2"].motors)
                seen["vel_sent"] = app.sent("j2")
                seen["vel_panel"] = text_of(app, "#detail")
                await pilot.press("s")
                seen["stopped"] = ("j2" in live.running, app.message)
                # torque above the continuous limit: refused, nothing runs, the set point stays 0
                await pilot.press("m")
                await type_set_point(pilot, app, "5A")
                await pilot.press("enter")
                seen["torque"] = (dict(live.running), app.setpoint["j2"], app.message)
                # a Σ joint: the set point shown is the joint's, the motors get half each (the old view
                # showed "set 400 counts/s" while sending 200 to each motor)
                await pilot.press("down")  # pitch
                await pilot.press("m", "right")  # velocity, +0.1 rad/s
                seen["sigma_motors"] = dict(live.running["pitch"].motors)
                seen["sigma_sent"] = app.sent("pitch")
                seen["sigma_setpoint"] = app.setpoint["pitch"]
                seen["sigma_panel"] = text_of(app, "#detail")
                await pilot.press("space")
                # Get Status: OK, details on request
                await pilot.press("g")
                seen["status"] = (app.message, text_of(app, "#detail"))
                await pilot.press("d")
                seen["details"] = text_of(app, "#detail")
                seen["keys_visible"] = on_screen(app, "#keys")
                await pilot.press("q")
            seen["report"] = live.report
        return seen

    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        seen = asyncio.run(scenario(s))
    assert seen["typed"] == pytest.approx(units.counts_to_rad(units.rad_to_counts(0.1, cpr), cpr))
    assert seen["at_rad"] and seen["at_deg"]
    assert seen["bad"][0] == "SetPointDialog" and "set point" in seen["bad"][1] and "'fast'" in seen["bad"][1]
    assert seen["after_bad"] == pytest.approx(units.counts_to_rad(units.deg_to_counts(-5, cpr), cpr))
    jv = units.rad_per_s_to_counts_per_s(0.2, cpr)
    assert seen["vel_running"] == {"elbow": jv}
    assert seen["vel_sent"][0] == pytest.approx(units.counts_per_s_to_rad_per_s(jv, cpr))
    assert f"running: {seen['vel_sent'][0]:+.4g} rad/s = elbow JV={jv}" in seen["vel_panel"]
    assert seen["stopped"] == (False, "j2: stopped")
    running, setpoint, message = seen["torque"]
    assert running == {} and setpoint == 0.0 and "above the continuous limit" in message
    a, b = seen["sigma_motors"].values()
    sigma_cpr = cfg.joints["pitch"].cpr
    assert seen["sigma_setpoint"] == pytest.approx(0.1)
    assert seen["sigma_sent"][0] == pytest.approx(units.counts_per_s_to_rad_per_s(a + b, sigma_cpr))
    assert abs(seen["sigma_sent"][0] - 0.1) < 2 * 2 * 3.1416 / sigma_cpr  # the joint's speed, to a count
    assert f"left JV={a}, right JV={b}" in seen["sigma_panel"] and "rad/s" in seen["sigma_panel"]
    # the status once: in the panel; the message only says it was read (it said "status OK" twice)
    assert seen["status"][0] == "pitch: status read" and "status: OK" in seen["status"][1]
    assert "SR 0x" in seen["details"] and "MF 0x" in seen["details"] and "left:" in seen["details"]
    assert seen["keys_visible"]
    assert all(d.stopped_by != "not stopped" for d in seen["report"].drives)


def test_an_expired_velocity_set_point_goes_back_to_0_on_screen():
    """docs/jog.md: a velocity or torque command that expires sets its set point back to 0, so the
    next press starts small; the panel kept showing the expired +0.1 rad/s. On stepped time, the
    view's ticks called by hand: the expiry comes when the test moves the clock, whatever the load."""
    cfg = view_config()

    async def scenario(session, stepped) -> dict:
        seen: dict = {}
        with LiveJog(session, resolve_axes(cfg, ["j2"]), keepalive=0.3, clock=stepped.now,
                     sleep=stepped.sleep) as live:
            app = JogView(live, tick_period=3600.0)  # no tick of its own: app.tick() below
            async with app.run_test(size=SIZE) as pilot:
                await pilot.pause(0.1)
                await pilot.press("m", "right")  # velocity, +0.1 rad/s, for the keepalive
                app.tick()
                seen["running"] = "j2" in live.running
                seen["during"] = text_of(app, "#detail")
                stepped.sleep(0.5)  # past the keepalive
                app.tick()
                seen["expired"] = "j2" not in live.running
                await pilot.pause(0.05)
                seen["after"] = text_of(app, "#detail")
                seen["typed"] = app.typed["j2"].get("velocity")
                await pilot.press("right")  # starts small again: one step, not two
                seen["again"] = app.setpoint["j2"]
                await pilot.press("space")
                await pilot.press("q")
        return seen

    with stepped_session(cfg) as (s, stepped):
        seen = asyncio.run(scenario(s, stepped))
    assert seen["running"] and "set point +0.1 rad/s" in seen["during"], seen["during"]
    assert seen["expired"]
    assert "set point +0 rad/s" in seen["after"] and seen["typed"] == 0.0, seen["after"]
    assert seen["again"] == pytest.approx(0.1)


@pytest.mark.parametrize("size", [(80, 24), (120, 40)])
def test_a_taller_wider_terminal_lists_every_joint_and_gives_the_rest_to_the_panel(size):
    """At 120x40 the shipped arm's list kept 16 blank lines and the bars 16 columns; at 80x24 the
    list scrolls as before and the detail keeps its six lines."""
    cfg = view_config(SHIPPED)
    names = list(cfg.joints)

    async def scenario(session) -> dict:
        seen: dict = {}
        with LiveJog(session, resolve_axes(cfg, names), keepalive=30.0) as live:
            app = JogView(live, tick_period=0.2)
            async with app.run_test(size=size) as pilot:
                await pilot.pause(0.2)
                await pilot.press("g")
                base = app.screen_stack[0]
                seen["regions"] = {w: base.query_one(w).region for w in ("#list", "#detail", "#status", "#keys")}
                seen["list"] = text_of(app, "#list")
                seen["detail"] = text_of(app, "#detail")
                await pilot.press("q")
        return seen

    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        seen = asyncio.run(scenario(s))
    r = seen["regions"]
    # no blank band: the panels follow each other down to the key help on the last lines
    assert r["#list"].y == 0 and r["#detail"].y == r["#list"].bottom and r["#status"].y == r["#detail"].bottom
    assert r["#keys"].bottom == size[1]
    bar = max(len(part) for line in seen["list"].splitlines() for part in line.split() if part.startswith("["))
    if size == (120, 40):
        assert r["#list"].height == len(names) and "above" not in seen["list"]
        assert "SR 0x" in seen["detail"] and "(d: details)" not in seen["detail"]  # room: shown without d
        assert bar > 16 + 2
    else:
        assert r["#list"].height < len(names) and "below" in seen["list"]
        assert r["#detail"].height == 7 and "(d: details)" in seen["detail"] and "SR 0x" not in seen["detail"]
        assert bar == 16 + 2


def test_the_shipped_joystick_section_is_the_seeds_mapping_and_drives_it(cli_windows, monkeypatch):
    """configs/sherpa-arm.yaml's `joystick:`: Z -> the lower rotation; X/Y -> the shoulder pair as
    XY+ (motor a at X+Y) and XY- (motor b at X-Y); a scripted device in place of the stick.

    With the drives echoing sets: without the echo, on stepped time, the live jog's first set after
    MO=1 gets no answer at all (an open finding of the strict default, docs/testing.md)."""
    import conftest

    monkeypatch.setattr(conftest, "TEST_PROTOCOL_WINDOWS", {**conftest.TEST_PROTOCOL_WINDOWS, "set_echo": True})
    cfg = view_config(SHIPPED)
    cli_windows(True)
    j = cfg.joystick
    maps = {(m.axis, m.joint) if m.joint else (m.x, m.y, m.pair, m.mix) for m in j.axes}
    assert maps == {("ABS_Z", "shoulder_yaw"), ("ABS_X", "ABS_Y", "shoulder_diff", "xy")}
    assert j.deadman == "BTN_TRIGGER" and j.device is None  # the seed's device is unknown: commented out

    def px(session, drive):
        with session.sim.lock:
            return session.sim.drives[drive].motor.counts

    def run(session, x: float, y: float, z: float) -> dict[str, int]:
        start = {d: px(session, d) for d in ("shoulder_1a", "shoulder_2a", "shoulder_2b")}
        axes = resolve_axes(cfg, joystick.joints_of(cfg, j))
        script = [(0.0, "BTN_TRIGGER", 1.0), (0.0, "ABS_X", x), (0.0, "ABS_Y", y), (0.0, "ABS_Z", z),
                  (2.0, "BTN_TRIGGER", 0.0)]
        with LiveJog(session, axes, keepalive=0.3, clock=stepped.now, sleep=stepped.sleep) as live:
            run_joystick(live, cfg, j, ScriptedSource(script, stepped.now), clock=stepped.now, sleep=stepped.sleep,
                         duration=2.2)
        return {d: px(session, d) - v for d, v in start.items()}

    # on stepped time (as tests/test_joystick.py): how far the joints get is the simulated drives', not the load's
    with stepped_session(cfg) as (s, stepped):
        moved = run(s, x=1.0, y=0.0, z=1.0)  # X alone: XY+ = XY-, both motors forward (Σ); Z: the yaw
        assert moved["shoulder_1a"] > 20, moved
        assert moved["shoulder_2a"] > 20 and abs(moved["shoulder_2a"] - moved["shoulder_2b"]) < 0.2 * moved[
            "shoulder_2a"], moved
        moved = run(s, x=0.0, y=1.0, z=0.0)  # Y alone: motor a forward, motor b backward (Δ)
        assert moved["shoulder_1a"] == 0, moved
        assert moved["shoulder_2a"] > 20 and moved["shoulder_2b"] < -20, moved
        assert motors_on(s) == set()


def test_calibrate_at_80x24_shows_the_whole_plan_and_homes_the_joint(tmp_path):
    """The seed GUI's Calibrate button at 80x24: the plan dialog and its answer line fit the screen,
    Enter homes, the joint is calibrated afterwards (no stale "not homed" note) and the key help stays."""
    cfg = home_arm(tmp_path)

    async def scenario(session) -> dict:
        seen: dict = {}
        with LiveJog(session, resolve_axes(cfg, ["yaw"]), keepalive=30.0) as live:
            app = JogView(live, tick_period=0.2)
            async with app.run_test(size=SIZE) as pilot:
                await pilot.pause(0.1)
                seen["before"] = live.state["yaw"].calibrated
                await pilot.press("c")
                await wait_until(pilot, lambda: isinstance(app.screen, HomeConfirm), 10)
                plan = app.screen.query_one("#plan")
                r = plan.region
                seen["plan_fits"] = (r.height > 0 and r.x >= 0 and r.y >= 0 and r.x + r.width <= SIZE[0]
                                     and r.y + r.height <= SIZE[1])
                seen["plan"] = str(plan.render())
                await pilot.press("enter")
                seen["done"] = await wait_until(pilot, lambda: app.homing is None and "homed" in app.message)
                seen["message"] = app.message
                seen["calibrated"] = live.state["yaw"].calibrated
                await pilot.pause(0.3)
                seen["detail"] = text_of(app, "#detail")
                seen["keys_on_screen"] = on_screen(app, "#keys") and text_of(app, "#keys") == KEY_HELP
                await pilot.press("q")
        return seen

    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        seen = asyncio.run(scenario(s))
        assert seen["done"], seen["message"]
        assert seen["before"] is False and seen["calibrated"] is True
        assert seen["plan_fits"], seen["plan"]
        assert "search: yaw up at 1000 counts/s" in seen["plan"] and "Enter/y: home now" in seen["plan"]
        assert seen["message"].startswith("calibrate: yaw: homed (home switch)"), seen["message"]
        assert "NOT calibrated" not in seen["detail"] and "yaw (yaw_drive) calibrated" in seen["detail"]
        assert seen["keys_on_screen"]
        assert motors_on(s) == set()
        assert s.sim.errors == []


def test_docs_jog_md_shows_the_views_key_help_and_step_sizes():
    """docs/jog.md's screen and key table are the view's: its key help word for word, and the step sizes
    in joint units per mode."""
    from sherpa_cli.cli.jog_view import INCREMENTS, UNITS

    doc = (SHIPPED.parent.parent / "docs" / "jog.md").read_text(encoding="utf-8")
    assert KEY_HELP in doc
    for mode, steps in INCREMENTS.items():
        listed = f"{mode} {', '.join(f'{v:g}' for v in steps)} {UNITS[mode]}"
        assert listed in doc, listed


def test_the_running_torque_of_a_sigma_joint_is_its_set_point_not_the_sum_of_its_motors():
    """A 0.1 A torque on the Σ joint sends about 0.1 A to each motor; "running:" said +0.2 A (their
    sum). It says the joint's current now, IΣ = (Ia + Ib) / 2 (docs/motion.md)."""
    cfg = view_config()
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s, \
            LiveJog(s, resolve_axes(cfg, ["pitch"]), keepalive=30.0) as live:
        message = live.set_torque("pitch", 0.1)
        assert "pitch" in live.running, message
        app = JogView(live, tick_period=0.2)
        value, text = app.sent("pitch")
        live.stop_all()
    assert value == pytest.approx(0.1)
    assert text.startswith("left TC=") and ", right TC=" in text
