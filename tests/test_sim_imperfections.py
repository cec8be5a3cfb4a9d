"""The real arm's imperfections in the simulator (docs/simulator.md "Imperfections"): a supply whose
voltage sags, a speed estimated from the encoder's whole counts, cogging, gravity on a pair's Σ pitch.
Each is a named setting, off by default and on in the seed-figures profile only; drive-level tests
step a ManualClock (no wall time)."""

from __future__ import annotations

import math
import re
import statistics
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from sherpa_cli.config import load_config
from sherpa_cli.elmo.codec import encode_execute, encode_set
from sherpa_cli.errors import ConfigError
from sherpa_cli.sim.arm import SimArm, settings_for
from sherpa_cli.sim.clock import ManualClock
from sherpa_cli.sim.drive import SimDrive
from sherpa_cli.sim.load import Load
from sherpa_cli.sim.settings import SimSettings
from sherpa_cli.sim.speed_estimate import SpeedEstimate
from sherpa_cli.sim.supply import Supply

ROOT = Path(__file__).resolve().parent.parent
ARM = ROOT / "configs" / "sherpa-arm.yaml"
SEED = ROOT / "configs" / "sim-profiles" / "seed-figures.yaml"
IMPERFECTIONS = ("bus_capacitance", "supply_resistance", "velocity_window_s", "cogging_torque", "cogging_cycles")
# the seed profile's shoulder rotation without the imperfections: what a test compares against
SHOULDER = dict(supply_current_limit=1.0, supply_voltage=25.0, servo_bandwidth_hz=5.0, servo_damping=0.7)


def _drive(settings: SimSettings, clock: ManualClock, node: int = 10) -> SimDrive:
    drive = SimDrive(node, clock=clock, settings=settings)
    drive.receive(0x000, bytes([0x01, node]))
    return drive


def _set(drive: SimDrive, letters: str, value: float) -> None:
    drive.receive(0x300 + drive.node, encode_set(letters, 0, value))


def _start(drive: SimDrive, clock: ManualClock, unit_mode: int, **params: float) -> None:
    _set(drive, "UM", unit_mode)
    for key, value in params.items():
        _set(drive, key, value)
    _set(drive, "MO", 1)
    clock.advance(drive.settings.mo_settle_s)
    drive.tick()
    if unit_mode != 1:
        drive.receive(0x300 + drive.node, encode_execute("BG"))


def _vx(drive: SimDrive, clock: ManualClock, seconds: float) -> list[float]:
    """VX (rad/s) every ms for ``seconds``."""
    k, out = drive.settings.counts_per_rad, []
    for _ in range(round(seconds / 0.001)):
        clock.advance(0.001)
        drive.tick()
        out.append(float(drive.read_param("VX")) / k)
    return out


def _move(settings: SimSettings) -> list[float]:
    """The seed's Fig. 9.4 move: 1 rad as fast as the recipe's profile lets it, VX every ms."""
    clock = ManualClock()
    drive = _drive(settings, clock)
    _start(drive, clock, 5, SP=1450, AC=12000, DC=12000, PA=round(settings.counts_per_rad))
    return _vx(drive, clock, 0.6)


def test_every_imperfection_is_off_by_default_and_on_only_in_the_seed_profile():
    default = SimSettings()
    assert all(getattr(default, key) == 0 for key in IMPERFECTIONS)
    arm = load_config(ARM)
    assert all(getattr(settings_for(arm, name), key) == 0 for name in arm.drives for key in IMPERFECTIONS)
    seed = load_config(SEED)
    for name in ("shoulder_1a", "shoulder_1a_20a", "shoulder_2a", "shoulder_2b"):
        s = settings_for(seed, name)
        assert s.velocity_window_s > 0 and s.cogging_torque > 0, name
        assert (s.bus_capacitance > 0) == (name in ("shoulder_1a", "shoulder_1a_20a")), name
    assert settings_for(seed, "shoulder_2a").gravity > 0  # the pair carries the pitch


def test_a_sagging_one_ampere_supply_makes_a_fast_move_drop_its_speed_after_about_100_ms():
    """Seed 9.1/9.5: the bus capacitor's charge carries the move's start, then the bus sags and the
    speed falls towards the 0.5 rad/s a 1 A supply holds; a stiff 1 A supply's speed levels off and never falls."""
    sagging = _move(SimSettings(**SHOULDER, bus_capacitance=0.002))
    stiff = _move(SimSettings(**SHOULDER))
    peak = max(range(len(sagging)), key=lambda i: sagging[i])
    assert 0.08 <= (peak + 1) * 0.001 <= 0.15
    assert min(sagging[peak:400]) < 0.5 * sagging[peak]  # a falling speed while the profile still cruises
    # a stiff 1 A supply: the speed levels off (1.8 rad/s) and holds until the profile decelerates
    assert all(v > 0.95 * max(stiff[:i + 1]) for i, v in enumerate(stiff[100:400], start=100))
    # a 20 A supply with the same capacitor never sags on this move
    strong = SimSettings(**{**SHOULDER, "supply_current_limit": 20.0}, bus_capacitance=0.002)
    clock = ManualClock()
    drive = _drive(strong, clock)
    _start(drive, clock, 5, SP=1450, AC=12000, DC=12000, PA=573)
    _vx(drive, clock, 0.3)
    assert drive.motor.supply is not None and drive.motor.supply.bus == pytest.approx(25.0)


