"""The Python API: `sherpa_cli.Arm`, typed, and the CLI commands as thin layers over it."""

from __future__ import annotations

import re
import subprocess
import sys
from math import tau as TAU
from pathlib import Path

import pytest

import sherpa_cli
from sherpa_cli.api import Arm, JogResult
from sherpa_cli.errors import SafetyError, UsageError

ROOT = Path(__file__).resolve().parent.parent
CONFIG = ROOT / "configs" / "sherpa-arm.yaml"


def test_importing_the_package_does_not_import_the_api():
    """`sherpa` starts fast: `import sherpa_cli` (every command does) loads neither the API nor the CAN stack."""
    code = "import sys, sherpa_cli\nprint(sorted(m for m in ('sherpa_cli.api', 'can') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True)
    assert out.stdout.strip() == "[]"


def test_arm_is_reachable_from_the_package_and_typed():
    assert sherpa_cli.Arm is Arm
    assert (Path(sherpa_cli.__file__).parent / "py.typed").is_file()
    with pytest.raises(AttributeError, match="no attribute 'Nope'"):
        sherpa_cli.Nope  # noqa: B018


def test_sim_and_a_bus_map_exclude_each_other():
    with pytest.raises(UsageError, match="exclude each other"), Arm.open(CONFIG, sim=True, bus_map=["can0=virtual:x"]):
        pass


def test_a_dry_run_writes_nothing_and_apply_is_read_back():
    with Arm.open(CONFIG, sim=True) as arm:
        first = arm.program_limits(["elbow_pitch"])
        assert first.result is None and first.changes > 0 and first.ok
        again = arm.program_limits(["elbow_pitch"])
        assert again.changes == first.changes  # the dry run wrote nothing
        done = arm.program_limits(["elbow_pitch"], apply=True)
        assert done.result is not None and [o.status for o in done.result.outcomes] == ["programmed"]
        assert arm.program_limits(["elbow_pitch"]).changes == 0


def test_save_without_a_confirmation_writes_nothing():
    with Arm.open(CONFIG, sim=True) as arm:
        with pytest.raises(SafetyError, match="not confirmed"):
            arm.program_limits(["wrist_3"], apply=True, save=True)
        report = arm.program_limits(["wrist_3"], apply=True, save=True, check=False)
        assert report.result is None and isinstance(report.problem, SafetyError)
        assert arm.program_limits(["wrist_3"]).changes == report.changes > 0  # nothing was written


def test_save_needs_apply():
    with Arm.open(CONFIG, sim=True) as arm, pytest.raises(UsageError, match="--save needs --apply"):
        arm.program_limits(save=True)


def test_stop_is_best_effort_and_names_what_it_could_not_reach(monkeypatch):
    from test_stop import _can0_cannot_open

    _can0_cannot_open(monkeypatch)  # opening can0 fails as a missing adapter does
    with Arm.open(CONFIG, sim=True, best_effort=True) as arm:
        assert "can0" in arm.session.unreachable
        report = arm.stop(check=False)
        on_can0 = [r.drive for r in report.drives if r.address.startswith("can0:")]
        assert on_can0 and report.not_reached == on_can0 and report.unconfirmed == []
        assert all(r.ok for r in report.drives if r.drive not in on_can0)
        with pytest.raises(SafetyError, match=f"partly stopped .* not reached .*{on_can0[0]}"):
            arm.stop()


def test_the_stop_command_is_a_layer_over_the_api(cli, monkeypatch):
    """What the CLI shows is what Arm.stop returned: one path for the command and for Python."""
    calls = []
    real = Arm.stop

    def spy(self, targets=None, *, check=True):
        calls.append((list(targets or []), check))
        return real(self, targets, check=check)

    monkeypatch.setattr(Arm, "stop", spy)
    result = cli("--sim", "stop", "elbow_pitch")
    assert result.exit_code == 0, result.output
    assert calls == [(["elbow_pitch"], False)]


def test_scan_and_program_limits_commands_go_through_the_api(cli, monkeypatch):
    from sherpa_cli.api import programming

    seen = []
    real_scan, real_run = Arm.scan, programming.run
    monkeypatch.setattr(Arm, "scan", lambda self, *a, **k: seen.append("scan") or real_scan(self, *a, **k))
    monkeypatch.setattr(programming, "run", lambda *a, **k: seen.append("program") or real_run(*a, **k))
    assert cli("--sim", "scan", "--bus", "can0").exit_code in (0, 1)
    assert cli("--sim", "program-limits", "elbow_pitch").exit_code == 0
    assert seen == ["scan", "program"]


