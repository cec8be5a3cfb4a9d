"""The CiA 402 drive moved by the tool's own pipeline (the drive seam), on stepped time: a pose with
a CiA 402 joint beside Elmo ones, a position jog, `stop` and `monitor`, and what the seam does not
carry refused before anything is sent. tests/data/cia402-arm.yaml: `wrist` on a cia402 drive."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from motion_helpers import motors_off, stepped_session

from sherpa_cli.api import Arm
from sherpa_cli.bus.targets import drive_ref
from sherpa_cli.config import load_config
from sherpa_cli.devices.drives import open_drive
from sherpa_cli.drive import Mode
from sherpa_cli.errors import UsageError
from sherpa_cli.motion.axis import resolve_axis
from sherpa_cli.motion.request import parse_request
from sherpa_cli.motion.settings import MotionSettings
from sherpa_cli.ops.jog import run_jog
from sherpa_cli.ops.monitor import Monitor
from sherpa_cli.ops.stop import stop_drives
from sherpa_cli.sim.cia402 import SimCia402Drive
from sherpa_cli.sim.drive import UNGUARDED_MO

CONFIG = Path(__file__).resolve().parent / "data" / "cia402-arm.yaml"


@pytest.fixture
def arm() -> Any:
    cfg = load_config(CONFIG)
    with stepped_session(cfg) as (session, st):
        events: list[tuple[str, str]] = []
        for name, d in session.sim.drives.items():
            nxt = d.on_event

            def seen(drive: Any, t: float, text: str, _name: str = name, _next: Any = nxt) -> None:
                events.append((_name, text))
                if _next is not None:
                    _next(drive, t, text)
            d.on_event = seen
        yield session, st, events


def _jog(session: Any, st: Any, name: str, **values: Any):
    axis = resolve_axis(session.cfg, name)
    mode = "position" if "to" in values or "by" in values else ("velocity" if "velocity" in values else "torque")
    req = parse_request(axis, mode, **values)
    return run_jog(session, axis, req, settings=MotionSettings.from_config(session.cfg), clock=st.now,
                   sleep=st.sleep)


def test_the_simulated_arm_plays_a_cia402_drive_for_a_cia402_drive_of_the_config(arm):
    session, _st, _ = arm
    assert isinstance(session.sim.drives["wrist"], SimCia402Drive)
    assert not isinstance(session.sim.drives["elbow"], SimCia402Drive)
    assert open_drive(session, drive_ref(session.cfg, "wrist")).kind == "cia402"
    assert open_drive(session, drive_ref(session.cfg, "elbow")).kind == "elmo"


def test_a_pose_moves_the_cia402_joint_with_the_elmo_joints_and_stops_it_from_standstill(arm):
    session, st, events = arm
    r = Arm(session).move_pose("reach", uncalibrated=True, clock=st.now, sleep=st.sleep)
    assert r.ok, r
    assert {n: j.end_counts for n, j in r.joints.items()} == {"arm": 300, "wrist": 1000, "pitch": 500}
    assert all(j.reached for j in r.joints.values())
    # the CiA 402 drive starts on its own (its set-point), the Elmo drives of the bus together
    assert r.start is not None and r.start.methods["wrist"] == "own" and r.start.methods["can0"] == "group"
    wrist = next(d for d in r.stop.drives if d.drive == "wrist")
    assert not wrist.problems and wrist.motor_off and wrist.standstill, wrist
    assert motors_off(session)
    texts = [t for n, t in events if n == "wrist"]
    assert any(t.startswith("motor on") for t in texts), texts
    assert not [t for _n, t in events if t.startswith(UNGUARDED_MO)], "a motor went on without an armed dead-man"
    # the dead-man was put back: the consumer entry is 0 again
    sdo = session.sdo(drive_ref(session.cfg, "wrist"))
    assert int.from_bytes(bytes(sdo.upload(0x1016, 1))[:4], "little") == 0


def test_a_position_jog_of_the_cia402_joint_arrives_and_leaves_it_switched_off(arm):
    session, st, events = arm
    r = _jog(session, st, "wrist", by="500counts", uncalibrated=True)
    assert r.ok and r.kind == "plain" and r.start_counts == 0
    assert r.target_counts == 500 and r.end_counts == 500 and r.ended_by == "target reached"
    (stop,) = r.stop.drives
    assert stop.drive == "wrist" and stop.motor_off and not stop.problems
    assert motors_off(session)
    assert not [t for _n, t in events if t.startswith(UNGUARDED_MO)]


def test_an_uncalibrated_cia402_joint_needs_uncalibrated_and_nothing_is_sent(arm):
    session, st, events = arm
    from sherpa_cli.errors import SafetyError

    with pytest.raises(SafetyError, match="cia402 drive"):
        _jog(session, st, "wrist", by="500counts")
    assert not [t for n, t in events if n == "wrist" and t.startswith("motor on")]


@pytest.mark.parametrize("values", [{"velocity": "100counts/s", "duration": 1.0}, {"torque": "0.1A", "duration": 1.0},
                                    {"by": "10counts", "hold": True, "uncalibrated": True}])
def test_what_the_seam_does_not_carry_is_refused_by_name_before_anything_is_sent(arm, values):
    session, st, events = arm
    with pytest.raises(UsageError, match="cia402 drive"):
        _jog(session, st, "wrist", **values)
    assert not [t for n, t in events if n == "wrist" and t.startswith("motor on")]


def test_stop_stops_a_moving_cia402_drive_from_standstill_and_switches_it_off(arm):
    session, st, _ = arm
    ref = drive_ref(session.cfg, "wrist")
    session.client(ref).nmt_start()
    drive = open_drive(session, ref)
    drive.enable(Mode.VELOCITY)
    drive.jog(2000)
    drive.begin()
    st.sleep(0.5)
    assert abs(drive.velocity()) > 0
    (r,) = stop_drives(session, [ref], MotionSettings.from_config(session.cfg), clock=st.now, sleep=st.sleep)
    assert r.ok and r.stopped_by == "halt" and r.standstill is True and r.motor_off, r
    assert not drive.status().enabled and drive.velocity() == 0
    (again,) = stop_drives(session, [ref], MotionSettings.from_config(session.cfg), clock=st.now, sleep=st.sleep)
    assert again.stopped_by == "motor was off" and not again.motor_off  # nothing written to a motor off


def test_monitor_shows_the_cia402_drive_power_stage_position_and_a_fault(arm):
    session, _st, _ = arm
    ref = drive_ref(session.cfg, "wrist")
    with Monitor(session, [ref]) as mon:
        mon.poll()
        (row,) = mon.snapshot()
    assert row.answering and row.mo == 0 and row.px == 0 and row.um is None and row.problem is None
    with session.sim.lock:
        session.sim.drives["wrist"].fault(0x2310)
    with Monitor(session, [ref]) as mon:
        mon.poll()
        (row,) = mon.snapshot()
    assert row.answering and row.problem is not None and row.problem.startswith("fault: "), row


def test_a_cia402_drive_in_fault_is_refused_by_the_guard_with_the_decoded_code(arm):
    session, st, events = arm
    from sherpa_cli.errors import SafetyError

    with session.sim.lock:
        session.sim.drives["wrist"].fault(0x2310)
    with pytest.raises(SafetyError, match="in fault, refusing to move it"):
        _jog(session, st, "wrist", by="10counts", uncalibrated=True)
    assert not [t for n, t in events if n == "wrist" and t.startswith("motor on")]


@pytest.mark.parametrize(("argv", "refused"), [
    (["identify", "wrist"], "`sherpa identify` is for Elmo drives"),
    (["cmd", "wrist", "PX"], "`sherpa cmd` is for Elmo drives"),
    (["tune", "show", "wrist"], "`sherpa tune` is for Elmo drives"),
    (["program-limits", "wrist"], "`sherpa program-limits` is for Elmo drives"),
    (["dump-params", "wrist"], "`sherpa dump-params` is for Elmo drives"),
    (["home", "wrist", "--yes"], "sherpa homes joints on Elmo drives"),
    (["log", "step", "wrist", "--velocity", "1", "--for", "1", "-o", "out", "--apply"], "is a cia402 drive"),
])
def test_an_elmo_command_refuses_a_named_cia402_drive_by_name_before_the_bus(cli, argv, refused):
    """Nothing is opened: the refusal comes from the config alone (no --sim, no bus)."""
    res = cli("--config", str(CONFIG), *argv)
    assert res.exit_code == 2, res
    assert refused in res.stderr and "Traceback" not in res.stderr, res.stderr


def test_identify_of_every_drive_reads_the_elmo_drives():
    from sherpa_cli.bus.targets import drive_names

    cfg = load_config(CONFIG)
    assert drive_names(cfg, None, elmo_only="identify") == ["elbow", "left", "right"]
    assert drive_names(cfg, None) == ["elbow", "wrist", "left", "right"]


def test_arm_state_reads_a_cia402_joint_through_the_seam(arm):
    import math

    session, st, _ = arm
    _jog(session, st, "wrist", by="300counts", uncalibrated=True)
    state = {j.name: j for j in Arm(session).state()}
    wrist = state["wrist"]
    assert wrist.position_counts == 300 and not wrist.motor_on and wrist.faults == ()
    assert not wrist.calibrated and "cia402 drive" in wrist.calibration
    assert math.isnan(wrist.current)  # not read from this drive type, never a made-up 0
    assert state["arm"].position_counts == 0 and not math.isnan(state["arm"].current)


def test_the_guard_journals_the_cia402_profile_before_it_changes_it_and_forgets_it_once_put_back(arm):
    """What `sherpa recover` puts back after a killed command: the profile objects (0x6081/3/4) as
    they were, on disk before the first of them changes; dropped from the journal once restored."""
    import json

    from sherpa_cli.bus import journal

    session, st, _ = arm
    ref = drive_ref(session.cfg, "wrist")
    drive = open_drive(session, ref)
    session.client(ref).nmt_start()
    before = drive.ramp()
    path = journal.path_for(ref.bus, ref.node)
    seen: list[dict[str, int]] = []
    sleep = st.sleep

    def peek(s: float) -> None:
        if path.exists() and not seen:
            steps = json.loads(path.read_text()).get("steps", [])
            names = {x["name"]: x["old"] for x in steps}
            if "0x6081:0" in names:
                seen.append(names)
        sleep(s)

    axis = resolve_axis(session.cfg, "wrist")
    req = parse_request(axis, "position", by="500counts", uncalibrated=True)
    r = run_jog(session, axis, req, settings=MotionSettings.from_config(session.cfg), clock=st.now, sleep=peek)
    assert r.ok
    assert seen and seen[0]["0x6081:0"] == before.speed and seen[0]["0x6083:0"] == before.accel \
        and seen[0]["0x6084:0"] == before.decel, seen
    assert drive.ramp() == before  # put back
    assert not path.exists() or not json.loads(path.read_text()).get("steps"), path.read_text()


def test_a_cia402_drive_in_fault_makes_a_monitor_snapshot_not_ok(arm):
    session, _st, _ = arm
    with Arm(session).monitor(["wrist"], count=1) as stream:
        assert next(stream).ok
    with session.sim.lock:
        session.sim.drives["wrist"].fault(0x2310)
    with Arm(session).monitor(["wrist"], count=1) as stream:
        snap = next(stream)
    assert not snap.ok and snap["wrist"].answering and snap["wrist"].problem.startswith("fault: ")
