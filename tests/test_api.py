"""The Python API (issue 28 item 3): `sherpa_cli.Arm`, typed, and the CLI commands as thin layers over it."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

import sherpa_cli
from sherpa_cli.api import Arm
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
    from sherpa_cli.ops.jog import JogResult

    assert isinstance(result, JogResult) and result.breach is None and result.ended_by == "time up"
    assert result.end_counts is not None and result.end_counts > result.start_counts  # it moved, outward
    assert result.stop.drives and all(d.motor_off for d in result.stop.drives)


def test_jog_moves_a_sigma_joint_with_both_motors():
    from sherpa_cli.ops.joint_jog import JogResult

    with Arm.open(CONFIG, sim=True) as arm:
        result = arm.jog("shoulder_pitch", velocity="50counts/s", duration=0.3)
        motors = [arm.session.sim.drives[d] for d in ("shoulder_2a", "shoulder_2b")]
        assert not any(m.motor_on for m in motors)
    assert isinstance(result, JogResult) and result.ok


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
