"""`log step` on the simulated arm with the servo-loop motor model (real time, in-process):
position step of 1 rad with and without the MO/UM switch, velocity step of 0.1 rad/s, torque
step of 1 A. The simulator runs on wall time here, so metrics are checked against tolerances;
the command's golden output (`--sim` runs on stepped time) is tests/test_log_step_golden.py."""

from __future__ import annotations

import uuid
from pathlib import Path

import pytest

from sherpa_cli.bus.session import ArmSession
from sherpa_cli.config import load_config
from sherpa_cli.motion.axis import resolve_axis
from sherpa_cli.motion.settings import MotionSettings
from sherpa_cli.ops.step import run_step
from sherpa_cli.sim.arm import SimArm, settings_for
from sherpa_cli.sim.load import Load
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
    target = resolve_axis(cfg, "elbow_pitch")
    with ArmSession.open(cfg, sim=sim, buses=["can1"]) as session:
        assert isinstance(sim.drives["elbow_1a"].motor, ServoMotor)
        if before:
            c = session.client(target.ref)
            c.nmt_start()
            before(c)
        return run_step(session, target, mode, value, duration=duration, rate=200,
                        settings=MotionSettings.from_config(cfg, ["can1"]))


# The steps below run on stepped time (_stepped_step): on wall time a loaded machine delayed the
# samples, the switch and the limit watch, and the figures drifted with it.

def test_position_step_after_a_mode_switch(arm):
    cfg, _sim = arm
    result = _stepped_step(cfg, "position", 1.0, before=lambda c, sim: c.set("UM", 0, 2), duration=3.0)
    m = result.metrics
    assert result.switch_s >= 0.2  # MO=1 (and UM 2 -> 5) before the step: the drive's settle time
    assert m.dead_time >= result.switch_s
    assert m.final == pytest.approx(1.0, abs=0.02)
    assert m.overshoot > 0.5  # the servo loop overshoots the profile
    assert m.rise_time is not None and m.settling_time is not None
    assert result.samples >= 0.95 * result.expected
    assert result.stop.drives[0].motor_off


def test_position_step_without_a_switch(arm):
    cfg, _sim = arm

    def ready(c, sim):
        c.set("UM", 0, 5)
        c.motor_on()

    result = _stepped_step(cfg, "position", 1.0, before=ready, duration=3.0)
    assert result.switch_s < 0.15  # UM and MO already right: nothing to switch
    assert result.metrics.dead_time < 0.15
    assert result.metrics.final == pytest.approx(1.0, abs=0.02)


def test_velocity_step(arm):
    cfg, _sim = arm
    result = _stepped_step(cfg, "velocity", 0.1, duration=1.5)
    assert result.metrics.final == pytest.approx(0.1, rel=0.05)
    assert result.metrics.rise_time is not None


def _stepped_step(cfg, mode, value, *, duration, before=None, sim_out=None):
    """``_step`` on the arm's stepped time (sim/stepped.py), as `sherpa --sim log step` runs it: the
    simulated joint moves by simulated time, so how far it gets does not depend on the host's load.
    ``before(client, sim)``: what is done to the drive first; ``sim_out``: a list given the arm."""
    from sherpa_cli.sim.stepped import SteppedTime

    stepped = SteppedTime()
    tag = uuid.uuid4().hex[:8]
    settings = {name: settings_for(cfg, name, **SERVO) for name in cfg.drives if cfg.drives[name].bus == "can1"}
    sim = SimArm(cfg, {"can1": {"interface": "virtual", "channel": f"step-{tag}"}}, settings=settings,
                 clock=stepped.clock)
    if sim_out is not None:
        sim_out.append(sim)
    target = resolve_axis(cfg, "elbow_pitch")
    with ArmSession.open(cfg, sim=sim, buses=["can1"]) as session:
        assert isinstance(sim.drives["elbow_1a"].motor, ServoMotor)
        unheard = lambda: (sum(d.unheard for d in sim.drives.values()),  # noqa: E731
                           sum(d.unheard_s for d in sim.drives.values()))
        session.client_overrides.update(stepped.client_overrides(cfg.protocol.reply_timeout, cfg.protocol.retries,
                                                                 unheard))
        if before:
            c = session.client(target.ref)
            c.nmt_start()
            before(c, sim)
        return run_step(session, target, mode, value, duration=duration, rate=200,
                        settings=MotionSettings.from_config(cfg, ["can1"]), timebase=stepped)


