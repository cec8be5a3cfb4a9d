"""Jogging on the simulated arm (in-process, python-can virtual): the Σ and Δ joints of a pair and a
plain joint, in position, velocity and torque mode, with the joint-limit watch.

Real time, like tests/test_motion_guard.py: the guard's dead-man heartbeat runs on a thread in
wall-clock time, so the simulated drives must too (a fake clock running ahead would trip their
heartbeat consumers). The config below keeps every motion short (fast joints, 50 ms MO settle).
"""

from __future__ import annotations

from pathlib import Path

import canopen
import pytest

from sherpa_cli.config import load_config
from sherpa_cli.errors import SafetyError, UsageError
from sherpa_cli.ops import joint_jog
from sherpa_cli.ops.joint_jog import JogRequest, resolve_axis
from sherpa_cli.ops.session import ArmSession, DriveRef

CONFIG = """\
name: jog-test
protocol: {mo_settle: 0.05, sv_blackout: 0.2}
motion: {consumer_time_ms: 300}
buses:
  can0: {interface: socketcan, channel: can0}
drives:
  yaw: {bus: can0, node: 5, model: whistle-10/60}
  left: {bus: can0, node: 10, model: whistle-20/60}
  right: {bus: can0, node: 11, model: whistle-20/60}
joints:
  j1:
    drive: yaw
    cpr: 4000
    range: {min: -2000, max: 2000, margin: 100, overshoot: 400}
    velocity: {limit: 8000, trip: 12000}
    acceleration: {accel: 40000, decel: 40000}
    current: {continuous: 2.0, peak: 6.0, peak_time: 1}
pairs:
  diff:
    drives: [left, right]
    current: {continuous: 3.0, peak: 9.0, peak_time: 1}
    sigma:
      name: pitch
      cpr: 6000
      range: {min: -3000, max: 3000, margin: 200, overshoot: 600}
      velocity: {limit: 8000, trip: 12000}
      acceleration: {accel: 40000, decel: 40000}
    delta:
      name: roll
      cpr: 6000
      range: {min: -2000, max: 2000, margin: 100, overshoot: 400}
      velocity: {limit: 8000, trip: 12000}
      acceleration: {accel: 40000, decel: 40000}
"""


@pytest.fixture(autouse=True)
def _isolated(monkeypatch: pytest.MonkeyPatch, tmp_path: Path):
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "state"))
    monkeypatch.setattr(canopen.Network, "NOTIFIER_CYCLE", 0.02)


@pytest.fixture
def cfg(tmp_path):
    path = tmp_path / "arm.yaml"
    path.write_text(CONFIG, encoding="utf-8")
    return load_config(path)


def calibrate(session, *drives):
    """What `home` leaves behind: UI[3]=1 on each drive (RAM)."""
    for name in drives:
        d = session.cfg.drives[name]
        c = session.client(DriveRef(name, d.bus, d.node, d))
        c.nmt_start()
        c.set("UI", 3, 1)


def jog(session, name, **kw):
    return joint_jog.run(session, resolve_axis(session.cfg, name), JogRequest(**kw))


def motors_off(session):
    with session.sim.lock:
        return all(not d.motor_on for d in session.sim.drives.values())


@pytest.mark.parametrize("name, to, other", [("pitch", "1000counts", "roll"), ("roll", "-601counts", "pitch"),
                                             ("pitch", "-1201counts", "roll")])
def test_position_jog_of_a_pair_joint_ends_where_asked_and_the_other_holds(cfg, name, to, other):
    with ArmSession.open(cfg, sim=True) as s:
        calibrate(s, "left", "right")
        r = jog(s, name, mode="position", to=to)
        target = int(to.removesuffix("counts"))
        assert r.ok and r.outcome == "done"
        assert abs(r.joints_end[name] - target) <= 1 and r.end == r.joints_end[name]
        assert abs(r.joints_end[other] - r.joints_start[other]) <= 1
        assert motors_off(s)
        assert s.sim.errors == []


def test_position_jog_of_a_pair_joint_with_by_and_degrees(cfg):
    with ArmSession.open(cfg, sim=True) as s:
        calibrate(s, "left", "right")
        first = jog(s, "roll", mode="position", to="300counts")
        second = jog(s, "pitch", mode="position", by="30deg")  # 30° of cpr 6000 = 500 counts
        assert abs(second.joints_end["pitch"] - 500) <= 1
        assert abs(second.joints_end["roll"] - first.joints_end["roll"]) <= 1
        assert second.motor_commands["left"]["SP"] == second.motor_commands["right"]["SP"]


