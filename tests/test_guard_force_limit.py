"""The motion guard watches the arm's F/T sensor (motion/force_watch.py through motion/guard.py):
a jog of the simulated wrist into the simulated wall (tests/data/ft-arm.yaml: a spring at +300
counts, 100 N/rad, force limit 20 N) stops once |F| crosses the limit, within one check period
plus the stop, and names the force; a sensor that is silent refuses the motion before anything moves;
a command's own --force-limit only tightens; without a sensor nothing changes."""

from __future__ import annotations

import dataclasses
import json
import math
import re
from pathlib import Path

import pytest
from motion_helpers import stepped_session

from sherpa_cli.api import Arm
from sherpa_cli.cli.jog_cmd import force_stop_line
from sherpa_cli.config import load_config
from sherpa_cli.devices.ft_sensor import Wrench
from sherpa_cli.motion.axis import resolve_axis
from sherpa_cli.motion.force_watch import ForceLimitError, SensorSilentError
from sherpa_cli.motion.report import DriveStop, GuardReport
from sherpa_cli.motion.request import parse_request
from sherpa_cli.motion.settings import MotionSettings

ARM = Path(__file__).resolve().parent / "data" / "ft-arm.yaml"
CPR = 3600
WALL = 300  # counts
STIFFNESS = 100.0  # N/rad past the wall


def wall_force(counts: float) -> float:
    """|F| the simulated sensor reads with the wrist at ``counts`` (no noise: the payload's gravity and the wall)."""
    tilt = counts * 2 * math.pi / CPR
    push = STIFFNESS * max(0.0, counts - WALL) * 2 * math.pi / CPR
    fx, fz = 9.81 * math.sin(tilt), push - 9.81 * math.cos(tilt)
    return math.hypot(fx, fz)


def quiet(cfg):
    return dataclasses.replace(cfg, sim_ft={"wrist_ft": dataclasses.replace(
        cfg.sim_ft["wrist_ft"], noise_force=0.0, noise_torque=0.0)})


def jog_into_the_wall(cfg, *, force_limit: float | None = None, to_counts: int = 800):
    with stepped_session(cfg) as (session, stepped):
        session.force_limit = force_limit
        axis = resolve_axis(cfg, "wrist")
        req = parse_request(axis, "position", to=to_counts * 2 * math.pi / CPR, uncalibrated=True)
        events: list[str] = []
        try:
            Arm(session).move(axis, req, settings=MotionSettings.from_config(cfg, ["can0"]),
                              clock=stepped.now, sleep=stepped.sleep)
            error = None
        except (ForceLimitError, SensorSilentError) as exc:
            error = exc
        with session.sim.lock:
            end = session.sim.drives["wrist_drive"].motor.counts
            on = session.sim.drives["wrist_drive"].motor_on
        return error, end, on, events


def crossing(limit: float) -> int:
    return next(c for c in range(0, 900) if wall_force(c) > limit)


def test_a_jog_into_the_wall_stops_once_the_force_crosses_the_limit_and_names_it():
    cfg = quiet(load_config(ARM))
    error, end, on, _ = jog_into_the_wall(cfg)
    assert isinstance(error, ForceLimitError), error
    assert error.axis == "Fz" and "force limit: F/T sensor wrist_ft read |F|" in error.message and "> 20 N" in error.message
    assert not on
    j = cfg.joints["wrist"]
    speed, decel = j.vel_limit, j.decel  # counts/s, counts/s^2
    bound = crossing(20.0) + speed * MotionSettings.from_config(cfg).force_check_interval + speed ** 2 / (2 * decel)
    assert crossing(20.0) <= end <= bound + 10, (end, crossing(20.0), bound)


def test_a_command_limit_tightens_and_stops_earlier():
    cfg = quiet(load_config(ARM))
    error, end, _, _ = jog_into_the_wall(cfg, force_limit=12.0)
    assert isinstance(error, ForceLimitError) and "> 12 N" in error.message
    assert end < crossing(20.0)


def test_a_silent_sensor_refuses_the_motion_before_anything_moves():
    cfg = load_config(ARM)
    cfg = dataclasses.replace(cfg, sim_ft={"wrist_ft": dataclasses.replace(cfg.sim_ft["wrist_ft"], silent_at=0.0)})
    error, end, on, _ = jog_into_the_wall(cfg)
    assert isinstance(error, SensorSilentError) and "does not answer" in error.message
    assert end == 0 and not on


