"""`log step` on the simulated arm with the servo-loop motor model (real time, in-process):
position step of 1 rad with and without the MO/UM switch, velocity step of 0.1 rad/s, torque
step of 1 A. The simulator runs on wall time here, so metrics are checked against tolerances;
the command's golden output (`--sim` runs on stepped time) is tests/test_log_step_golden.py."""

from __future__ import annotations

import uuid
from pathlib import Path

import pytest

from sherpa_cli.config import load_config
from sherpa_cli.ops.jog import resolve_jog_target
from sherpa_cli.ops.motion import MotionSettings
from sherpa_cli.ops.session import ArmSession
from sherpa_cli.ops.step import run_step
from sherpa_cli.sim.arm import SimArm, settings_for
from sherpa_cli.sim.servo import ServoMotor

ROOT = Path(__file__).resolve().parent.parent
SERVO = dict(servo_bandwidth_hz=8.0, servo_damping=0.4, mo_settle_s=0.2)


@pytest.fixture
def arm():
    cfg = load_config(ROOT / "configs/sherpa-arm.yaml")
    tag = uuid.uuid4().hex[:8]
    settings = {name: settings_for(cfg, name, **SERVO) for name in cfg.drives if cfg.drives[name].bus == "can1"}
    sim = SimArm(cfg, {"can1": {"interface": "virtual", "channel": f"step-{tag}"}}, settings=settings)
    return cfg, sim


def _step(cfg, sim, mode, value, *, before=None, duration=2.0):
    target = resolve_jog_target(cfg, "elbow_pitch")
    with ArmSession.open(cfg, sim=sim, buses=["can1"]) as session:
        assert isinstance(sim.drives["elbow_1a"].motor, ServoMotor)
        if before:
            c = session.client(target.ref)
            c.nmt_start()
            before(c)
        return run_step(session, target, mode, value, duration=duration, rate=200,
                        settings=MotionSettings.from_config(cfg, ["can1"]))


def test_position_step_after_a_mode_switch(arm):
    cfg, sim = arm
    result = _step(cfg, sim, "position", 1.0, before=lambda c: c.set("UM", 0, 2))
    m = result.metrics
    assert result.switch_s >= 0.2  # MO=1 (and UM 2 -> 5) before the step: the drive's settle time
    assert m.dead_time >= result.switch_s
    assert m.final == pytest.approx(1.0, abs=0.02)
    assert m.overshoot > 0.5  # the servo loop overshoots the profile
    assert m.rise_time is not None and m.settling_time is not None
    assert result.samples >= 0.95 * result.expected
    assert result.stop.drives[0].motor_off


def test_position_step_without_a_switch(arm):
    cfg, sim = arm

    def ready(c):
        c.set("UM", 0, 5)
        c.motor_on()

    result = _step(cfg, sim, "position", 1.0, before=ready)
    assert result.switch_s < 0.15  # UM and MO already right: nothing to switch
    assert result.metrics.dead_time < 0.15
    assert result.metrics.final == pytest.approx(1.0, abs=0.02)


def test_velocity_step(arm):
    cfg, sim = arm
    result = _step(cfg, sim, "velocity", 0.1, duration=1.5)
    assert result.metrics.final == pytest.approx(0.1, rel=0.05)
    assert result.metrics.rise_time is not None


def test_torque_step_of_one_ampere(arm):
    cfg, sim = arm
    result = _step(cfg, sim, "torque", 1.0, duration=0.4)
    assert result.signal == "cur"
    assert result.metrics.final == pytest.approx(1.0, abs=0.01)
    assert result.ended_by == "time up"


def test_supply_limit_slows_a_step():
    """The seed's 1 A supply: the same step takes longer when the supply limits the current."""
    from sherpa_cli.sim.motor import Motor  # noqa: F401

    def settle(supply):
        m = ServoMotor(wn=2 * 3.14159 * 8, zeta=0.6, torque_accel_per_amp=10000.0, current_limit=10.0,
                       supply_limit=supply, supply_speed=20000.0)
        m.move_to(2000, 1e9, 1e9, 1e9)
        t = 0.0
        while t < 5:
            m.step(0.001)
            t += 0.001
            if abs(m.position - 2000) < 20 and abs(m.v) < 50:
                return t
        return t

    assert settle(1.0) > 1.5 * settle(None)


def test_cli_step_writes_csv_png_and_metrics(cli, tmp_path):
    out = tmp_path / "step"
    result = cli("--sim", "log", "step", "elbow_pitch", "--torque", "0.5", "--for", "0.3", "--rate", "200",
                 "-o", str(out))
    assert result.exit_code == 0, result.stderr
    import json

    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["mode"] == "torque" and metrics["metrics"]["final"] == pytest.approx(0.5, abs=0.01)
    assert (out / "recording.csv").stat().st_size > 0 and (out / "step.png").stat().st_size > 1000
    assert "stopped by" in result.stdout
    bad = cli("--sim", "log", "step", "elbow_pitch", "--torque", "9", "-o", str(out))
    assert bad.exit_code == 2 and "continuous current limit" in bad.stderr
    both = cli("--sim", "log", "step", "elbow_pitch", "--torque", "1", "--position", "1", "-o", str(out))
    assert both.exit_code == 2 and "exactly one" in both.stderr


def test_the_config_sim_section_turns_the_servo_model_on(tmp_path):
    import yaml

    from sherpa_cli.sim.drive import SimDrive
    from sherpa_cli.sim.clock import ManualClock

    doc = yaml.safe_load((ROOT / "configs/sherpa-arm.yaml").read_text(encoding="utf-8"))
    doc.setdefault("sim", {}).setdefault("drives", {})["elbow_1a"] = {"servo_bandwidth": 8,
                                                                     "supply_current_limit": 1.0}
    path = tmp_path / "servo.yaml"
    path.write_text(yaml.safe_dump(doc, allow_unicode=True), encoding="utf-8")
    cfg = load_config(path)
    settings = settings_for(cfg, "elbow_1a")
    assert settings.servo_bandwidth_hz == 8 and settings.supply_current_limit == 1.0
    motor = SimDrive(40, clock=ManualClock(), settings=settings).motor
    assert isinstance(motor, ServoMotor) and motor.supply_limit == 1.0
    assert not isinstance(SimDrive(41, clock=ManualClock(), settings=settings_for(cfg, "elbow_1b")).motor,
                          ServoMotor)
