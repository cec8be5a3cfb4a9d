"""`sherpa jog --joystick` (ops/joystick.py) with a scripted event source in place of the device,
on the simulated arm in-process on stepped time (sim/stepped.py: the motors move only while the loop
waits, so how far a joint gets does not depend on the host's load); and with a real uinput virtual
joystick (wall time) where /dev/uinput exists."""

from __future__ import annotations

import dataclasses
import os
import re
import sys
import time

import pytest
from motion_helpers import JOG_CONFIG, stepped_session

from sherpa_cli.bus.session import ArmSession
from sherpa_cli.config import load_config
from sherpa_cli.config.model import JoystickMap
from sherpa_cli.errors import ConfigError, UsageError
from sherpa_cli.ops import joystick
from sherpa_cli.ops.joystick import ScriptedSource, deadzone, run_joystick
from sherpa_cli.ops.live_jog import LiveJog, resolve_axes
from sherpa_cli.sim.arm import SimArm

CONFIG = JOG_CONFIG
JOY = """
joystick:
  rate_hz: 25
  deadzone: 0.1
  deadman: BTN_TRIGGER
  axes:
    - {axis: ABS_Z, joint: j1, sensitivity: 0.25}
    - {pair: diff, x: ABS_X, y: ABS_Y, mix: xy, sensitivity: 0.25}
"""


@pytest.fixture
def cfg(tmp_path):
    p = tmp_path / "arm.yaml"
    p.write_text(CONFIG.read_text() + JOY)
    return load_config(p)


def px(session, drive):
    with session.sim.lock:
        return session.sim.drives[drive].motor.counts


def motors_on(session):
    with session.sim.lock:
        return {name for name, d in session.sim.drives.items() if d.motor_on}


def drive(cfg, session, stepped, script, duration, jcfg=None):
    jcfg = jcfg or cfg.joystick
    axes = resolve_axes(cfg, joystick.joints_of(cfg, jcfg))
    with LiveJog(session, axes, keepalive=0.3, clock=stepped.now, sleep=stepped.sleep) as live:
        src = ScriptedSource(script, stepped.now)
        run = run_joystick(live, cfg, jcfg, src, clock=stepped.now, sleep=stepped.sleep, duration=duration)
    return run, live


def test_deadzone_rescales_and_holds_zero():
    assert deadzone(0.05, 0.1) == 0.0 and deadzone(1.0, 0.1) == 1.0 and deadzone(-0.55, 0.1) == pytest.approx(-0.5)


def test_deflection_moves_the_mapped_joint_only_while_the_deadman_is_held(cfg):
    with stepped_session(cfg) as (s, stepped):
        script = [(0.0, "ABS_Z", 1.0),           # deflected, dead-man not held: nothing moves
                  (0.4, "BTN_TRIGGER", 1.0),     # held: j1 runs at 0.25 x 8000 counts/s
                  (2.2, "BTN_TRIGGER", 0.0)]     # released: stop at once (MO=1 takes ~1 s of this)
        start = px(s, "yaw")
        run, _live = drive(cfg, s, stepped, script, 2.6)
        end = px(s, "yaw")
        assert run.releases == 1 and run.commands > 0
        assert 300 < end - start < 1.8 * 2000 + 300  # forward at 2000 counts/s for at most the 1.8 s held
        assert motors_on(s) == set()
        assert s.sim.errors == []


def test_deflection_without_the_deadman_sends_no_motion_command(cfg):
    with stepped_session(cfg) as (s, stepped):
        script = [(0.0, "ABS_Z", 1.0), (0.0, "ABS_X", 1.0), (0.0, "ABS_Y", -1.0)]  # never held
        start = {d: px(s, d) for d in ("yaw", "left", "right")}
        run, _live = drive(cfg, s, stepped, script, 0.8)
        assert run.commands == 0
        with s.sim.lock:  # the simulator's record: no motor switched on, no BG
            assert all(not d.events for d in s.sim.drives.values()), {n: d.events for n, d in s.sim.drives.items()}
        assert {d: px(s, d) for d in start} == start