def test_torque_step_of_one_ampere():
    """On stepped time: on wall time a loaded machine let the joint run out of its range before the
    0.4 s were up (the limit watch then ended the step instead of the time)."""
    cfg = load_config(ROOT / "configs/sherpa-arm.yaml")
    result = _stepped_step(cfg, "torque", 1.0, duration=0.4)
    assert result.signal == "cur"
    assert result.metrics.final == pytest.approx(1.0, abs=0.01)
    assert result.ended_by == "time up"


def test_supply_limit_slows_a_step():
    """The seed's 1 A supply: the same step takes longer when the supply limits the current."""
    def settle(supply):
        m = ServoMotor(wn=2 * 3.14159 * 8, zeta=0.6, load=Load(peak_current=10.0, supply_current=supply))
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
                 "-o", str(out), "--apply")
    assert result.exit_code == 0, result.stderr
    import json

    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["mode"] == "torque" and metrics["metrics"]["final"] == pytest.approx(0.5, abs=0.01)
    assert (out / "recording.csv").stat().st_size > 0 and (out / "step.png").stat().st_size > 1000
    assert "stopped; motor off; settings put back" in result.stdout
    bad = cli("--sim", "log", "step", "elbow_pitch", "--torque", "9", "-o", str(out))
    assert bad.exit_code == 2 and "continuous current limit" in bad.stderr
    both = cli("--sim", "log", "step", "elbow_pitch", "--torque", "1", "--position", "1", "-o", str(out))
    assert both.exit_code == 2 and "exactly one" in both.stderr


def test_the_config_sim_section_turns_the_servo_model_on(tmp_path):
    import yaml

    from sherpa_cli.sim.clock import ManualClock
    from sherpa_cli.sim.drive import SimDrive

    doc = yaml.safe_load((ROOT / "configs/sherpa-arm.yaml").read_text(encoding="utf-8"))
    doc.setdefault("sim", {}).setdefault("drives", {})["elbow_1a"] = {"servo_bandwidth": 8,
                                                                     "supply_current_limit": 1.0}
    path = tmp_path / "servo.yaml"
    path.write_text(yaml.safe_dump(doc, allow_unicode=True), encoding="utf-8")
    cfg = load_config(path)
    settings = settings_for(cfg, "elbow_1a")
    assert settings.servo_bandwidth_hz == 8 and settings.supply_current_limit == 1.0
    motor = SimDrive(40, clock=ManualClock(), settings=settings).motor
    assert isinstance(motor, ServoMotor) and motor.load is not None and motor.load.supply_current == 1.0
    assert not isinstance(SimDrive(41, clock=ManualClock(), settings=settings_for(cfg, "elbow_1b")).motor,
                          ServoMotor)


# -- jog's checks (normal range, calibration, the joint-limit watch) -------------------

def _frames(sim, drive):
    with sim.lock:
        return [(t, i, bytes(f)) for t, i, f in sim.drives[drive].received]


def test_a_position_step_outside_the_normal_range_is_refused_before_anything_is_sent(arm):
    """R5: 3 rad = 1719 counts from 0, normal range [-1314, 1314]: refused like `jog --by`."""
    from sherpa_cli.errors import UsageError

    cfg, sim = arm
    target = resolve_axis(cfg, "elbow_pitch")
    with (
        ArmSession.open(cfg, sim=sim, buses=["can1"]) as session,
        pytest.raises(UsageError, match="outside the joint's normal range"),
    ):
        run_step(session, target, "position", 3.0, duration=0.3, rate=200,
                 settings=MotionSettings.from_config(cfg, ["can1"]))
    node = cfg.drives["elbow_1a"].node
    sent = [f[:4] for t, i, f in _frames(sim, "elbow_1a") if i == 0x300 + node and len(f) == 8]  # sets
    assert not sent, f"written before the refusal: {sent}"
    assert not [f for t, i, f in _frames(sim, "elbow_1a") if i == 0x300 + node and f[:2] == b"BG"]


def test_a_position_step_of_an_uncalibrated_joint_needs_the_override(arm):
    """R5: elbow_stiffness has no absolute encoder and was not homed: refused, unless uncalibrated."""
    from sherpa_cli.errors import SafetyError

    cfg, sim = arm
    target = resolve_axis(cfg, "elbow_stiffness")
    settings = MotionSettings.from_config(cfg, ["can1"])
    with ArmSession.open(cfg, sim=sim, buses=["can1"]) as session:
        with pytest.raises(SafetyError, match=r"refusing a position move.*not"):
            run_step(session, target, "position", 0.05, duration=0.5, rate=200, settings=settings)
        node = cfg.drives["elbow_1b"].node
        assert not [f for t, i, f in _frames(sim, "elbow_1b") if i == 0x300 + node and f[:2] in (b"BG", b"MO")]
        result = run_step(session, target, "position", 0.05, duration=0.5, rate=200, settings=settings,
                          uncalibrated=True)
    assert result.breach is None and result.command.startswith("PA=")


