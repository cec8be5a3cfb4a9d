"""Jogging on the simulated arm (in-process, python-can virtual): the Σ and Δ joints of a pair
(ops/joint_jog.py) and a plain joint (ops/jog.py), in position, velocity and torque mode, with the
joint-limit watch.

Real time, like tests/test_motion_guard.py: the guard's dead-man heartbeat runs on a thread in
wall-clock time, so the simulated drives must too (a fake clock running ahead would trip their
heartbeat consumers). The config below keeps every motion short (fast joints, 50 ms MO settle).
"""

from __future__ import annotations

import pytest
from motion_helpers import JOG_CONFIG, calibrate, motors_off

from sherpa_cli.bus.session import ArmSession
from sherpa_cli.config import load_config
from sherpa_cli.errors import SafetyError, UsageError
from sherpa_cli.motion.axis import resolve_axis
from sherpa_cli.motion.request import parse_request
from sherpa_cli.ops import joint_jog
from sherpa_cli.sim.arm import SimArm

CONFIG = JOG_CONFIG


@pytest.fixture
def cfg():
    return load_config(CONFIG)


def jog(session, name, **kw):
    axis = resolve_axis(session.cfg, name)
    return joint_jog.run(session, axis, parse_request(axis, **kw))


@pytest.mark.parametrize("name, to, other", [("pitch", "1000counts", "roll"), ("roll", "-601counts", "pitch"),
                                             ("pitch", "-1201counts", "roll")])
def test_position_jog_of_a_pair_joint_ends_where_asked_and_the_other_holds(cfg, name, to, other):
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        calibrate(s, "left", "right")
        r = jog(s, name, mode="position", to=to)
        target = int(to.removesuffix("counts"))
        assert r.ok and r.outcome == "done"
        assert abs(r.joints_end[name] - target) <= 1 and r.end_counts == r.joints_end[name]
        assert abs(r.joints_end[other] - r.joints_start[other]) <= 1
        assert motors_off(s)
        assert s.sim.errors == []


def test_position_jog_of_a_pair_joint_with_by_and_degrees(cfg):
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        calibrate(s, "left", "right")
        first = jog(s, "roll", mode="position", to="300counts")
        second = jog(s, "pitch", mode="position", by="30deg")  # 30° of cpr 6000 = 500 counts
        assert abs(second.joints_end["pitch"] - 500) <= 1
        assert abs(second.joints_end["roll"] - first.joints_end["roll"]) <= 1
        assert second.motor_commands["left"]["SP"] == second.motor_commands["right"]["SP"]


@pytest.mark.parametrize("name, velocity, other, sign", [("pitch", "3000counts", "roll", 1),
                                                         ("roll", "-2000counts/s", "pitch", -1)])
def test_velocity_jog_of_a_pair_joint_moves_only_that_joint(cfg, name, velocity, other, sign):
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        r = jog(s, name, mode="velocity", velocity=velocity, duration=0.2)
        assert r.ok
        assert sign * r.joints_end[name] > 200  # moved the asked way
        assert abs(r.joints_end[other] - r.joints_start[other]) <= 1
        speeds = [c["JV"] for c in r.motor_commands.values()]
        assert (speeds == [1500, 1500]) if name == "pitch" else (speeds == [-1000, 1000])


@pytest.mark.parametrize("name, other", [("pitch", "roll"), ("roll", "pitch")])
def test_torque_jog_of_a_pair_joint_moves_only_that_joint(cfg, name, other):
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        r = jog(s, name, mode="torque", torque="0.2A", duration=0.2)
        assert r.ok and r.joints_end[name] > 20
        assert abs(r.joints_end[other] - r.joints_start[other]) <= 1
        currents = [c["TC"] for c in r.motor_commands.values()]
        assert currents == ([0.2, 0.2] if name == "pitch" else [0.2, -0.2])


@pytest.mark.parametrize("name, mode, kw", [
    ("pitch", "velocity", {"velocity": "6000counts"}),
    ("roll", "velocity", {"velocity": "-6000counts"}),
    ("pitch", "torque", {"torque": "2A"}),
    ("roll", "torque", {"torque": "-2A"}),
])
def test_leaving_the_full_range_stops_and_comes_back_to_the_normal_range(cfg, name, mode, kw):
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
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
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        with pytest.raises(UsageError, match="needs --for"):
            jog(s, "pitch", mode="torque", torque="1A")
        with s.sim.lock:
            assert all(d.od_writes == [] for d in s.sim.drives.values())


def test_refusals_outside_the_normal_range_and_uncalibrated(cfg):
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        with pytest.raises(UsageError, match=r"target 2850 counts is outside the joint's normal range \[-2800, 2800\]"):
            jog(s, "pitch", mode="position", to="2850counts")
        with pytest.raises(SafetyError, match=r"not homed since power-up \(left UI\[3\]=0, right UI\[3\]=0\)"):
            jog(s, "roll", mode="position", to="10counts")
        r = jog(s, "roll", mode="position", to="10counts", uncalibrated=True)
        assert r.ok and abs(r.end_counts - 10) <= 1
        with pytest.raises(UsageError, match=r"above the joint.s speed limit \d\.\d{4} rad/s \(8000 counts/s\)"):
            jog(s, "pitch", mode="velocity", velocity="9000counts", duration=0.1)
        with pytest.raises(UsageError, match="above the configured continuous limit 3 A"):
            jog(s, "roll", mode="torque", torque="3.5", duration=0.1)