def test_release_stops_before_the_keepalive_would(cfg):
    with stepped_session(cfg) as (s, stepped):
        script = [(0.0, "BTN_TRIGGER", 1.0), (0.0, "ABS_Z", -1.0), (1.5, "BTN_TRIGGER", 0.0)]
        jcfg = dataclasses.replace(cfg.joystick, axes=cfg.joystick.axes[:1])
        axes = resolve_axes(cfg, ["j1"])
        with LiveJog(s, axes, keepalive=5.0, clock=stepped.now, sleep=stepped.sleep) as live:  # only the release can stop it in time
            src = ScriptedSource(script, stepped.now)
            run_joystick(live, cfg, jcfg, src, clock=stepped.now, sleep=stepped.sleep, duration=1.55)
            assert live.running == {}
            a = px(s, "yaw")
            stepped.sleep(0.3)
            b = px(s, "yaw")
            assert a < -100 and abs(b - a) < 150  # moved backwards, then stopped (decelerating only)
        assert motors_on(s) == set()


@pytest.mark.parametrize("x, y, moved, held", [(0.6, 0.0, "pitch", "roll"), (0.0, 0.6, "roll", "pitch")])
def test_xy_plus_and_minus_drive_the_right_motors_of_the_pair(cfg, x, y, moved, held):
    with stepped_session(cfg) as (s, stepped):
        a0, b0 = px(s, "left"), px(s, "right")
        script = [(0.0, "BTN_TRIGGER", 1.0), (0.0, "ABS_X", x), (0.0, "ABS_Y", y), (3.0, "BTN_TRIGGER", 0.0)]
        run, _live = drive(cfg, s, stepped, script, 3.3)  # MO=1 of two drives takes ~2 s of it
        da, db = px(s, "left") - a0, px(s, "right") - b0
        assert da > 100, run.messages  # X+Y > 0 drives motor a forward
        if moved == "pitch":  # X only: X+Y = X-Y, both motors the same way, Δ holds
            assert db > 100 and abs(da - db) < 0.15 * da
        else:  # Y only: X-Y < 0, motor b backwards, Σ holds
            assert db < -100 and abs(da + db) < 0.15 * da
        assert motors_on(s) == set()


def test_limits_hold_under_full_deflection(cfg):
    jcfg = dataclasses.replace(cfg.joystick, axes=(JoystickMap(joint="j1", axis="ABS_Z", sensitivity=1.0),))
    with stepped_session(cfg) as (s, stepped):
        script = [(0.0, "BTN_TRIGGER", 1.0), (0.0, "ABS_Z", 1.0)]
        run, _live = drive(cfg, s, stepped, script, 2.5, jcfg)
        j1 = cfg.joints["j1"]
        assert px(s, "yaw") <= j1.full_range[1]
        assert any("edge of its normal range" in m or m.startswith("limit:") for m in run.messages)
        assert motors_on(s) == set()


def test_joystick_config_errors_name_file_and_line(tmp_path):
    p = tmp_path / "arm.yaml"
    p.write_text(CONFIG.read_text() + JOY.replace("rate_hz: 25", "rate_hz: 100"))
    with pytest.raises(ConfigError, match=r"arm.yaml:\d+: joystick.rate_hz: rate_hz 100 must be 20..50"):
        load_config(p)
    p.write_text(CONFIG.read_text() + JOY.replace("mix: xy", "mix: sum"))
    with pytest.raises(ConfigError, match=r"arm.yaml:\d+: joystick.axes\[1\].mix: mix 'sum'"):
        load_config(p)
    p.write_text(CONFIG.read_text() + JOY.replace("x: ABS_X", "x: ABS_Z"))
    with pytest.raises(ConfigError, match=r"x 'ABS_Z' is already used by joystick map 1"):
        load_config(p)


def test_missing_evdev_is_a_clear_message(monkeypatch):
    monkeypatch.setitem(sys.modules, "evdev", None)
    monkeypatch.setattr(sys, "platform", "linux")
    with pytest.raises(UsageError, match="needs the python package 'evdev'"):
        joystick.EvdevSource("/dev/input/event0")
    monkeypatch.setattr(sys, "platform", "win32")
    with pytest.raises(UsageError, match="needs Linux"):
        joystick.list_joysticks()