def test_the_sagging_bus_holds_the_supply_current_and_recovers():
    load, supply = Load(), Supply(voltage=25.0, current_limit=1.0, capacitance=0.002)
    supply.drain(load, 0.5, 1.0, 0.01)  # 2.5 W: the supply holds its voltage
    assert supply.bus == 25.0
    for _ in range(200):  # 4 A at 2 rad/s: 48 W from a 25 W supply
        supply.drain(load, supply.current(load, 4.0, 2.0), 2.0, 0.001)
    assert supply.bus < 15.0
    assert load.resistance * supply.current(load, 4.0, 2.0) + load.back_emf * 2.0 <= supply.bus + 1e-9
    for _ in range(200):
        supply.drain(load, 0.0, 0.0, 0.001)  # no load: the supply's 1 A recharges it, never above 25 V
    assert supply.bus == 25.0
    with pytest.raises(ValueError, match="capacitance"):
        Supply(voltage=25.0, current_limit=1.0, capacitance=0.0)


@given(st.floats(min_value=1.0, max_value=5000.0), st.sampled_from([0.01, 0.05, 0.1]))
def test_the_speed_estimate_is_whole_counts_over_its_window(speed, window):
    est = SpeedEstimate(window)
    est.reset(0.0, 0)
    t, counts, seen = 0.0, 0, set()
    for i in range(1, 400):
        t = i * 0.001
        counts = math.floor(speed * t)
        est.sample(t, counts)
        if t >= window:
            value = est.value(t, counts)
            assert abs(value - speed) <= 1 / window + 1e-6  # within one count of the window
            assert round(value * window, 6) == round(value * window)  # a whole number of counts
            seen.add(value)
    assert len(seen) <= 3 or speed * window < 1


def test_a_quantised_speed_has_a_ripple_a_perfect_one_has_none():
    def ripple(settings: SimSettings) -> tuple[float, float]:
        clock = ManualClock()
        drive = _drive(settings, clock)
        _start(drive, clock, 2, JV=57, AC=12000, DC=12000)  # 0.1 rad/s (seed Fig. 9.3)
        tail = _vx(drive, clock, 1.5)[500:]
        return statistics.mean(tail), statistics.stdev(tail)

    mean, sd = ripple(SimSettings(velocity_window_s=0.05))
    assert mean == pytest.approx(0.0995, rel=0.05) and sd > 0.005
    mean, sd = ripple(SimSettings())
    assert mean == pytest.approx(0.0995, rel=0.01) and sd < 1e-9


def _torque_step(settings: SimSettings) -> list[float]:
    clock = ManualClock()
    drive = _drive(settings, clock)
    _start(drive, clock, 1, TC=1.0)
    return _vx(drive, clock, 1.5)[500:]


def test_cogging_makes_a_torque_step_not_very_constant_and_is_the_same_for_the_same_seed():
    """Seed Fig. 9.8: "close to 0.5 rad/s but it is not very constant"."""
    rough = SimSettings(cogging_torque=0.1, cogging_cycles=24, seed=1)
    speeds = _torque_step(rough)
    assert statistics.mean(speeds) == pytest.approx(0.5, rel=0.1)
    assert statistics.stdev(speeds) > 0.025  # above 5 % of 0.5 rad/s
    assert statistics.stdev(_torque_step(SimSettings())) < 1e-3
    assert _torque_step(rough) == speeds  # deterministic
    assert rough.load().cogging_phase != SimSettings(cogging_torque=0.1, cogging_cycles=24, seed=2).load().cogging_phase


def test_gravity_on_a_pair_acts_on_its_sigma_angle(tmp_path):
    cfg = load_config(SEED)
    arm = SimArm(cfg, {"can0": {"interface": "virtual", "channel": f"imperfect-{tmp_path.name}"}}, clock=ManualClock())
    a, b = arm.drives["shoulder_2a"], arm.drives["shoulder_2b"]
    k = cfg.joints["shoulder_pitch"].cpr / (2 * math.pi)
    assert a.motor.gravity_angle is not None and b.motor.gravity_angle is not None
    a.motor.counts, b.motor.counts = 500, 1000
    assert a.motor.gravity_angle() == pytest.approx(1500 / k) == b.motor.gravity_angle()


@pytest.mark.parametrize(("key", "value", "message"), [
    ("bus_capacitance", -0.001, "bus_capacitance -0.001 is out of range; expected 0..10 F"),
    ("velocity_window", 100, "velocity_window 100.0 is out of range; expected 0..60 s"),
    ("cogging_cycles", -3, "cogging_cycles -3 is out of range; expected 0..100000 per turn"),
    ("cogging_torque", ".nan", "cogging_torque nan is not a finite number"),
])
def test_a_bad_imperfection_is_one_clear_message_with_its_place(tmp_path, key, value, message):
    text = re.sub(rf"{key}: [-0-9.]+", f"{key}: {value}", SEED.read_text(encoding="utf-8"), count=1)
    assert f"{key}: {value}" in text
    path = tmp_path / "seed.yaml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ConfigError) as err:
        load_config(path)
    assert message in str(err.value) and "seed.yaml:" in str(err.value) and "shoulder_1a" in str(err.value)


def test_target_skew_is_a_drive_that_stores_every_target_off(tmp_path):
    text = re.sub(r"(shoulder_2a: \{supply_current_limit: 1\.0)", r"\1, target_skew: -7", SEED.read_text(encoding="utf-8"))
    path = tmp_path / "seed.yaml"
    path.write_text(text, encoding="utf-8")
    assert settings_for(load_config(path), "shoulder_2a").store_skew == (("PA", -7),)
    assert settings_for(load_config(SEED), "shoulder_2a").store_skew == ()
