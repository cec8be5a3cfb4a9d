"""The load model (sim/load.py) and the one servo model (sim/servo.py), against the seed's figures
(chapter 9) through the seed profile configs/sim-profiles/seed-figures.yaml. Time is simulated: the
drive-level tests step a ManualClock, `--sim log step` runs on stepped time (docs/log.md)."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import pytest

from sherpa_cli.config import load_config
from sherpa_cli.elmo.codec import encode_execute, encode_set
from sherpa_cli.sim.arm import settings_for
from sherpa_cli.sim.clock import ManualClock
from sherpa_cli.sim.drive import SimDrive
from sherpa_cli.sim.load import Load
from sherpa_cli.sim.settings import SimSettings

ROOT = Path(__file__).resolve().parent.parent
ARM = ROOT / "configs" / "sherpa-arm.yaml"
SEED = ROOT / "configs" / "sim-profiles" / "seed-figures.yaml"


def _drive(settings: SimSettings, clock: ManualClock, node: int = 10) -> SimDrive:
    drive = SimDrive(node, clock=clock, settings=settings)
    drive.receive(0x000, bytes([0x01, node]))
    return drive


def _set(drive: SimDrive, letters: str, value: float, index: int = 0) -> None:
    drive.receive(0x300 + drive.node, encode_set(letters, index, value))


def _run(drive: SimDrive, clock: ManualClock, seconds: float, dt: float = 0.001) -> list[tuple[float, float, float]]:
    """(t, position counts, IQ) every dt."""
    out = []
    for _ in range(round(seconds / dt)):
        clock.advance(dt)
        drive.tick()
        out.append((clock.now(), drive.motor.position, float(drive.read_param("IQ"))))
    return out


def _torque(settings: SimSettings, amps: float, seconds: float) -> list[tuple[float, float, float]]:
    clock = ManualClock()
    drive = _drive(settings, clock)
    _set(drive, "UM", 1)
    _set(drive, "TC", amps)
    _set(drive, "MO", 1)
    return _run(drive, clock, seconds)


def test_one_ampere_on_the_shoulder_settles_near_half_a_radian_per_second_and_stays_in_range():
    cfg = load_config(ARM)
    settings = settings_for(cfg, "shoulder_1a")
    k = settings.counts_per_rad
    trace = _torque(settings, 1.0, 1.0)
    speed = (trace[-1][1] - trace[-101][1]) / 0.1 / k
    assert speed == pytest.approx(0.5, rel=0.05)
    lo, hi = cfg.joints["shoulder_yaw"].normal_range
    assert all(lo <= x <= hi for _, x, _ in trace)


def test_the_load_model_limits():
    load = Load(supply_current=1.0)
    assert load.current(50.0, 0.0) == 20.0  # the drive's peak
    assert load.current(-50.0, 0.0) == -20.0
    assert load.current(10.0, 5.0) == pytest.approx(  # the 25 W supply at 5 rad/s (EMF 20 V)
        (-20 + math.sqrt(400 + 4 * 25)) / 2)
    assert load.current(-10.0, 5.0) == -10.0  # braking: the supply does not limit it
    assert Load().current(10.0, 6.0) == 1.0  # (25 V - 24 V EMF) / 1 ohm
    assert Load().step(0.3, 0.0, 0.0, 0.001) == 0.0  # 0.3 N m < Coulomb 0.4: static friction holds
    falling = Load(gravity=5.0)
    assert falling.step(0.0, 0.0, 0.0, 0.01) < 0  # gravity at horizontal pulls a pitch joint down
    assert falling.step(0.0, 0.0, math.pi / 2, 0.01) == 0.0  # upright: no gravity torque
    with pytest.raises(ValueError, match="inertia"):
        Load(inertia=0)


def test_gravity_is_a_named_per_joint_setting(tmp_path):
    text = ARM.read_text(encoding="utf-8") + "sim:\n  drives:\n    elbow_1a: {gravity: 3.0, coulomb: 0.2}\n"
    path = tmp_path / "arm.yaml"
    path.write_text(text, encoding="utf-8")
    cfg = load_config(path)
    settings = settings_for(cfg, "elbow_1a")
    assert (settings.gravity, settings.coulomb) == (3.0, 0.2)
    trace = _torque(settings, 0.0, 0.3)  # motor on, no torque: the elbow sags
    assert trace[-1][1] < -5
    bad = path.read_text(encoding="utf-8").replace("gravity: 3.0", "inertia: -1")
    path.write_text(bad, encoding="utf-8")
    with pytest.raises(Exception, match="inertia"):
        load_config(path)


def test_no_simulated_current_exceeds_the_drive_peak():
    """The kinematic model's arrival used to read -32 A on a 20 A drive; the servo model is clamped."""
    for settings in (SimSettings(), SimSettings(servo_bandwidth_hz=30, servo_damping=0.3),
                     SimSettings(lag_s=0.008)):
        clock = ManualClock()
        drive = _drive(settings, clock)
        _set(drive, "AC", 1_000_000)  # 100 A worth of the kinematic model's acceleration
        _set(drive, "DC", 1_000_000)
        _set(drive, "SP", 3000)  # within what the back-EMF leaves at 25 V
        _set(drive, "PA", 1500)
        _set(drive, "MO", 1)
        clock.advance(settings.mo_settle_s)
        drive.receive(0x300 + drive.node, encode_execute("BG"))
        trace = _run(drive, clock, 1.5)
        peak = max(abs(i) for _, _, i in trace)
        assert 1.0 < peak <= settings.max_current, settings
        assert abs(trace[-1][1] - 1500) < 2, settings