@pytest.mark.parametrize("name, velocity, other, sign", [("pitch", "3000counts", "roll", 1),
                                                         ("roll", "-2000counts/s", "pitch", -1)])
def test_velocity_jog_of_a_pair_joint_moves_only_that_joint(cfg, name, velocity, other, sign):
    with ArmSession.open(cfg, sim=True) as s:
        r = jog(s, name, mode="velocity", velocity=velocity, duration=0.2)
        assert r.ok
        assert sign * r.joints_end[name] > 200  # moved the asked way
        assert abs(r.joints_end[other] - r.joints_start[other]) <= 1
        speeds = [c["JV"] for c in r.motor_commands.values()]
        assert (speeds == [1500, 1500]) if name == "pitch" else (speeds == [-1000, 1000])


@pytest.mark.parametrize("name, other", [("pitch", "roll"), ("roll", "pitch")])
def test_torque_jog_of_a_pair_joint_moves_only_that_joint(cfg, name, other):
    with ArmSession.open(cfg, sim=True) as s:
        r = jog(s, name, mode="torque", torque="0.2A", duration=0.2)
        assert r.ok and r.joints_end[name] > 20
        assert abs(r.joints_end[other] - r.joints_start[other]) <= 1
        currents = [c["TC"] for c in r.motor_commands.values()]
        assert currents == ([0.2, 0.2] if name == "pitch" else [0.2, -0.2])


@pytest.mark.parametrize("name, mode, kw", [
    ("pitch", "velocity", {"velocity": "6000counts"}),
    ("roll", "velocity", {"velocity": "-6000counts"}),
    ("pitch", "torque", {"torque": "2A"}),
    ("j1", "velocity", {"velocity": "6000counts"}),
    ("j1", "torque", {"torque": "-1.5A"}),
])
def test_leaving_the_full_range_stops_and_comes_back_to_the_normal_range(cfg, name, mode, kw):
    with ArmSession.open(cfg, sim=True) as s:
        r = jog(s, name, mode=mode, duration=3.0, **kw)
        assert not r.ok and r.outcome == "limit"
        (b,) = r.breaches
        assert b.joint == name
        j = next(j for j in resolve_axis(cfg, name).watched if j.name == name)
        assert abs(r.recovered_to[name] - b.back_to) <= 1  # the nearest normal edge
        assert b.back_to in j.normal
        for other, start in r.joints_start.items():
            if other != name:
                assert abs(r.joints_end[other] - start) <= 1
        assert motors_off(s)


def test_torque_without_for_is_refused_before_anything_moves(cfg):
    with ArmSession.open(cfg, sim=True) as s:
        with pytest.raises(UsageError, match="needs --for"):
            jog(s, "pitch", mode="torque", torque="1A")
        with s.sim.lock:
            assert all(d.od_writes == [] for d in s.sim.drives.values())


def test_refusals_outside_the_normal_range_and_uncalibrated(cfg):
    with ArmSession.open(cfg, sim=True) as s:
        with pytest.raises(SafetyError, match=r"target 2850 counts is outside the joint's normal range \[-2800, 2800\]"):
            jog(s, "pitch", mode="position", to="2850counts")
        with pytest.raises(SafetyError, match=r"not homed since power-up \(left UI\[3\]=0, right UI\[3\]=0\)"):
            jog(s, "roll", mode="position", to="10counts")
        r = jog(s, "roll", mode="position", to="10counts", uncalibrated=True)
        assert r.ok and abs(r.end - 10) <= 1
        with pytest.raises(SafetyError, match="above the joint's speed limit 8000"):
            jog(s, "pitch", mode="velocity", velocity="9000counts", duration=0.1)
        with pytest.raises(SafetyError, match="above the configured continuous limit 3 A"):
            jog(s, "roll", mode="torque", torque="3.5", duration=0.1)


def test_a_pair_motor_alone_is_checked_in_joint_space(cfg):
    with ArmSession.open(cfg, sim=True) as s:
        calibrate(s, "left", "right")
        # right alone to 1950: Σ 1950 is fine, Δ -1950 is past roll's normal edge -1900
        with pytest.raises(SafetyError, match=r"puts joint roll at -1950 counts, outside its normal range"):
            jog(s, "right", mode="position", to="1950counts")
        r = jog(s, "right", mode="position", to="400counts")
        assert r.joints_end == {"pitch": 400, "roll": -400}