@pytest.mark.parametrize("mode, value", [("torque", 1.0), ("velocity", 0.1)])
def test_the_limit_watch_stops_a_step_that_leaves_the_full_range(arm, mode, value):
    """R5: elbow_pitch stands 10 counts inside its full range [-1370, 1370]; the step pushes it out:
    stopped at once and brought back to the normal range edge 1314 -- in torque mode too, where
    no drive limit acts."""
    cfg, _sim = arm

    def near_the_end(c, sim):
        # the joint stands there (its absolute encoder PY reads it), not only its counter: an absolute
        # joint's PX is re-synced from the encoder when the step starts
        with sim.lock:
            sim.drives["elbow_1a"].motor.counts = 1360
        c.set("PX", 0, 1360)

    arms: list[SimArm] = []
    result = _stepped_step(cfg, mode, value, duration=3.0, before=near_the_end, sim_out=arms)
    with arms[0].lock:
        px = arms[0].drives["elbow_1a"].motor.counts
    assert result.breach is not None and result.breach.joint == "elbow_pitch" and result.breach.side == "high"
    assert result.ended_by.startswith("left its full range")
    assert abs(result.recovered_to - 1314) <= 5 and abs(px - 1314) <= 5
    assert result.as_json()["ok"] is False and result.as_json()["limit"]["recovered_to"] == result.recovered_to
    assert result.stop.drives[0].motor_off
    # the recording ends where the watch stopped the motor: the way back is not part of the step
    _times, pos = result.recording.series("elbow_pitch", "pos")
    assert max(pos) < 1370 / 3600 * 2 * 3.141593 + 0.05


# -- the motor is stopped before the recording is torn down ---------------------------

def _st_before_pdo_restore(sim, drive):
    node = sim.drives[drive].node
    rx = _frames(sim, drive)
    bg = next(t for t, i, f in rx if i == 0x300 + node and f[:2] == b"BG")
    st = next((t for t, i, f in rx if i == 0x300 + node and f[:2] == b"ST" and t > bg), None)
    teardown = [t for t, i, f in rx if t > bg and i == 0x600 + node and f[0] & 0xE0 == 0x20
                and f[1:3] in (b"\x00\x18", b"\x00\x1a")]  # SDO downloads to 0x1800 / 0x1A00
    return st, teardown


def test_the_motor_is_stopped_before_the_recording_is_torn_down(arm):
    cfg, sim = arm
    _step(cfg, sim, "velocity", 0.05, duration=0.3)
    st, teardown = _st_before_pdo_restore(sim, "elbow_1a")
    assert st is not None and teardown and st < teardown[0], "the PDO restore began while JV was still applied"


def test_on_an_error_the_motor_is_stopped_before_the_recording_is_torn_down(arm):
    """R6 on the error path: the step's wait raises (as Ctrl-C would) while JV is applied."""
    import sherpa_cli.ops.step as step_mod

    cfg, sim = arm
    target = resolve_axis(cfg, "elbow_pitch")
    node = cfg.drives["elbow_1a"].node
    after_bg = []

    def sleep(seconds):
        import time

        if after_bg or any(i == 0x300 + node and f[:2] == b"BG" for t, i, f in _frames(sim, "elbow_1a")):
            after_bg.append(seconds)
            if len(after_bg) == 11:  # once: JV applied, the step not settled yet (it needs 0.2 s at least)
                raise KeyboardInterrupt
        time.sleep(seconds)

    with ArmSession.open(cfg, sim=sim, buses=["can1"]) as session, pytest.raises(KeyboardInterrupt):
        step_mod.run_step(session, target, "velocity", 0.05, duration=2.0, rate=200,
                          settings=MotionSettings.from_config(cfg, ["can1"]), sleep=sleep)
    st, teardown = _st_before_pdo_restore(sim, "elbow_1a")
    assert st is not None and teardown and st < teardown[0]
    with sim.lock:
        assert not sim.drives["elbow_1a"].motor_on


def test_cli_step_without_apply_is_a_dry_run(cli, tmp_path):
    out = tmp_path / "dry"
    result = cli("--sim", "log", "step", "elbow_pitch", "--velocity", "0.1", "--for", "1", "-o", str(out))
    assert result.exit_code == 0, result.stderr
    assert "dry run: would record elbow_pitch" in result.stdout and "JV=" in result.stdout
    assert "nothing sent; add --apply to move" in result.stdout
    assert not out.exists()
    far = cli("--sim", "log", "step", "elbow_pitch", "--position", "3", "-o", str(out), "--apply")
    assert far.exit_code == 2 and "outside the joint's normal range" in far.stderr