def test_lag_is_the_servo_model_trailing_its_profile_by_tau_at_speed():
    clock = ManualClock()
    lagging, perfect = _drive(SimSettings(lag_s=0.02), clock, 10), _drive(SimSettings(), clock, 11)
    for d in (lagging, perfect):
        _set(d, "JV", 1000)
        _set(d, "MO", 1)
    clock.advance(0.5)
    for d in (lagging, perfect):
        d.tick()
        d.receive(0x300 + d.node, encode_execute("BG"))
    for _ in range(500):
        clock.advance(0.001)
        lagging.tick(), perfect.tick()
    behind = perfect.motor.position - lagging.motor.position
    assert behind == pytest.approx(0.02 * 1000, rel=0.15)  # tau x v


# -- the seed profile through the CLI -----------------------------------------------------------------

def _csv(path: Path) -> list[dict[str, float]]:
    with path.open(encoding="utf-8") as handle:
        return [{k: float(v) for k, v in row.items()} for row in csv.DictReader(handle)]


def test_seed_profile_torque_step_reaches_half_a_radian_per_second(cli, tmp_path):
    """Fig. 9.8/9.9: a 1 A torque step on the shoulder rotation, close to 0.5 rad/s."""
    out = tmp_path / "fig9-8"
    result = cli("--config", str(SEED), "--sim", "log", "step", "shoulder_yaw", "--torque", "1", "--for", "2",
                 "-o", str(out), "--apply")
    assert result.exit_code == 0, result.stderr
    rows = _csv(out / "recording.csv")
    end = rows[-1]["time_s"]
    steady = [r["shoulder_yaw.vel_rad_s"] for r in rows if end - 0.5 <= r["time_s"] <= end]
    assert sum(steady) / len(steady) == pytest.approx(0.5, rel=0.2)
    assert max(abs(r["shoulder_yaw.cur_a"]) for r in rows) <= 1.0 + 1e-6


def _position_step(cli, tmp_path: Path, supply: float) -> list[dict[str, float]]:
    text = SEED.read_text(encoding="utf-8").replace("shoulder_1a: {supply_current_limit: 1.0,",
                                                    f"shoulder_1a: {{supply_current_limit: {supply},")
    config = tmp_path / f"seed-{supply:g}A.yaml"
    config.write_text(text, encoding="utf-8")
    out = tmp_path / f"step-{supply:g}A"
    assert cli("--config", str(config), "sim", "--reset-state").exit_code == 0  # a fresh arm: the joint at 0
    result = cli("--config", str(config), "--sim", "log", "step", "shoulder_yaw", "--position", "1", "--uncalibrated",
                 "--for", "4", "-o", str(out), "--apply")
    assert result.exit_code == 0, result.stderr
    return _csv(out / "recording.csv")


def test_seed_profile_one_ampere_supply_slows_the_move_as_in_fig_9_4(cli, tmp_path):
    """Fig. 9.4/9.5: with the 1 A supply the speed drops early (the supply cannot deliver the power: its
    bus sags to the 0.5 rad/s a 1 A supply holds); with a 20 A supply it holds the profile's speed until
    the deceleration; both arrive."""
    weak, strong = _position_step(cli, tmp_path, 1.0), _position_step(cli, tmp_path, 20.0)

    def peak_speed(rows):
        return max(abs(r["shoulder_yaw.vel_rad_s"]) for r in rows)

    def reach(rows, level):
        return next(r["time_s"] for r in rows if r["shoulder_yaw.pos_rad"] >= level)

    assert peak_speed(weak) < 0.6 * peak_speed(strong)
    assert reach(weak, 0.9) > reach(strong, 0.9) + 0.15
    for rows in (weak, strong):
        assert rows[-1]["shoulder_yaw.pos_rad"] == pytest.approx(1.0, abs=0.01)
        assert max(abs(r["shoulder_yaw.cur_a"]) for r in rows) <= 20.0


def test_seed_profile_sigma_move_shows_a_delta_excursion_that_returns(cli):
    """Fig. 9.10: a Σ move of the mismatched pair moves Δ "a bit", and Δ ends where it started."""
    result = cli("--config", str(SEED), "--sim", "--json", "diffdrive", "move", "shoulder_diff", "--sigma", "1",
                 "--naive", "--apply")
    assert result.exit_code == 0, result.stderr
    report = json.loads(result.stdout)
    excursion = report["coupling"]["held_excursion"]["rad"]
    assert report["coupling"]["held"] == "shoulder_roll" and 0.01 < excursion < 0.15
    start_a, start_b = report["motors_start"] if isinstance(report["motors_start"], list) else \
        report["motors_start"].values()
    end_a, end_b = report["motors_end"] if isinstance(report["motors_end"], list) else report["motors_end"].values()
    assert abs((end_a - end_b) - (start_a - start_b)) <= 2  # Δ back where it was