def test_without_a_limit_short_of_the_wall_the_jog_ends_normally():
    cfg = quiet(load_config(ARM))
    error, end, on, _ = jog_into_the_wall(cfg, to_counts=250)
    assert error is None and abs(end - 250) <= 2 and not on


ROOT = Path(__file__).resolve().parent.parent


def test_the_jog_command_stops_at_its_force_limit_and_says_so(cli):
    """`sherpa jog ... --force-limit N --apply` on the arm with the sensor: exit 1, the force named,
    the motor off; the wall at 300 counts is never reached with a limit the payload alone crosses."""
    result = cli("--config", str(ROOT / "tests" / "data" / "ft-arm.yaml"), "--sim", "jog", "wrist", "--to",
                 "800counts", "--uncalibrated", "--force-limit", "15", "--apply")
    assert result.exit_code == 1, result.stdout + result.stderr
    assert "force limit: F/T sensor wrist_ft read |F|" in result.stderr and "> 15 N" in result.stderr
    assert "Traceback" not in result.stderr


@pytest.mark.parametrize("value", ["0", "-3", "nan"])
def test_a_force_limit_that_is_no_force_is_refused_before_anything_moves(cli, value):
    result = cli("--config", str(ROOT / "tests" / "data" / "ft-arm.yaml"), "--sim", "jog", "wrist", "--by",
                 "0.1", "--uncalibrated", "--force-limit", value, "--apply")
    assert result.exit_code == 2 and "--force-limit" in result.stderr and "expected a force in N" in result.stderr


def test_a_force_limit_on_an_arm_without_a_sensor_is_refused_before_anything_moves(cli):
    result = cli("--sim", "jog", "elbow_pitch", "--by", "0.05", "--force-limit", "10", "--apply")
    assert result.exit_code == 2 and "this arm has no F/T sensor" in result.stderr, result.stderr
    assert "motor on" not in result.stderr


def test_a_sensor_that_goes_silent_during_the_motion_stops_it():
    """A watch that cannot see is no watch: the sensor stops answering mid-jog (simulated time
    0.5 s), the jog stops within the silence bound (SensorSilentError, exit 3) short of its end."""
    cfg = quiet(load_config(ARM))
    cfg = dataclasses.replace(cfg, sim_ft={"wrist_ft": dataclasses.replace(cfg.sim_ft["wrist_ft"], silent_at=0.5)},
                              sim_reply_timeout=0.05)  # each unanswered request waits 50 ms of wall time
    with stepped_session(cfg) as (session, stepped):
        axis = resolve_axis(cfg, "wrist")
        req = parse_request(axis, "velocity", velocity=100 * 2 * math.pi / CPR, duration=3.0)
        with pytest.raises(SensorSilentError, match=r"F/T sensor wrist_ft silent for \d+ ms, 5 requests unanswered"):
            Arm(session).move(axis, req, settings=MotionSettings.from_config(cfg, ["can0"]),
                              clock=stepped.now, sleep=stepped.sleep)
        with session.sim.lock:
            end = session.sim.drives["wrist_drive"].motor.counts
            on = session.sim.drives["wrist_drive"].motor_on
    assert not on and 0 < end < 250, end  # 3 s at 100 counts/s would end at 300


def test_the_api_takes_a_force_limit_per_call_and_puts_the_sessions_back():
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.sim.arm import SimArm

    cfg = quiet(load_config(ARM))
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as session:
        arm = Arm(session)
        with pytest.raises(ForceLimitError, match=r"> 12 N"):
            arm.jog("wrist", to=800 * 2 * math.pi / CPR, uncalibrated=True, force_limit=12.0)
        assert session.force_limit is None  # one call's, not the session's from now on
        with pytest.raises(Exception, match="expected a force in N"):
            arm.jog("wrist", by=0.01, uncalibrated=True, force_limit=-1.0)


