"""`Arm.wrench()`: one typed F/T reading from the simulated arm (tests/data/ft-arm.yaml)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from sherpa_cli import Arm
from sherpa_cli.config import load_config
from sherpa_cli.devices.ft_sensor import StatusWord, Wrench
from sherpa_cli.errors import DriveTimeoutError, UsageError

ARM = Path(__file__).resolve().parent / "data" / "ft-arm.yaml"


def test_wrench_returns_a_typed_reading():
    with Arm.open(ARM, sim=True) as arm:
        w = arm.wrench()
        named = arm.wrench("wrist_ft")
    assert isinstance(w, Wrench) and isinstance(w.status, StatusWord) and w.status.ok
    assert w.frame == "wrist_ft_link" and -9.9 < w.fz < -9.7 and w.force == pytest.approx(9.81, abs=0.1)
    assert named.sample == w.sample + 1


def test_wrench_names_a_missing_sensor_and_a_silent_one():
    with Arm.open(ARM, sim=True) as arm, pytest.raises(UsageError, match="'elbow' is no F/T sensor"):
        arm.wrench("elbow")
    cfg = load_config(ARM)
    silent = dataclasses.replace(cfg, sim_ft={"wrist_ft": dataclasses.replace(cfg.sim_ft["wrist_ft"], silent_at=0)})
    with Arm.open(silent, sim=True) as arm, pytest.raises(DriveTimeoutError, match="no reply within 100 ms"):
        arm.wrench(wait_s=0.1)


def test_a_sensor_on_a_bus_the_arm_was_not_opened_on_is_read_after_its_bus_is_opened():
    """`Arm.open(..., buses=["can0"])` with the sensor on can1 raised a bare KeyError."""
    from test_ft_config import BASE

    from sherpa_cli.config import load_config_text
    from sherpa_cli.devices.ft_sensor import open_reader

    cfg = load_config_text(BASE, "ft.yaml")
    with Arm.open(cfg, sim=True, buses=["can0"]) as arm:
        with pytest.raises(UsageError, match="F/T sensor wrist_ft: bus can1 is not open in this session"), \
                open_reader(arm.session, cfg.devices["wrist_ft"]):
            pass
        w = arm.wrench()
    assert isinstance(w, Wrench) and w.status.ok
