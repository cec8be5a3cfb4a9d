"""The simulated servo loop runs on the gains the drive holds (sim/servo.py): KP[2], KI[2], KP[3] in RAM
change the step response, the factory gains give the configured loop, and the seed profile's shoulder pair
shows its mismatch. Time is a ManualClock."""

from __future__ import annotations

from pathlib import Path

import pytest

from sherpa_cli.config import load_config
from sherpa_cli.elmo.codec import encode_execute, encode_set
from sherpa_cli.sim.arm import settings_for
from sherpa_cli.sim.clock import ManualClock
from sherpa_cli.sim.drive import SimDrive
from sherpa_cli.sim.params import factory_ram
from sherpa_cli.sim.servo import REFERENCE_GAINS
from sherpa_cli.sim.settings import SimSettings

SEED = Path(__file__).resolve().parent.parent / "configs" / "sim-profiles" / "seed-figures.yaml"


def _drive(settings: SimSettings, clock: ManualClock, node: int = 10) -> SimDrive:
    drive = SimDrive(node, clock=clock, settings=settings)
    drive.receive(0x000, bytes([0x01, node]))
    return drive


def _set(drive: SimDrive, letters: str, value: float, index: int = 0) -> None:
    drive.receive(0x300 + drive.node, encode_set(letters, index, value))


def _behind_at_speed(settings: SimSettings, gains: dict[str, float], speed: int = 1000) -> float:
    """Counts a jog at ``speed`` cnt/s trails a perfect (kinematic) drive after 0.5 s."""
    clock = ManualClock()
    servo, perfect = _drive(settings, clock, 10), _drive(SimSettings(), clock, 11)
    for key, value in gains.items():
        letters, index = key[:2], int(key[3])
        _set(servo, letters, value, index)
    for d in (servo, perfect):
        _set(d, "JV", speed)
        _set(d, "MO", 1)
    clock.advance(0.5)
    for d in (servo, perfect):
        d.tick()
        d.receive(0x300 + d.node, encode_execute("BG"))
    for _ in range(500):
        clock.advance(0.001)
        servo.tick(), perfect.tick()
    return perfect.motor.position - servo.motor.position


def _overshoot(gains: dict[str, float]) -> float:
    """Overshoot (share of the step) of a 10-count position step (small: the loop's current stays below
    the drive's peak, so the response is the linear loop's) of a 20 Hz, damping 0.5 servo loop."""
    clock = ManualClock()
    d = _drive(SimSettings(servo_bandwidth_hz=20, servo_damping=0.5), clock)
    for key, value in gains.items():
        _set(d, key[:2], value, int(key[3]))
    _set(d, "AC", 10_000_000), _set(d, "DC", 10_000_000), _set(d, "SP", 1_000_000)
    _set(d, "PA", 10)
    _set(d, "MO", 1)
    clock.advance(0.5)
    d.tick()
    d.receive(0x300 + d.node, encode_execute("BG"))
    peak = 0.0
    for _ in range(400):
        clock.advance(0.0005)
        d.tick()
        peak = max(peak, d.motor.position)
    return (peak - 10) / 10


def test_reference_gains_are_the_factory_gains():
    ram = factory_ram(6)
    assert {k: ram[k] for k in REFERENCE_GAINS} == REFERENCE_GAINS


def test_the_factory_gains_give_the_configured_lag_and_kp3_divides_it():
    assert _behind_at_speed(SimSettings(lag_s=0.02), {}) == pytest.approx(20, rel=0.15)  # tau x v
    doubled = _behind_at_speed(SimSettings(lag_s=0.02), {"KP[3]": 2 * REFERENCE_GAINS["KP[3]"]})
    assert doubled == pytest.approx(10, rel=0.15)  # tau / 2


def test_kp2_damps_the_position_step_and_kp3_makes_it_ring():
    base = _overshoot({})
    assert base > 0.1  # damping 0.5 overshoots
    softer = _overshoot({"KP[2]": 4 * REFERENCE_GAINS["KP[2]"]})  # kv x4: damping x2 -> 1, no overshoot
    assert softer < 0.2 * base
    stiffer = _overshoot({"KP[3]": 4 * REFERENCE_GAINS["KP[3]"]})  # kp x4: damping / 2, more overshoot
    assert stiffer > 1.1 * base


def test_a_gain_written_while_moving_acts_at_once():
    settings = SimSettings(lag_s=0.02)
    assert _behind_at_speed(settings, {"KP[3]": 0.5 * REFERENCE_GAINS["KP[3]"]}) == pytest.approx(40, rel=0.15)


def test_the_seed_profile_pair_is_mismatched_in_its_loops():
    cfg = load_config(SEED)
    a = _behind_at_speed(settings_for(cfg, "shoulder_2a"), {})
    b = _behind_at_speed(settings_for(cfg, "shoulder_2b"), {})
    assert a > 2 * b + 3  # the same gains, the same jog: a trails, b does not