@pytest.mark.skipif(not os.access("/dev/uinput", os.W_OK), reason="no writable /dev/uinput on this machine")
def test_a_real_uinput_virtual_joystick_drives_the_joint(cfg):  # pragma: no cover - needs /dev/uinput
    evdev = pytest.importorskip("evdev")
    e = evdev.ecodes
    caps = {e.EV_KEY: [e.BTN_TRIGGER],
            e.EV_ABS: [(e.ABS_Z, evdev.AbsInfo(0, -512, 511, 0, 0, 0))]}
    with evdev.UInput(caps, name="sherpa-test-joystick") as ui:
        time.sleep(0.3)
        path = next(j.path for j in joystick.list_joysticks() if j.name == "sherpa-test-joystick")
        src = joystick.EvdevSource(path)
        with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:  # a real device: wall time
            jcfg = dataclasses.replace(cfg.joystick, axes=cfg.joystick.axes[:1])
            start = px(s, "yaw")
            with LiveJog(s, resolve_axes(cfg, ["j1"]), keepalive=0.3) as live:
                ui.write(e.EV_KEY, e.BTN_TRIGGER, 1)
                ui.write(e.EV_ABS, e.ABS_Z, 511)
                ui.syn()
                run_joystick(live, cfg, jcfg, src, duration=0.5)
            assert px(s, "yaw") - start > 100
            assert motors_on(s) == set()


def test_the_joystick_section_survives_config_convert(cfg, tmp_path):
    from sherpa_cli.config.dump import dump_native

    p = tmp_path / "converted.yaml"
    p.write_text(dump_native(cfg))
    assert load_config(p).joystick == cfg.joystick


def _held_then(cfg, s, stepped, duration, **scripted):
    """j1 driven backwards with the dead-man held from 0 s; ``scripted``: what else the device does."""
    script = [(0.0, "BTN_TRIGGER", 1.0), (0.0, "ABS_Z", -1.0), *scripted.pop("script", [])]
    jcfg = dataclasses.replace(cfg.joystick, axes=cfg.joystick.axes[:1])
    with LiveJog(s, resolve_axes(cfg, ["j1"]), keepalive=5.0, clock=stepped.now,
                 sleep=stepped.sleep) as live:  # only the dead-man can stop in time
        src = ScriptedSource(script, stepped.now, **scripted)
        run = run_joystick(live, cfg, jcfg, src, clock=stepped.now, sleep=stepped.sleep, duration=duration)
        running = dict(live.running)
        a = px(s, "yaw")
        stepped.sleep(0.3)
        b = px(s, "yaw")
    return run, running, a, b


def test_a_lost_release_event_still_stops_by_the_devices_key_state(cfg):
    """Review R11: the release event is lost (the evdev buffer overflowed while the loop stalled):
    every period the device's own key state is asked, and the dead-man is up."""
    with stepped_session(cfg) as (s, stepped):
        run, running, a, b = _held_then(cfg, s, stepped, 2.4, lost=[(1.8, "BTN_TRIGGER", 0.0)])
        assert run.releases == 1 and running == {}
        assert a < -100 and abs(b - a) < 150  # moved backwards, then stopped
        assert motors_on(s) == set()


def test_a_failed_key_state_query_counts_as_released(cfg):
    with stepped_session(cfg) as (s, stepped):
        run, running, a, b = _held_then(cfg, s, stepped, 2.4, keys_fail_at=1.8)
        assert run.releases == 1 and running == {}
        assert a < -100 and abs(b - a) < 150
        assert motors_on(s) == set()


def test_syn_dropped_forgets_the_stale_axis_values(cfg):
    """Review R11: after SYN_DROPPED the axis values read before are stale (the stick's return to
    centre was among the lost events): nothing runs on them; the dead-man state is read again."""
    with stepped_session(cfg) as (s, stepped):
        run, running, a, b = _held_then(cfg, s, stepped, 2.4, script=[(1.8, "SYN_DROPPED", 1.0)],
                                        lost=[(1.8, "ABS_Z", 0.0)])
        assert run.releases == 0 and running == {}  # still held: stopped by the centred stick
        assert a < -100 and abs(b - a) < 150
        assert motors_on(s) == set()


