"""`sherpa move --trajectory` and `Arm.play` on the simulated arm, on stepped time: a path streamed as
Elmo PVT in one motion guard, every joint watched (tests/data/move-arm.yaml: j1 on can1, j2 and the
Σ/Δ pair pitch/roll on can0). What stops every joint -- a breach, a joint that cannot follow, Ctrl-C --
stops it from standstill, and what the stream changed is put back."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest
from motion_helpers import motors_off, stepped_session

from sherpa_cli.api import Arm
from sherpa_cli.bus import journal
from sherpa_cli.bus.targets import drive_ref
from sherpa_cli.config import load_config
from sherpa_cli.errors import SafetyError, UsageError
from sherpa_cli.joints.trajectory import Trajectory
from sherpa_cli.sim.drive import UNGUARDED_MO

DATA = Path(__file__).resolve().parent / "data"
CONFIG = DATA / "move-arm.yaml"


@pytest.fixture
def arm() -> Any:
    cfg = load_config(CONFIG)
    with stepped_session(cfg) as (session, st):
        events: list[tuple[str, str, float]] = []  # drive, text, its motor's speed at that instant
        for name, d in session.sim.drives.items():
            nxt = d.on_event

            def seen(drive: Any, t: float, text: str, _name: str = name, _next: Any = nxt) -> None:
                events.append((_name, text, drive.motor.v))
                if _next is not None:
                    _next(drive, t, text)
            d.on_event = seen
        yield Arm(session), st, events


def _path(a: Arm, moves: dict[str, float], seconds: float = 2.0) -> Trajectory:
    """From where the joints stand, each by ``moves[joint]`` counts along a cosine (at rest at both ends)."""
    now = {j.name: j.position_counts for j in a.state()}
    times = [k * 0.05 for k in range(int(seconds / 0.05) + 1)]
    shape = [0.5 - 0.5 * math.cos(math.pi * t / seconds) for t in times]
    return Trajectory(tuple(moves), tuple(times), tuple(tuple(now[j] + d * s for s in shape) for j, d in moves.items()))


def _stopped_still(events: list[tuple[str, str, float]], standstill: int) -> None:
    offs = [(d, v) for d, text, v in events if text == "motor off: MO=0"]
    assert offs, "no motor was switched off"
    assert all(abs(v) <= standstill for _d, v in offs), offs
    assert not [e for e in events if e[1].startswith(UNGUARDED_MO) or e[1].startswith("heartbeat lost")], events


def test_a_path_of_a_plain_joint_and_a_pair_plays_within_the_tracking_bound_and_ends_on_its_end(arm, caplog):
    a, st, events = arm
    path = _path(a, {"j1": 300, "pitch": 200, "roll": -100})
    r = a.play(path, uncalibrated=True, clock=st.now, sleep=st.sleep)
    assert r.ok and r.stream is not None and r.stream.stopped is None
    assert r.stream.on_time_pct == 100.0 and r.stream.periods >= 200
    assert set(r.tracking) == {"j1", "pitch", "roll"}
    assert max(r.tracking.values()) <= 3 <= a.config.motion.tracking_bound, r.tracking
    assert all(abs(r.end[j] - r.target[j]) <= 1 for j in r.target), (r.end, r.target)
    assert motors_off(a.session)
    _stopped_still(events, a.config.motion.standstill_velocity)
    for d in ("yaw", "left", "right"):
        assert not journal.leftover(drive_ref(a.config, d))
    # the queue draining at the end is the stream's normal end: the streamer answers it, nobody warns
    assert "PVT queue low" not in caplog.text, caplog.text


@pytest.mark.parametrize("way", ["breach", "tracking", "ctrl_c"])
def test_a_breach_a_joint_that_cannot_follow_or_ctrl_c_stops_every_joint_from_standstill(arm, way):
    a, st, events = arm
    sim, sleep = a.session.sim, st.sleep
    path = _path(a, {"j1": 300, "j2": -300}, seconds=3.0)
    t_on: list[float] = []
    done: list[bool] = []

    def wrapped(s: float) -> None:
        sleep(s)
        if not t_on and any(text.startswith("motor on") for _d, text, _v in events):
            t_on.append(st.now())
        if done or not t_on or st.now() - t_on[0] < 1.0:  # well into the stream
            return
        done.append(True)
        # the PVT table drives the simulated motor itself: what the drive reports (PX) is moved instead
        with sim.lock:
            d = sim.drives["elbow"]
            if way == "breach":
                d._px_offset += -1800 - 10 - d.px  # past j2's full range
            elif way == "tracking":
                d._px_offset += 400  # inside its range, 400 counts off the path
        if way == "ctrl_c":
            raise KeyboardInterrupt

    expected = {"breach": (SafetyError, "every joint stopped"), "tracking": (SafetyError, "from the path"),
                "ctrl_c": (KeyboardInterrupt, None)}[way]
    with pytest.raises(expected[0], match=expected[1]):
        a.play(path, uncalibrated=True, clock=st.now, sleep=wrapped)
    assert done, "the way out was not injected"
    assert motors_off(a.session)
    _stopped_still(events, a.config.motion.standstill_velocity)
    for d in ("yaw", "elbow"):
        assert not journal.leftover(drive_ref(a.config, d))


def test_a_path_that_does_not_start_where_the_arm_stands_is_refused_with_nothing_switched_on(arm):
    a, st, events = arm
    path = _path(a, {"j1": 300})
    moved = Trajectory(path.joints, path.times, tuple(tuple(x + 50 for x in s) for s in path.positions))
    with pytest.raises(UsageError, match="starts \\+50 counts from where j1 stands"):
        a.play(moved, uncalibrated=True, clock=st.now, sleep=st.sleep)
    assert not [e for e in events if e[1].startswith("motor on")]


def test_a_path_that_ends_moving_is_refused(arm):
    a, st, _events = arm
    now = {j.name: j.position_counts for j in a.state()}
    times = tuple(k * 0.05 for k in range(21))
    ramp = Trajectory(("j1",), times, (tuple(now["j1"] + 600 * t for t in times),))  # 600 counts/s throughout
    with pytest.raises(UsageError, match=r"(still moves at its end|would accelerate)"):
        a.play(ramp, uncalibrated=True, clock=st.now, sleep=st.sleep)


def test_the_dry_run_says_what_would_play(cli, golden):
    result = cli("--config", str(CONFIG), "--sim", "move", "--trajectory", str(DATA / "move-path.csv"),
                 "--uncalibrated")
    assert result.exit_code == 0, result.transcript()
    golden("move/trajectory-dry-run.txt", result.transcript().replace(str(DATA), "DATA"))


@pytest.mark.parametrize(("argv", "said"), [
    (["move", "ready", "--trajectory", "x.csv"], "name a POSE or give --trajectory FILE"),
    (["move"], "name a POSE or give --trajectory FILE"),
    (["move", "--trajectory", "x.csv", "--joints", "j1"], "a trajectory is played as it is"),
    (["move", "--trajectory", "missing.csv"], "missing.csv: no such file"),
])
def test_bad_trajectory_arguments_are_one_line_before_the_bus(cli, argv, said):
    result = cli("--config", str(CONFIG), *argv)
    assert result.exit_code == 2 and said in result.stderr and "Traceback" not in result.stderr, result.transcript()