def test_a_pair_motor_alone_is_checked_in_joint_space(cfg):
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        calibrate(s, "left", "right")
        # right alone to 1950: Σ 1950 is fine, Δ -1950 is past roll's normal edge -1900
        with pytest.raises(UsageError, match=r"puts joint roll at -1950 counts, outside its normal range"):
            jog(s, "right", mode="position", to="1950counts")
        r = jog(s, "right", mode="position", to="400counts")
        assert r.joints_end == {"pitch": 400, "roll": -400}


# -- the plain joint's own path (ops/jog.py, what `sherpa jog PLAIN_JOINT` runs) --------------------

@pytest.mark.parametrize("req", [dict(mode="velocity", velocity=9.0, duration=3.0),  # 5730 counts/s
                                 dict(mode="velocity", velocity=-9.0),  # open-ended: the watch ends it
                                 dict(mode="torque", torque=1.5, duration=3.0)])
def test_plain_jog_past_the_full_range_is_stopped_and_brought_back(cfg, req):
    from sherpa_cli.motion.settings import MotionSettings
    from sherpa_cli.ops.jog import run_jog

    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        r = run_jog(s, resolve_axis(cfg, "j1"), parse_request(resolve_axis(cfg, "j1"), **req), settings=MotionSettings.from_config(cfg))
        (b,) = r.breaches  # a plain jog stops at its first
        assert b.joint == "j1" and not r.ok
        edge = 1900 if b.side == "high" else -1900
        assert b.back_to == edge and r.recovered_to == {"j1": edge} and r.end_counts == edge
        assert r.ended_by == f"left its full range, brought back to {edge} counts"
        assert r.as_json()["ok"] is False and r.as_json()["limit"]["recovered_to"] == edge
        assert motors_off(s)


def test_plain_position_refusals_before_anything_is_armed(cfg):
    from sherpa_cli.motion.settings import MotionSettings
    from sherpa_cli.ops.jog import run_jog

    settings = MotionSettings.from_config(cfg)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        target = resolve_axis(cfg, "j1")
        with pytest.raises(UsageError, match=r"target 7540 counts is outside the joint's normal range \[-1900, 1900\]"):
            run_jog(s, target, parse_request(target, mode="position", to=11.844), settings=settings)
        with pytest.raises(SafetyError, match=r"not homed since power-up \(yaw UI\[3\]=0\)"):
            run_jog(s, target, parse_request(target, mode="position", to=0.5), settings=settings)
        with s.sim.lock:
            assert all(d.od_writes == [] for d in s.sim.drives.values())  # the dead-man was never armed
        calibrate(s, "yaw")
        r = run_jog(s, target, parse_request(target, mode="position", to=0.5), settings=settings)
        (cal,) = r.calibrations
        assert cal.calibrated and abs(r.end_counts - 318) <= 1


def test_a_motor_that_trips_during_a_pair_jog_ends_it_with_the_reason(cfg):
    import threading
    import time

    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        left = s.sim.drives["left"]

        def trip() -> None:
            deadline = time.monotonic() + 10
            while abs(left.position) < 50 and time.monotonic() < deadline:  # the jog is under way
                time.sleep(0.005)
            with s.sim.lock:
                left._shut_down(0x400000, "test trip")  # as past LL[3]/HL[3]

        t = threading.Thread(target=trip)
        t.start()
        with pytest.raises(SafetyError, match=r"left \(node 10\): the motor was switched off during the jog: "
                                              r"position limit") as info:
            jog(s, "pitch", mode="velocity", velocity="1000counts", duration=3.0)
        t.join()
        report = info.value.motion_report
        assert report.reason == "error" and len(report.drives) == 2
        assert motors_off(s)


def test_what_a_pair_jog_takes(cfg):
    # one resolver for every axis (motion/axis.py): a plain joint is an axis too
    assert [resolve_axis(cfg, name).kind for name in ("j1", "yaw")] == ["plain", "plain"]
    with pytest.raises(UsageError, match="is a differential pair: name the joint to move"):
        resolve_axis(cfg, "diff")
    with pytest.raises(UsageError, match="unknown target 'pich'"):
        resolve_axis(cfg, "pich")
    assert (resolve_axis(cfg, "can0:11").kind, resolve_axis(cfg, "can0:11").drives) == ("motor", ("right",))
    assert resolve_axis(cfg, "roll").kind == "delta"


def test_progress_reports_both_pair_joints(cfg):
    seen = []
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        joint_jog.run(s, resolve_axis(cfg, "pitch"), parse_request(resolve_axis(cfg, "pitch"), mode="velocity", velocity="2000counts",
                                                                duration=0.2), on_progress=seen.append)
    assert seen and all(set(p) == {"pitch", "roll"} for p in seen)
    assert seen[-1]["pitch"] > seen[0]["pitch"]