def test_after_a_force_stop_the_arm_can_be_moved_away_and_pressing_harder_stops_again():
    """The stop leaves the wrist pressing on the wall, past the limit: the next jog was refused
    ("|F| 22.62 N > 20 N"), the jog away from the contact too."""
    cfg = quiet(load_config(ARM))
    settings = MotionSettings.from_config(cfg, ["can0"])
    with stepped_session(cfg) as (session, stepped):
        axis = resolve_axis(cfg, "wrist")
        arm = Arm(session)

        def move_to(counts: int) -> None:
            arm.move(axis, parse_request(axis, "position", to=counts * 2 * math.pi / CPR, uncalibrated=True),
                     settings=settings, clock=stepped.now, sleep=stepped.sleep)

        with pytest.raises(ForceLimitError):
            move_to(800)
        with session.sim.lock:
            stopped_at = session.sim.drives["wrist_drive"].motor.counts
        assert wall_force(stopped_at) > 20.0  # still pressing past the limit
        with pytest.raises(ForceLimitError, match=r"it began past its 20 N limit"):
            move_to(stopped_at + 40)  # harder into the wall: stopped again
        move_to(0)  # away from the wall: allowed
        with session.sim.lock:
            assert abs(session.sim.drives["wrist_drive"].motor.counts) <= 2


def test_a_force_limit_stop_says_where_the_joint_stopped(cli):
    """The jog into the wall ends with the force-limit error; it used to print only the guard's stop
    line and the error, never where the joint stood. It says it as a normal stop does, from the PX the
    guard read at standstill (the next command reads the same); a jog refused before anything moved
    (the wrist still presses) says no position."""
    config = str(ARM)
    result = cli("--config", config, "--sim", "jog", "wrist", "--to", "800counts", "--uncalibrated", "--apply")
    assert result.exit_code == 1 and "error: force limit: F/T sensor wrist_ft" in result.stderr, result.transcript()
    found = re.search(r"^wrist \(wrist_drive, can0:11\): stopped at ([+-]\d\.\d{4}) rad \((\d+) counts\), "
                      r"force limit$", result.stdout, re.M)
    assert found, result.transcript()
    counts = int(found[2])
    assert WALL < counts < 800 and found[1] == f"{counts * 2 * math.pi / CPR:+.4f}"
    px = cli("--config", config, "--sim", "--json", "cmd", "wrist_drive", "PX")
    assert json.loads(px.stdout)["results"][0]["value"] == counts
    back = cli("--config", config, "--sim", "jog", "wrist", "--to", "0counts", "--uncalibrated", "--apply")
    assert back.exit_code == 0, back.transcript()  # away from the contact: allowed, and said
    # said with how the guard stopped the motors (the guard report's notes)
    assert "F/T sensor wrist_ft: begins past its force limit" in back.stdout, back.transcript()
    assert "target reached" in back.stdout and "force limit:" not in back.stderr, back.transcript()


def test_a_force_limit_stop_of_a_pair_says_where_both_joints_stopped():
    """A Σ jog or `diffdrive move` names the joint asked for first, then the other of the pair."""
    cfg = load_config(Path(__file__).resolve().parent.parent / "configs" / "sherpa-arm.yaml")
    sigma, delta = resolve_axis(cfg, "shoulder_pitch"), resolve_axis(cfg, "shoulder_roll")
    error = ForceLimitError("force limit: |F| 25 N > 20 N", axis="Fz", value=25.0, limit=20.0,
                            wrench=Wrench(0, 0, 25, 0, 0, 0))
    error.motion_report = GuardReport([DriveStop("shoulder_2a", "can0:20", "ST", True, True, position=150),
                                       DriveStop("shoulder_2b", "can0:21", "ST", True, True, position=50)])
    line = force_stop_line(error, [sigma, delta])
    assert line == (f"shoulder_pitch: at {200 * 2 * math.pi / sigma.cpr:+.4f} rad (200 counts), stopped by the "
                    f"force limit; shoulder_roll at {100 * 2 * math.pi / delta.cpr:+.4f} rad (100 counts)")
    error.motion_report = GuardReport([DriveStop("shoulder_2a", "can0:20", "ST", True, True, position=None),
                                       DriveStop("shoulder_2b", "can0:21", "ST", True, True, position=50)])
    assert force_stop_line(error, [sigma]) == "shoulder_pitch: at an unknown position (PX unreadable), stopped by " \
                                              "the force limit"
    assert force_stop_line(SensorSilentError("silent"), [sigma]) is None
