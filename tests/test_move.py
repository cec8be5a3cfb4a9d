"""`sherpa move` and the motion session on the simulated arm, on stepped time (sim/stepped.py: the
simulated motors move only while the command waits, so how far they get does not depend on the host).

tests/data/move-arm.yaml: j1 on can1, j2 and the Σ/Δ pair (pitch, roll) on can0.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from motion_helpers import motors_off, stepped_session

from sherpa_cli.api import Arm
from sherpa_cli.config import load_config
from sherpa_cli.errors import SafetyError, UsageError

MOVE_CONFIG = Path(__file__).resolve().parent / "data" / "move-arm.yaml"


@pytest.fixture
def arm() -> Any:
    cfg = load_config(MOVE_CONFIG)
    with stepped_session(cfg) as (session, st):
        yield Arm(session), st


def test_a_pose_brings_every_joint_there_together(arm: Any) -> None:
    a, st = arm
    r = a.move_pose("ready", uncalibrated=True, clock=st.now, sleep=st.sleep)
    assert r.ok and set(r.joints) == {"j1", "j2", "pitch", "roll"}
    for j in r.joints.values():
        assert j.reached, j
    # the pose's values in each joint's counts (j2: -10deg of 3600 cpr); roll's -400 counts and
    # pitch's 191 differ in parity: no whole motor position has both, and roll gave way by one count
    assert r.joints["j2"].end_counts == -100 and r.joints["pitch"].end_counts == 191
    assert r.joints["roll"].end_counts == r.joints["roll"].target_counts == -399
    # started on two buses (can1: j1 alone; can0: j2 and the pair, one group start), skew measured
    assert r.start is not None and r.start.methods == {"can1": "sequential", "can0": "group"}
    assert r.start.skew_s >= 0
    # all arrive together: the arrival spread in simulated time is within 10 ms (one poll of the watch)
    spread = r.arrival_spread_s
    assert spread is not None and spread <= 0.010 + 1e-9, {n: j.time_s for n, j in r.joints.items()}
    assert motors_off(a.session)
    assert {d.drive for d in r.stop.drives} == {"yaw", "elbow", "left", "right"}


def test_the_slowest_joint_sets_the_time_and_the_others_go_slower(arm: Any) -> None:
    a, _st = arm
    prepared = a.plan_pose("reach")
    plan = prepared.plan
    j1, j2 = plan.joint("j1"), plan.joint("j2")
    assert plan.paced_by == "j1"  # 637 counts against 200, the same limit
    assert j1.limit - 2 <= j1.speed <= j1.limit and j2.speed < j1.speed
    assert j2.speed / abs(j2.distance) == pytest.approx(j1.speed / abs(j1.distance))
    assert motors_off(a.session)  # a plan moves nothing


def test_a_breach_on_one_joint_stops_every_joint(arm: Any) -> None:
    a, st = arm
    sim = a.session.sim
    pushed: dict[str, bool] = {}
    sleep = st.sleep
    t_on: list[float] = []

    def push_j2_out() -> None:
        with sim.lock:
            m = sim.drives["elbow"].motor
            m.counts += -1800 - 10 - m.counts  # 10 counts past the low end of j2's full range

    def wrapped(s: float) -> None:
        sleep(s)
        with sim.lock:
            on = sim.drives["yaw"].motor_on
        if on and not t_on:
            t_on.append(st.now())
        if t_on and not pushed and st.now() - t_on[0] >= 0.05:
            pushed["j2"] = True
            push_j2_out()

    # j2's move back starts only once every motor of the move stands: j1's speed at each BG of j2
    # after the breach (the simulated drive's events)
    elbow, yaw = sim.drives["elbow"], sim.drives["yaw"]
    at_bg: list[tuple[str, float]] = []
    nxt = elbow.on_event

    def seen(drive: Any, t: float, text: str) -> None:
        if pushed and text.startswith("BG"):
            at_bg.append((text, yaw.motor.v))
        if nxt is not None:
            nxt(drive, t, text)
    elbow.on_event = seen
    # a long move of j1 (from 0 to -1.0 rad: 637 counts) and j2
    r = a.move_pose({"j1": -1.0, "j2": "20deg"}, clock=st.now, sleep=wrapped)
    assert pushed, "the breach was not injected"
    assert not r.ok and [b.joint for b in r.breaches] == ["j2"]
    # j1, on another bus, was stopped with it: far from its target, not on its way there
    assert r.joints["j1"].end_counts > -600, r.joints["j1"]
    assert not r.joints["j1"].reached
    assert r.recovered_to["j2"] == -1764  # brought back to its normal range's edge
    assert at_bg and all(abs(v) <= 2 for _, v in at_bg), at_bg
    assert motors_off(a.session)


def test_a_fault_on_one_joint_stops_every_joint(arm: Any) -> None:
    a, st = arm
    sim = a.session.sim
    sleep = st.sleep
    t_on: list[float] = []
    tripped: list[float] = []

    def wrapped(s: float) -> None:
        sleep(s)
        with sim.lock:
            on = sim.drives["yaw"].motor_on
        if on and not t_on:
            t_on.append(st.now())
        if t_on and not tripped and st.now() - t_on[0] >= 0.05:
            tripped.append(st.now())
            with sim.lock:
                sim.drives["elbow"].trip()

    with pytest.raises(SafetyError) as exc:
        a.move_pose({"j1": -1.0, "j2": "20deg"}, clock=st.now, sleep=wrapped)
    assert "elbow" in str(exc.value)
    report = exc.value.motion_report
    assert report is not None and {d.drive for d in report.drives} == {"yaw", "elbow"}
    with sim.lock:
        yaw = sim.drives["yaw"].motor.rounded
    assert yaw > -600  # stopped on the way, not run to its target
    assert motors_off(a.session)


def test_refusals_name_what_is_wrong(arm: Any) -> None:
    a, _st = arm
    with pytest.raises(UsageError, match="pose 'redy' is not in the config; did you mean 'ready'"):
        a.move_pose("redy")
    with pytest.raises(UsageError, match="joint 'j3' is not a joint of the config"):
        a.move_pose({"j3": 0.1})
    with pytest.raises(UsageError, match="outside the joint's normal range"):
        a.move_pose({"j1": 3.0})
    with pytest.raises(UsageError, match=r"--speed-scale 1\.5"):
        a.move_pose("reach", speed_scale=1.5)
    with pytest.raises(SafetyError, match="joint pitch is not homed"):
        a.move_pose("level")
    assert motors_off(a.session)


# ------------------------------------------------------------------------------------------------
# the motion session


def test_a_session_moves_several_times_in_one_guard(arm: Any) -> None:
    a, st = arm
    events: list[str] = []
    with a.motion(["j1", "j2"], on_event=events.append, clock=st.now, sleep=st.sleep) as m:
        first = m.move_to({"j1": 0.5, "j2": 0.05})
        second = m.move_to({"j1": "-100counts"})
        here = m.positions()
    assert first.ok and first.joints["j1"].reached and first.joints["j2"].reached
    assert second.joints["j1"].end_counts == -100 and set(second.joints) == {"j1"}
    assert here["j1"] == pytest.approx(-100 * 2 * 3.141592653589793 / 4000)
    # one guard: the dead-man was armed once per drive, and the report names both drives
    assert sum("heartbeat thread" in e for e in events) == 1
    assert {d.drive for d in m.report.drives} == {"yaw", "elbow"}
    assert motors_off(a.session)


def test_a_session_of_one_joint_takes_a_value(arm: Any) -> None:
    a, st = arm
    with a.motion("j2", clock=st.now, sleep=st.sleep) as m:
        r = m.move_to(0.1)
        held = m.hold()
        m.stop()
    assert r.joints["j2"].reached
    assert held["j2"] == pytest.approx(0.1, abs=0.002)
    assert motors_off(a.session)


def test_a_session_refuses_what_it_does_not_move(arm: Any) -> None:
    a, st = arm
    with a.motion(["j1", "j2"], clock=st.now, sleep=st.sleep) as m:
        with pytest.raises(UsageError, match="give a mapping joint -> value"):
            m.move_to(0.5)
        with pytest.raises(UsageError, match="pitch is not a joint of this motion session"):
            m.move_to({"pitch": 0.1})
    with pytest.raises(UsageError, match="not open"):
        m.move_to({"j1": 0.1})
    assert motors_off(a.session)


def test_a_session_velocity_runs_for_its_time_then_stops(arm: Any) -> None:
    a, st = arm
    with a.motion(["j1", "pitch"], uncalibrated=True, clock=st.now, sleep=st.sleep) as m:
        r = m.velocity({"j1": "1000counts/s", "pitch": "-600counts/s"}, for_=0.2)
        with a.session.sim.lock:
            still = all(abs(d.motor.v) <= 2 for d in a.session.sim.drives.values())
    assert r.ok and still
    j1, pitch = r.joints["j1"], r.joints["pitch"]
    assert 150 <= j1.end_counts - j1.start_counts <= 260, j1
    assert -160 <= pitch.end_counts - pitch.start_counts <= -90, pitch
    assert motors_off(a.session)


def test_leaving_the_block_on_an_error_stops_every_motor_and_carries_the_report(arm: Any) -> None:
    a, st = arm
    with pytest.raises(RuntimeError), a.motion(["j1", "j2"], clock=st.now, sleep=st.sleep) as m:
        m.move_to({"j1": 0.2, "j2": 0.2})
        raise RuntimeError("the script failed")
    assert {d.drive for d in m.report.drives} == {"yaw", "elbow"}
    assert motors_off(a.session)


def test_the_move_command_is_a_layer_over_the_api(cli, monkeypatch):
    calls: list[tuple[str | None, bool]] = []
    real = Arm.run_pose

    def spy(self: Arm, prepared: Any, **kw: Any) -> Any:
        calls.append((prepared.pose, kw.get("hold", False)))
        return real(self, prepared, **kw)

    monkeypatch.setattr(Arm, "run_pose", spy)
    result = cli("--config", str(MOVE_CONFIG), "--sim", "move", "reach", "--apply")
    assert result.exit_code == 0, result.transcript()
    assert calls == [("reach", False)]


def test_transport_brings_all_14_joints_there_together_from_a_random_start():
    """The shipped arm: 14 joints on three buses, from a random calibrated start (one move there,
    inside every joint's normal range) to the transport pose: every joint arrives, within 10 ms of
    the others (one poll of the watch: each joint's arrival is when its motors' profiles ended), and
    no joint leaves its range on the way."""
    import random

    from motion_helpers import calibrate

    cfg = load_config(Path(__file__).resolve().parent.parent / "configs" / "sherpa-arm.yaml")
    rng = random.Random(39)
    start = {}
    for name, j in cfg.joints.items():
        lo, hi = j.normal_range
        start[name] = f"{rng.randint(lo // 2, hi // 2)}counts"
    with stepped_session(cfg) as (session, st):
        calibrate(session, *cfg.drives)
        arm = Arm(session)
        first = arm.move_pose(start, clock=st.now, sleep=st.sleep)
        assert first.ok and all(j.reached for j in first.joints.values()), first.joints
        seen: dict[str, list[int]] = {}

        def progress(joints: Any) -> None:
            for name, p in joints.items():
                seen.setdefault(name, []).append(p)
        r = arm.move_pose("transport", clock=st.now, sleep=st.sleep, on_progress=progress)
    assert r.ok and len(r.joints) == 14
    assert all(j.reached and j.end_counts == 0 for j in r.joints.values()), r.joints
    assert r.start is not None and set(r.start.methods) == {"can0", "can1", "can2"}
    spread = r.arrival_spread_s
    assert spread is not None and spread <= 0.010 + 1e-9, {n: j.time_s for n, j in r.joints.items()}
    for name, positions in seen.items():
        lo, hi = cfg.joints[name].full_range
        assert lo <= min(positions) and max(positions) <= hi, name


def test_a_pose_already_reached_switches_nothing_on(arm: Any) -> None:
    a, st = arm
    a.move_pose("reach", clock=st.now, sleep=st.sleep)
    again = a.move_pose("reach", clock=st.now, sleep=st.sleep)
    assert again.ok and all(j.reached and j.time_s == 0.0 for j in again.joints.values())
    assert again.start is None and not again.stop.drives  # no guard was armed
    assert motors_off(a.session)


def test_a_sessions_later_moves_on_a_group_started_bus_start_one_bg_after_another() -> None:
    """Two joints on one bus start by the group BG, whose id takes effect through a reset
    communication: the session's second move, its motors still on, was refused ("motor on: no NMT
    reset communication") -- a session of two moves failed on the shipped arm. It starts the motors
    one BG after another instead, the skew measured."""
    from sherpa_cli.api import Arm

    cfg = load_config(Path(__file__).resolve().parent.parent / "configs" / "sherpa-arm.yaml")
    assert cfg.motion.pair_start == "group" and cfg.motion.pair_group_reset_comm
    with stepped_session(cfg, ["can1"]) as (session, st):
        with Arm(session).motion(["elbow_pitch", "wrist_1"], clock=st.now, sleep=st.sleep) as m:
            first = m.move_to({"elbow_pitch": 0.1, "wrist_1": -0.05})
            second = m.move_to({"elbow_pitch": 0.0, "wrist_1": 0.0})
        assert first.ok and second.ok
        assert first.start is not None and first.start.methods == {"can1": "group"}
        assert second.start is not None and second.start.methods == {"can1": "sequential"}
        assert all(j.reached for j in second.joints.values())
        assert motors_off(session)