class _FakeDevice:
    """An evdev.InputDevice stand-in: the real ecodes, scripted events and key state."""

    def __init__(self, path, keys=(288,)):
        evdev = pytest.importorskip("evdev")
        e = evdev.ecodes
        self.path, self.name, self.e = path, "fake stick", e
        self.keys = list(keys)
        self.events: list = []
        self.held: list[int] = []
        self.fail = False
        self.closed = False
        self.info = evdev.AbsInfo(0, -512, 511, 0, 0, 0)

    def capabilities(self):
        return {self.e.EV_ABS: [(self.e.ABS_Z, self.info)], self.e.EV_KEY: self.keys}

    def read(self):
        if not self.events:
            raise BlockingIOError
        out, self.events = self.events, []
        return out

    def active_keys(self):
        if self.fail:
            raise OSError(19, "No such device")
        return list(self.held)

    def close(self):
        self.closed = True


@pytest.fixture
def fake_evdev(monkeypatch):
    evdev = pytest.importorskip("evdev")
    made = {}

    def open_device(path):
        made["dev"] = _FakeDevice(path, made.get("keys", (evdev.ecodes.BTN_TRIGGER,)))
        return made["dev"]
    monkeypatch.setattr(sys, "platform", "linux")
    monkeypatch.setattr(evdev, "InputDevice", open_device)
    return evdev, made


def _ev(evdev, type_, code, value):
    return evdev.InputEvent(0, 0, type_, code, value)


def test_an_aliased_deadman_name_is_reported_under_the_configs_name(fake_evdev):
    """Review note: evdev knows 0x120 as BTN_JOYSTICK and BTN_TRIGGER; a dead-man named BTN_TRIGGER
    must engage (it came out as the first alias and never matched)."""
    evdev, made = fake_evdev
    e = evdev.ecodes
    src = joystick.EvdevSource("/dev/input/event7", "BTN_TRIGGER")
    made["dev"].events = [_ev(evdev, e.EV_KEY, e.BTN_TRIGGER, 1), _ev(evdev, e.EV_SYN, e.SYN_REPORT, 0)]
    assert src.read() == [joystick.JoyEvent("BTN_TRIGGER", 1.0)]
    made["dev"].held = [e.BTN_TRIGGER]
    assert "BTN_TRIGGER" in src.active_keys() and "BTN_JOYSTICK" in src.active_keys()
    made["dev"].fail = True
    with pytest.raises(OSError):
        src.active_keys()


@pytest.mark.parametrize("name, says", [("BTN_TRIGGR", "'BTN_TRIGGR' is not an evdev button name"),
                                        ("ABS_X", "'ABS_X' is not an evdev button name"),
                                        ("BTN_THUMB", "has no button BTN_THUMB (its buttons: BTN_JOYSTICK/BTN_TRIGGER)")])
def test_a_deadman_the_device_cannot_report_is_refused_at_start(fake_evdev, name, says):
    with pytest.raises(UsageError, match=re.escape("arm.yaml: joystick.deadman: ") + ".*" + re.escape(says)):
        joystick.EvdevSource("/dev/input/event7", name, where="arm.yaml: joystick.deadman")


def test_syn_dropped_is_reported_and_the_broken_report_skipped(fake_evdev):
    evdev, made = fake_evdev
    e = evdev.ecodes
    src = joystick.EvdevSource("/dev/input/event7", "BTN_TRIGGER")
    made["dev"].events = [_ev(evdev, e.EV_ABS, e.ABS_Z, 511), _ev(evdev, e.EV_SYN, e.SYN_DROPPED, 0),
                          _ev(evdev, e.EV_KEY, e.BTN_TRIGGER, 1), _ev(evdev, e.EV_SYN, e.SYN_REPORT, 0),
                          _ev(evdev, e.EV_ABS, e.ABS_Z, -512)]
    assert src.read() == [joystick.JoyEvent("ABS_Z", 1.0), joystick.JoyEvent("SYN_DROPPED", 1.0),
                          joystick.JoyEvent("ABS_Z", -1.0)]


def test_an_unknown_deadman_name_ends_the_command_with_exit_2(cli, fake_evdev, tmp_path):
    p = tmp_path / "arm.yaml"
    p.write_text(CONFIG.read_text() + JOY.replace("deadman: BTN_TRIGGER", "deadman: BTN_TRIGGR"))
    result = cli("--config", str(p), "--sim", "jog", "--joystick", "--device", "/dev/input/event7", "--apply")
    assert result.exit_code == 2, result.transcript()
    assert "Traceback" not in result.stderr
    assert f"error: {p}: joystick.deadman: 'BTN_TRIGGR' is not an evdev button name" in result.stderr