def test_jog_moves_a_plain_joint_inside_the_guard_and_leaves_the_motor_off():
    with Arm.open(CONFIG, sim=True) as arm:
        result = arm.jog("elbow_pitch", velocity=0.3, duration=0.4)  # an absolute joint: no homing needed
        drive = arm.session.sim.drives["elbow_1a"]
        assert not drive.motor_on
    assert isinstance(result, JogResult) and result.ok and not result.breaches and result.ended_by == "time up"
    assert result.end_counts is not None and result.end_counts > result.start_counts  # it moved, outward
    assert result.stop.drives and all(d.motor_off for d in result.stop.drives)


def test_jog_moves_a_sigma_joint_with_both_motors():
    with Arm.open(CONFIG, sim=True) as arm:
        result = arm.jog("shoulder_pitch", velocity="50counts/s", duration=0.3)
        motors = [arm.session.sim.drives[d] for d in ("shoulder_2a", "shoulder_2b")]
        assert not any(m.motor_on for m in motors)
    assert isinstance(result, JogResult) and result.ok
    assert [d.drive for d in result.stop.drives] == ["shoulder_2a", "shoulder_2b"]  # the typed report


@pytest.mark.parametrize("name,kind,drives,cpr", [("elbow_pitch", "plain", ("elbow_1a",), 3600),
                                                  ("shoulder_pitch", "sigma", ("shoulder_2a", "shoulder_2b"), 6000),
                                                  ("shoulder_2a", "motor", ("shoulder_2a",), 6000)])
def test_every_kind_of_axis_jogs_into_the_one_result_in_rad_and_counts(name, kind, drives, cpr):
    """A plain joint, a Σ joint and one motor of a pair: the one JogResult, its positions in rad the
    simulated drives' counts (Σ = a + b) over the joint's cpr."""
    with Arm.open(CONFIG, sim=True) as arm:
        sim = arm.session.sim.drives
        before = {d: sim[d].px for d in drives}
        result = arm.jog(name, velocity="200counts/s", duration=0.3)
        after = {d: sim[d].px for d in drives}
    start, end = sum(before.values()), sum(after.values())
    assert type(result) is JogResult
    assert (result.axis, result.kind, result.drives, result.cpr) == (name, kind, drives, cpr)
    assert result.start_counts == start and result.end_counts == end and end > start  # it moved, the asked way
    assert result.start_rad == pytest.approx(start * TAU / cpr)
    assert result.end_rad == pytest.approx(end * TAU / cpr) and result.end_rad > result.start_rad
    assert result.speed_rad_s == pytest.approx(200 * TAU / cpr) and result.target_rad is None
    assert {d: result.motors_end[d] for d in drives} == after
    assert result.ok and result.ended_by == "time up" and result.duration > 0.0
    assert result.stop.drives and all(d.motor_off for d in result.stop.drives)


