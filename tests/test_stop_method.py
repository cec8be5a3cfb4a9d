"""motion.stop_method everywhere: the jogs' own stops (motion/recovery.stop_now: the pair/`jog` limit
stop and end of a velocity/torque jog; ops/live_jog: `s`, Space, expiry, the limit watch) go the
guard's one stop path (motion/stopping.send_stop), so `st`, `jv0` and `auto` show in the frames each
simulated drive received: `st` ST only, `jv0` JV=0 + BG (no ST), `auto` ST, and JV=0 + BG where the
firmware refuses ST in speed mode (UM=2)."""

from __future__ import annotations

import dataclasses
import time

import pytest
from motion_helpers import JOG_CONFIG, motors_off

from sherpa_cli.bus.session import ArmSession
from sherpa_cli.config import load_config
from sherpa_cli.config.model import SimDriveConfig
from sherpa_cli.errors import SafetyError
from sherpa_cli.motion.axis import resolve_axis
from sherpa_cli.motion.request import parse_request
from sherpa_cli.ops import joint_jog
from sherpa_cli.ops.live_jog import LiveJog, resolve_axes
from sherpa_cli.sim.arm import SimArm

MOTION = {b"ST", b"BG"}


def with_motion(cfg, *, refuse_st: tuple[str, ...] = (), **motion):
    cfg = dataclasses.replace(cfg, motion=dataclasses.replace(cfg.motion, **motion))
    if refuse_st:
        cfg = dataclasses.replace(cfg, sim={d: SimDriveConfig(st_refused_in_speed_mode=True) for d in refuse_st})
    return cfg


def commands(session, drive: str, since: int = 0) -> list[str]:
    """The motion commands the drive received (from frame ``since``): ST, BG, JV=n, TC=x."""
    d = session.sim.drives[drive]
    out = []
    with session.sim.lock:
        frames = list(d.received)[since:]
    for _, cid, data in frames:
        if not 0x300 < cid < 0x380:
            continue
        data = bytes(data)
        if len(data) == 4 and data[:2] in MOTION:
            out.append(data[:2].decode())
        elif len(data) == 8 and data[:2] == b"JV":
            out.append(f"JV={int.from_bytes(data[4:], 'little', signed=True)}")
        elif len(data) == 8 and data[:2] == b"TC":
            out.append("TC")
    return out


def received(session, drive: str) -> int:
    with session.sim.lock:
        return len(session.sim.drives[drive].received)


# -- the live jog (the interactive view and the joystick) -------------------------------------------

@pytest.mark.parametrize("method, refuse, um, expected", [
    ("st", False, 5, ["ST"]),
    ("jv0", False, 5, ["JV=0", "BG"]),
    ("auto", False, 5, ["ST"]),
    ("auto", True, 2, ["ST", "JV=0", "BG"]),  # ST refused in speed mode: JV=0 + BG
])
def test_live_jog_stop_uses_the_configured_stop_method(method, refuse, um, expected):
    cfg = with_motion(load_config(JOG_CONFIG), refuse_st=("yaw",) if refuse else (), stop_method=method,
                      velocity_unit_mode=um)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        with LiveJog(s, resolve_axes(cfg, ["j1"]), keepalive=30.0) as live:
            live.set_velocity("j1", 1000)
            for _ in range(5):
                live.tick()
                time.sleep(0.03)
            mark = received(s, "yaw")
            live.stop("j1")
            assert commands(s, "yaw", mark) == expected
            assert "j1" not in live.running
            mark = received(s, "yaw")
            live.stop_all()  # Space: every drive the session commanded, by the same method
            assert commands(s, "yaw", mark) == expected
        assert motors_off(s) and s.sim.errors == []


def test_live_jog_st_method_on_firmware_that_refuses_st_says_so():
    cfg = with_motion(load_config(JOG_CONFIG), refuse_st=("yaw",), stop_method="st", velocity_unit_mode=2)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        with pytest.raises(SafetyError), LiveJog(s, resolve_axes(cfg, ["j1"]), keepalive=30.0) as live:
            live.set_velocity("j1", 1000)
            live.tick()
            with pytest.raises(SafetyError, match=r"yaw.*ST refused"):
                live.stop("j1")
            raise SafetyError("leave")  # the guard's exit: ST refused again, the motor switched off
        assert motors_off(s)


def test_live_jog_expiry_stops_with_the_configured_method():
    cfg = with_motion(load_config(JOG_CONFIG), stop_method="jv0")
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        with LiveJog(s, resolve_axes(cfg, ["j1"]), keepalive=0.2) as live:
            live.set_velocity("j1", 1000)
            mark = received(s, "yaw")
            deadline = time.monotonic() + 5
            while "j1" in live.running:
                assert time.monotonic() < deadline
                live.tick()
                time.sleep(0.03)
            assert commands(s, "yaw", mark) == ["JV=0", "BG"]
        assert motors_off(s)


# -- `sherpa jog` of a pair joint (ops/joint_jog.py: stop_now at the end of a velocity jog) ----------

@pytest.mark.parametrize("method, stop", [("st", "ST"), ("jv0", "JV=0")])
def test_pair_velocity_jog_ends_with_the_configured_stop_method(method, stop):
    cfg = with_motion(load_config(JOG_CONFIG), stop_method=method)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        r = joint_jog.run(s, resolve_axis(cfg, "pitch"), parse_request(resolve_axis(cfg, "pitch"), mode="velocity", velocity="2000counts",
                                                                    duration=0.2))
        assert r.ok
        for drive in ("left", "right"):
            got = commands(s, drive)
            after = got[got.index("JV=1000") + 1:]
            # the jog's own stop (stop_now), then the guard's exit stops: all by the method (the BGs
            # between are the start, the held joint's correction and JV=0's own BG)
            stops = [c for c in after if c != "BG"]
            assert len(stops) >= 2 and set(stops) == {stop}, (drive, got)
        assert motors_off(s) and s.sim.errors == []
