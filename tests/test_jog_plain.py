"""`sherpa jog` of a plain joint on the simulated arm: position, velocity and torque, refusals, the CLI."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from motion_helpers import stepped_session
from test_motion_guard import ARMED, CONFIG, RESTORED

from sherpa_cli.bus.session import ArmSession
from sherpa_cli.config import load_config
from sherpa_cli.errors import UsageError
from sherpa_cli.motion.axis import resolve_axis
from sherpa_cli.motion.request import parse_request
from sherpa_cli.motion.settings import MotionSettings
from sherpa_cli.ops.jog import check_request, run_jog
from sherpa_cli.sim.arm import SimArm

CPR = 4000


@pytest.fixture
def cfg(tmp_path):
    path = tmp_path / "arm.yaml"
    path.write_text(CONFIG, encoding="utf-8")
    return load_config(path)


def jog(cfg, name, **req):
    """``run_jog`` on the arm's stepped time (motion_helpers.stepped_session): how far a timed jog gets
    is the simulated drive's, not the host's load."""
    target = resolve_axis(cfg, name)
    progress = []
    with stepped_session(cfg) as (s, stepped):
        result = run_jog(s, target, parse_request(target, **req), settings=MotionSettings.from_config(cfg),
                         clock=stepped.now, sleep=stepped.sleep, on_progress=progress.append)
        drive = s.sim.drives[target.ref.name]
        with s.sim.lock:
            sim = {"px": drive.px, "on": drive.motor_on, "v": drive.motor.v,
                   "writes": [(i, sub, v) for _, i, sub, v in drive.od_writes],
                   "um": drive.ram["UM"], "tc": drive.ram["TC"]}
        assert s.sim.errors == []
    return result, sim, progress


def test_position_jog_to_ends_at_the_target(cfg):
    result, sim, progress = jog(cfg, "j1", mode="position", to=1.0, uncalibrated=True)  # j1 cannot be homed
    goal = round(1.0 * CPR / (2 * math.pi))  # 637
    assert result.target_counts == goal and result.command == f"PA={goal}"
    assert abs(result.end_counts - goal) <= 1 and result.error_counts == result.end_counts - goal
    assert sim["px"] == result.end_counts and not sim["on"] and sim["v"] == 0
    assert sim["writes"] == ARMED + RESTORED
    assert result.ended_by == "target reached" and progress
    (stop,) = result.stop.drives
    assert stop.stopped_by == "ST" and stop.motor_off and stop.standstill


def test_position_jog_by_is_relative(cfg):
    result, _sim, _ = jog(cfg, "drive1", mode="position", by=-0.5, uncalibrated=True)
    assert result.start_counts == 0 and result.target_counts == -318
    assert abs(result.end_counts + 318) <= 1


def test_velocity_jog_for_a_time_stops_where_it_says(cfg):
    result, sim, progress = jog(cfg, "j1", mode="velocity", velocity=2.0, duration=0.3)
    v = round(2.0 * CPR / (2 * math.pi))
    assert result.command == f"JV={v}" and result.ended_by == "time up"
    assert 0.3 <= result.duration < 0.5  # of simulated time: the stop's own requests add a little
    # it moved about v * 0.3 s, and the result names exactly where the motor stands
    assert v * 0.2 < result.end_counts < v * 0.5, result.end_counts
    assert sim["px"] == result.end_counts and not sim["on"] and sim["v"] == 0
    assert sim["um"] == 5  # velocity_unit_mode 5: JV + BG in position mode, UM untouched
    assert [p.counts for p in progress] == sorted(p.counts for p in progress)


def test_torque_jog_for_a_time_stops_and_restores_the_unit_mode(cfg):
    result, sim, _ = jog(cfg, "j1", mode="torque", torque=0.5, duration=0.2)
    assert result.command == "TC=0.5" and result.end_counts > 0
    assert sim["px"] == result.end_counts and not sim["on"] and sim["v"] == 0
    assert sim["um"] == 5 and sim["tc"] == 0.0
    (stop,) = result.stop.drives
    assert stop.stopped_by == "TC=0 + ST" and "UM=5" in stop.restored


@pytest.mark.parametrize("req,match", [
    (dict(mode="torque", torque=0.5), "needs --for"),
    (dict(mode="torque", torque=2.5, duration=1), "continuous current limit 2.0 A"),
    (dict(mode="velocity", velocity=20.0), r"j1: --velocity 19.9994 rad/s \(12732 counts/s\) is above the joint's speed limit "),
    (dict(mode="position", to=1.0, by=1.0), "exactly one of --to or --by"),
    (dict(mode="position", to=1.0, duration=1.0), "--for applies to"),
    (dict(mode="velocity", velocity=1.0, duration=0.0), "--for 0.0"),
    (dict(mode="position", to=float("nan")), "finite"),
])
def test_refusals_before_the_bus(cfg, req, match):
    with pytest.raises(UsageError, match=match):
        check_request(resolve_axis(cfg, "j1"), parse_request(resolve_axis(cfg, "j1"), **req))


def test_a_drive_without_a_plain_joint_needs_counts(cfg):
    with pytest.raises(UsageError, match="no cpr"):
        check_request(resolve_axis(cfg, "drive2"), parse_request(resolve_axis(cfg, "drive2"), mode="position", to=1.0))


# -- the command ---------------------------------------------------------------------------------

def test_cli_torque_without_for_is_refused(cli):
    result = cli("--sim", "jog", "elbow_pitch", "--torque", "0.5", "--apply")
    assert result.exit_code == 2, result.transcript()
    assert "needs --for" in result.stderr and "Traceback" not in result.stderr


def test_cli_needs_exactly_one_motion(cli):
    result = cli("--sim", "jog", "elbow_pitch", "--to", "0.1", "--velocity", "0.1", "--apply")
    assert result.exit_code == 2 and "exactly one of" in result.stderr


def test_cli_dry_run_moves_nothing(cli):
    result = cli("--sim", "jog", "elbow_pitch", "--to", "0.1")
    assert result.exit_code == 0, result.transcript()
    assert "dry run" in result.stdout and "--apply" in result.stdout


def test_cli_sigma_joint_goes_the_pair_way(cli):
    # wave/jog: Σ/Δ joints are jogged through ops/joint_jog.py (tests/test_jog_pair.py); this one is not homed
    result = cli("--sim", "jog", "shoulder_pitch", "--to", "0.1", "--apply")
    assert result.exit_code == 1 and "not homed since power-up" in result.stderr


@pytest.mark.realbus
def test_cli_position_jog_on_the_arm(arm_cli):
    result = arm_cli("--json", "jog", "elbow_pitch", "--to", "0.5", "--apply")
    assert result.exit_code == 0, result.transcript()
    data = json.loads(result.stdout)
    goal = round(0.5 * 3600 / (2 * math.pi))
    assert data["target_position"]["counts"] == goal
    assert abs(data["error"]["counts"]) <= 1 and data["ended_by"] == "target reached"
    assert data["stop"]["drives"][0]["motor_off"] is True
    assert result.stderr == ""  # no live position with --json


def test_cli_velocity_jog_final_line(cli):
    result = cli("--sim", "jog", "elbow_pitch", "--velocity", "0.2", "--for", "0.2", "--apply")
    assert result.exit_code == 0, result.transcript()
    *stops, last = result.stdout.splitlines()
    assert last.startswith("elbow_pitch (elbow_1a, can1:40): stopped at ") and "time up" in last
    assert stops == ["stop: elbow_1a (can1:40): stopped; motor off; settings put back"]
    assert "\r" not in result.stderr  # not a terminal: no live line


def test_position_jog_by_is_checked_again_with_the_px_read_after_arming(cfg, monkeypatch):
    from sherpa_cli.ops import jog as jog_mod

    real_precheck = jog_mod.precheck

    def precheck_then_the_joint_moves(session, target, req):
        cal = real_precheck(session, target, req)  # checked with PX = 0: 0 + 318 is inside
        with session.sim.lock:
            session.sim.drives["drive1"].motor.counts = 19800  # pushed meanwhile: 19800 + 318 is not
        return cal
    monkeypatch.setattr(jog_mod, "precheck", precheck_then_the_joint_moves)
    with pytest.raises(UsageError, match=r"j1: target 20118 counts is outside the joint's normal range"):
        jog(cfg, "j1", mode="position", by=0.5, uncalibrated=True)


def test_velocity_jog_without_a_configured_speed_limit_is_refused(tmp_path):
    path = tmp_path / "arm.yaml"
    path.write_text(CONFIG.replace("    velocity: {limit: 8000, trip: 12000}\n", ""), encoding="utf-8")
    cfg = load_config(path)
    assert cfg.joints["j1"].vel_limit is None
    with pytest.raises(UsageError, match=r"j1: no speed limit configured \(joints.j1.velocity.limit is missing\)"):
        check_request(resolve_axis(cfg, "j1"), parse_request(resolve_axis(cfg, "j1"), mode="velocity", velocity=0.1, duration=0.2))


def test_pair_velocity_jog_without_a_configured_speed_limit_is_refused():
    import dataclasses

    from test_jog_pair import CONFIG as PAIR_CONFIG

    from sherpa_cli.ops import joint_jog

    pair_cfg = load_config(PAIR_CONFIG)
    axis = dataclasses.replace(resolve_axis(pair_cfg, "pitch"), vel_limit=None)
    with pytest.raises(UsageError, match="pitch: no speed limit configured"):
        joint_jog.check_offline(pair_cfg, axis, parse_request(axis, mode="velocity", velocity="100counts/s",
                                                                     duration=0.2))


def _stop_that_never_settles(monkeypatch):
    from sherpa_cli.motion import guard, stopping

    real = stopping.stop_drive

    def stop_drive(*a, **k):
        how, _standstill, problems = real(*a, **k)
        return how, False, [*problems, "not at standstill 2 s after the stop"]
    monkeypatch.setattr(stopping, "stop_drive", stop_drive)  # the limit watch's stop
    monkeypatch.setattr(guard, "stop_drive", stop_drive)  # the guard's exit stop


def test_ctrl_c_ending_a_velocity_jog_does_not_hide_a_failed_stop(cfg, monkeypatch):
    from sherpa_cli.errors import SafetyError

    _stop_that_never_settles(monkeypatch)
    calls = []

    def progress(p):
        calls.append(p)
        if len(calls) == 3:
            raise KeyboardInterrupt  # how an open-ended velocity jog normally ends
    target = resolve_axis(cfg, "j1")
    with (
        ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s,
        pytest.raises(SafetyError, match="drive1: not at standstill") as info,
    ):
        run_jog(s, target, parse_request(target, mode="velocity", velocity=0.5),
                settings=MotionSettings.from_config(cfg), on_progress=progress)
    assert info.value.motion_report.drives[0].standstill is False


def test_cli_json_error_carries_the_stop_report(cli, monkeypatch):
    _stop_that_never_settles(monkeypatch)
    result = cli("--sim", "--json", "jog", "elbow_pitch", "--velocity", "0.2", "--for", "0.2", "--apply")
    assert result.exit_code != 0, result.transcript()
    data = json.loads(result.stdout)
    assert "did not go cleanly" in data["error"]
    assert data["stop"]["drives"][0]["standstill"] is False


def test_the_limit_watch_stops_with_the_configured_stop_method(tmp_path):
    path = tmp_path / "arm.yaml"
    path.write_text(CONFIG.replace("motion: {consumer_time_ms: 300}", "motion: {consumer_time_ms: 300, stop_method: jv0}"),
                    encoding="utf-8")
    cfg = load_config(path)
    target = resolve_axis(cfg, "j1")
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        drive = s.sim.drives["drive1"]
        with s.sim.lock:
            drive.motor.counts = 19950  # 50 counts short of the full range's end (20000)
        result = run_jog(s, target, parse_request(target, mode="velocity", velocity=0.5, duration=3.0),
                         settings=MotionSettings.from_config(cfg))
        with s.sim.lock:
            executed = [d[:2].decode() for _, cid, d in drive.received if cid == 0x305 and len(d) == 4]
    assert not result.ok and len(result.breaches) == 1
    assert "ST" not in executed and "BG" in executed  # motion.stop_method jv0: JV=0 + BG, never ST


# -- --hold and gravity-loaded joints ----------------------------------------------------------------

def test_hold_keeps_the_motor_on_at_the_end_position_until_ctrl_c(cfg):
    seen: list[tuple[bool, int]] = []
    holding_from: list[int] = []

    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        drive = s.sim.drives["drive1"]

        def progress(p):
            with s.sim.lock:
                seen.append((drive.motor_on, p.counts))
            if drive.ram.get("UM") == 5 and len(seen) > 40:
                holding_from.append(len(seen))
                if len(holding_from) > 20:
                    raise KeyboardInterrupt  # how a hold ends
        result = run_jog(s, resolve_axis(cfg, "j1"),
                         parse_request(resolve_axis(cfg, "j1"), mode="velocity", velocity=0.5, duration=0.2, hold=True),
                         settings=MotionSettings.from_config(cfg), on_progress=progress)
        with s.sim.lock:
            off_at_end = not drive.motor_on
    assert result.ended_by == "held until Ctrl-C"
    assert "then held at PA=" in result.command
    held = [on for on, _ in seen[holding_from[0]:]]
    assert held and all(held)  # on while held
    assert off_at_end  # the guard's exit switched it off


def test_hold_ends_normally_when_sherpa_stop_switches_the_motor_off(cfg):
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        ref = resolve_axis(cfg, "j1").ref
        calls = {"n": 0}

        def progress(p):
            calls["n"] += 1
            if calls["n"] == 60:
                s.client(ref).motor_off()  # what `sherpa stop` from a second terminal ends with: MO=0
        result = run_jog(s, resolve_axis(cfg, "j1"),
                         parse_request(resolve_axis(cfg, "j1"), mode="velocity", velocity=0.5, duration=0.2, hold=True),
                         settings=MotionSettings.from_config(cfg), on_progress=progress)
    assert result.ended_by == "held until the motor was switched off (sherpa stop)"
    assert ref.name == "drive1"


def test_a_gravity_loaded_joint_is_named_before_it_moves(cli, tmp_path):
    import yaml

    data = yaml.safe_load(Path("configs/sherpa-arm.yaml").read_text())
    data["joints"]["elbow_pitch"]["gravity"] = True
    path = tmp_path / "arm.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    assert cli("--config", str(path), "config", "check").exit_code == 0
    moved = cli("--config", str(path), "--sim", "jog", "elbow_pitch", "--velocity", "0.05", "--for", "0.2", "--apply")
    assert moved.exit_code == 0, moved.transcript()
    assert "elbow_pitch: gravity-loaded: the motor is switched off at the end and the joint falls" in moved.stderr
    held = cli("--config", str(path), "--sim", "jog", "wrist_1", "--velocity", "0.05", "--for", "0.2", "--apply")
    assert "gravity-loaded" not in held.stderr  # only the marked joint