def test_the_docs_jog_example_passes_mypy_strict_as_written(tmp_path):
    """What a user copies from docs/api.md's jog section type-checks: one result type, whatever the axis."""
    text = (ROOT / "docs" / "api.md").read_text(encoding="utf-8")
    section = text.split("\n## Jog\n", 1)[1].split("\n## ", 1)[0]
    (block,) = re.findall(r"```python\n(.*?)```", section, flags=re.S)
    assert "start_rad" in block and "end_rad" in block  # the example reads joint units
    example = tmp_path / "jog_example.py"
    example.write_text(block, encoding="utf-8")
    out = subprocess.run([sys.executable, "-m", "mypy", "--strict", "--follow-imports=silent",
                          "--cache-dir", str(tmp_path / "cache"), str(example)],
                         cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stdout + out.stderr


def test_the_docs_move_example_passes_mypy_strict_as_written(tmp_path):
    """docs/api.md's "Move several joints" example type-checks: move_pose, the motion session, typed results."""
    text = (ROOT / "docs" / "api.md").read_text(encoding="utf-8")
    section = text.split("\n## Move several joints\n", 1)[1].split("\n## ", 1)[0]
    (block,) = re.findall(r"```python\n(.*?)```", section, flags=re.S)
    assert "arm.motion(" in block and "move_pose(" in block
    example = tmp_path / "move_example.py"
    example.write_text(block, encoding="utf-8")
    out = subprocess.run([sys.executable, "-m", "mypy", "--strict", "--follow-imports=silent",
                          "--cache-dir", str(tmp_path / "cache"), str(example)],
                         cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stdout + out.stderr


def test_jog_takes_exactly_one_kind_of_move():
    with Arm.open(CONFIG, sim=True) as arm, pytest.raises(UsageError, match="exactly one"):
        arm.jog("elbow_pitch", velocity=0.1, torque=0.5, duration=0.2)


def test_the_jog_command_is_a_layer_over_the_api(cli, monkeypatch):
    calls = []
    real = Arm.move

    def spy(self, axis, request, **kw):
        calls.append((axis.name, request.mode))
        return real(self, axis, request, **kw)

    monkeypatch.setattr(Arm, "move", spy)
    result = cli("--sim", "jog", "elbow_pitch", "--velocity", "0.2", "--for", "0.2", "--apply")
    assert result.exit_code == 0, result.transcript()
    assert calls == [("elbow_pitch", "velocity")]


# -- home, diffdrive move, log step, the live jog and the joystick (the motion matrix runs them all)

def test_home_reads_an_absolute_encoder_and_marks_the_drive_calibrated():
    from sherpa_cli.bus.targets import drive_ref
    from sherpa_cli.ops.home import HomeReport

    with Arm.open(CONFIG, sim=True) as arm:
        cfg = arm.config
        drive = arm.session.client(drive_ref(cfg, "elbow_1a"))
        drive.nmt_start()
        flag = cfg.protocol.calibration_flag
        assert int(drive.get("UI", flag)) == 0  # a fresh simulated drive: not marked
        seen = []
        report = arm.home(["elbow_pitch"], on_unit=seen.append)
        marked = int(drive.get("UI", flag))
    assert isinstance(report, HomeReport) and seen == report.units
    [unit] = report.units
    assert (unit.name, unit.kind, unit.drives) == ("elbow_pitch", "abs_encoder", ("elbow_1a",))
    assert marked == 1


def test_home_refuses_what_cannot_be_homed_before_anything_moves():
    with Arm.open(CONFIG, sim=True) as arm:
        with pytest.raises(UsageError, match="nope"):
            arm.home(["nope"])
        assert not any(d.motor_on for d in arm.session.sim.drives.values())


def test_diffdrive_move_moves_both_motors_to_the_target_and_switches_them_off():
    from sherpa_cli.ops.diffdrive import MoveResult

    with Arm.open(CONFIG, sim=True) as arm:
        events: list[str] = []
        r = arm.diffdrive_move("shoulder_pitch", sigma=0.1, relative=True, velocity="200counts/s",
                               uncalibrated=True, on_event=events.append)  # a Σ joint names its pair; 0.1 rad
        motors = [arm.session.sim.drives[d] for d in ("shoulder_2a", "shoulder_2b")]
        assert not any(m.motor_on for m in motors)
    assert isinstance(r, MoveResult) and r.ok and r.pair == "shoulder_diff"
    assert r.target[0] == r.start[0] + 95  # 0.1 rad of a 6000-count joint
    assert abs(r.target[1] - r.start[1]) <= 1  # Δ holds (it gives way a count where Σ's parity needs it)
    assert r.end == r.target and r.stop["drives"]
    assert events  # the guard said what it did


def test_diffdrive_move_refusals_are_the_documented_errors():
    with Arm.open(CONFIG, sim=True) as arm:
        with pytest.raises(SafetyError, match="refusing a move: joint shoulder_pitch is not homed"):
            arm.diffdrive_move("shoulder_diff", sigma="10counts", relative=True)  # not homed since power-up
        with pytest.raises(UsageError, match="normal range"):
            arm.diffdrive_move("shoulder_diff", sigma=3.0, uncalibrated=True)
        with pytest.raises(UsageError, match="not part of a differential pair"):
            arm.diffdrive_move("elbow_pitch", sigma=0.1)
        with pytest.raises(UsageError, match="--naive and --feedback"):
            arm.diffdrive_move("shoulder_diff", sigma=0.1, naive=True, feedback=True, uncalibrated=True)
        assert not any(d.motor_on for d in arm.session.sim.drives.values())


def test_log_step_records_a_velocity_step_and_its_metrics():
    from sherpa_cli.ops.step import StepResult

    with Arm.open(CONFIG, sim=True) as arm:
        step = arm.log_step("elbow_1a", "velocity", 0.1, duration=0.3, rate=200)  # the drive of a plain joint
        assert not arm.session.sim.drives["elbow_1a"].motor_on
    assert isinstance(step, StepResult) and (step.joint, step.drive, step.mode) == ("elbow_pitch", "elbow_1a", "velocity")
    assert step.command.startswith("JV=") and step.samples > 0 and step.breach is None
    assert step.recording.series("elbow_pitch", "vel") is not None
    assert step.stop.drives and all(d.motor_off for d in step.stop.drives)


def test_log_step_refusals_are_the_documented_errors():
    with Arm.open(CONFIG, sim=True) as arm:
        with pytest.raises(UsageError, match="differential pair"):
            arm.log_step("shoulder_pitch", "velocity", 0.1, duration=0.3)
        with pytest.raises(UsageError, match=r"longer than motion\.max_torque_for"):
            arm.log_step("elbow_pitch", "torque", 0.5, duration=60)
        with pytest.raises(UsageError, match="normal range"):
            arm.log_step("elbow_pitch", "position", 3.0, duration=0.5)
        # the command's bounds hold for the API too (review: a 1 Hz step reached the drive)
        with pytest.raises(UsageError, match=r"--rate 1: expected Hz >= 10"):
            arm.log_step("elbow_pitch", "velocity", 0.1, duration=0.5, rate=1.0)
        with pytest.raises(UsageError, match=r"--for 7200.0: expected seconds > 0 and <= 3600"):
            arm.log_step("elbow_pitch", "velocity", 0.1, duration=7200.0)
        assert not any(d.motor_on for d in arm.session.sim.drives.values())


def test_live_jog_is_the_interactive_engine_and_stops_on_leaving():
    from sherpa_cli.ops.live_jog import LiveJog

    with Arm.open(CONFIG, sim=True) as arm:
        live = arm.live_jog(["elbow_pitch"], keepalive=0.3)
        assert isinstance(live, LiveJog) and list(live.axes) == ["elbow_pitch"] and live.drives == ("elbow_1a",)
        with live:
            live.set_velocity("elbow_pitch", 200)
            live.tick()
            assert arm.session.sim.drives["elbow_1a"].motor_on
        assert not arm.session.sim.drives["elbow_1a"].motor_on
    assert [d.drive for d in live.report.drives] == ["elbow_1a"] and live.report.drives[0].motor_off
    with Arm.open(CONFIG, sim=True) as arm, pytest.raises(UsageError, match="unknown target 'nope'"):
        arm.live_jog(["nope"])


def test_joystick_commands_the_mapped_joint_while_the_deadman_is_held():
    import time

    from sherpa_cli.ops.joystick import ScriptedSource

    with Arm.open(CONFIG, sim=True) as arm:
        assert arm.joystick_joints() == ["shoulder_yaw", "shoulder_pitch", "shoulder_roll"]
        with arm.live_jog(arm.joystick_joints()) as live:
            stick = ScriptedSource([(0.0, "BTN_TRIGGER", 1.0), (0.0, "ABS_Z", 0.5), (0.2, "BTN_TRIGGER", 0.0)],
                                   time.monotonic)
            run = arm.joystick(live, stick, duration=0.3)
        assert not any(d.motor_on for d in arm.session.sim.drives.values())
    assert run.ended_by == "time up" and run.commands > 0
    assert {d.drive for d in live.report.drives} == {"shoulder_1a", "shoulder_2a", "shoulder_2b"}


def _spy(monkeypatch, name, calls):
    real = getattr(Arm, name)

    def spy(self, *args, **kw):
        calls.append((name, args))
        return real(self, *args, **kw)

    monkeypatch.setattr(Arm, name, spy)


def test_home_diffdrive_move_and_log_step_commands_go_through_the_api(cli, monkeypatch, tmp_path):
    calls: list[tuple[str, tuple]] = []
    for name in ("home", "diffdrive_move", "log_step"):
        _spy(monkeypatch, name, calls)
    assert cli("--sim", "home", "elbow_pitch").exit_code == 0
    moved = cli("--config", "tests/data/diffdrive-arm.yaml", "--sim", "diffdrive", "move", "diff", "--sigma", "1",
                "--apply")
    assert moved.exit_code == 0, moved.transcript()
    stepped = cli("--sim", "log", "step", "elbow_pitch", "--velocity", "0.1", "--for", "0.3", "--rate", "200",
                  "-o", str(tmp_path / "step"), "--apply")
    assert stepped.exit_code == 0, stepped.transcript()
    assert calls == [("home", (["elbow_pitch"],)), ("diffdrive_move", ("diff",)),
                     ("log_step", ("elbow_pitch", "velocity", 0.1))]
    # the dry runs plan without the session: nothing reaches the API
    calls.clear()
    assert cli("--sim", "home", "elbow_pitch", "--dry-run").exit_code == 0
    assert cli("--sim", "log", "step", "elbow_pitch", "--velocity", "0.1", "-o", str(tmp_path / "dry")).exit_code == 0
    assert calls == []
