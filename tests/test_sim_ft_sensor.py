"""The simulated ATI F/T sensor (sim/ft_sensor.py): payload gravity through the wrist, the wall's
spring, seeded noise, bias drift on the simulator's clock, bias, silence; and on the simulated arm's
bus, read by the tool's reader (tests/data/ft-arm.yaml: wrist_ft on can0 at base 0x010)."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest

from sherpa_cli.bus.session import ArmSession
from sherpa_cli.config import load_config
from sherpa_cli.config.model import SimFtConfig
from sherpa_cli.devices import ft_sensor as ft
from sherpa_cli.errors import DriveTimeoutError
from sherpa_cli.sim.arm import SimArm
from sherpa_cli.sim.clock import ManualClock
from sherpa_cli.sim.ft_sensor import SimFtSensor

ROOT = Path(__file__).resolve().parent.parent
ARM = ROOT / "tests" / "data" / "ft-arm.yaml"
CPR = 3600
QUIET = SimFtConfig(payload_kg=1.0, payload_com=(0.0, 0.0, 0.1), wrist=("wrist",), wall_joint="wrist",
                    wall_position=300, wall_stiffness=100, noise_force=0, noise_torque=0, drift_force=0,
                    drift_torque=0)


def sensor(sim: SimFtConfig = QUIET, positions: dict[str, float] | None = None, clock: ManualClock | None = None):
    cfg = load_config(ARM)
    where = positions if positions is not None else {"wrist": 0.0}
    return SimFtSensor(cfg.devices["wrist_ft"], sim, clock or ManualClock(), cfg.joints, lambda j: where[j])


def decode(s: SimFtSensor, frames) -> ft.Wrench:
    (i5, d5), (i6, d6) = frames
    raw = ft.decode_reply(0x010, ft.Frame(i5, d5), ft.Frame(i6, d6))
    return ft.to_wrench(raw, ft.Calibration(1000, 1000))


def test_gravity_of_the_payload_follows_the_wrist():
    where = {"wrist": 0.0}
    s = sensor(dataclasses.replace(QUIET, wall_joint=None), positions=where)
    assert s.load() == pytest.approx((0, 0, -9.81, 0, 0, 0))
    where["wrist"] = CPR / 4  # tilted 90 degrees about x: the weight along +y, its torque about -x
    fx, fy, fz, tx, ty, tz = s.load()
    assert (fx, fy, fz) == pytest.approx((0, 9.81, 0), abs=1e-9)
    assert (tx, ty, tz) == pytest.approx((-0.981, 0, 0), abs=1e-9)


def test_the_wall_pushes_only_past_its_position():
    where = {"wrist": 300.0}
    s = sensor(dataclasses.replace(QUIET, payload_kg=0), positions=where)
    assert s.load()[2] == 0
    where["wrist"] = 300 + CPR / 360  # one degree past the wall
    assert s.load()[2] == pytest.approx(100 * math.pi / 180)
    low = sensor(dataclasses.replace(QUIET, payload_kg=0, wall_side="low", wall_axis="Fx"), positions={"wrist": 290})
    assert low.load()[0] == pytest.approx(100 * 10 * 2 * math.pi / CPR)


def test_noise_is_seeded_and_drift_follows_the_simulator_clock():
    noisy = dataclasses.replace(QUIET, noise_force=0.5, seed=3)
    a, b = sensor(noisy), sensor(noisy)
    first = [a.reading(0.0) for _ in range(5)]
    assert first == [b.reading(0.0) for _ in range(5)]
    assert len({r[0] for r in first}) == 5  # noise, not a constant
    assert [sensor(dataclasses.replace(noisy, seed=4)).reading(0.0) for _ in range(1)] != first[:1]
    clock = ManualClock()
    drifting = sensor(dataclasses.replace(QUIET, drift_force=0.1, drift_torque=0.01), clock=clock)
    clock.advance(10.0)
    fx, _, fz, tx, _, _ = drifting.reading(clock.now())
    assert (fx, fz, tx) == pytest.approx((1.0, -9.81 + 1.0, 0.1))


def test_request_and_bias_frames_on_the_base_id():
    clock = ManualClock()
    s = sensor(dataclasses.replace(QUIET, drift_force=0.1), clock=clock)
    assert s.receive(0x011, b"\x02") == [] and s.receive(0x010, b"") == []
    frames = s.receive(0x010, b"\x02")
    assert [f[0] for f in frames] == [0x015, 0x016]
    w = decode(s, frames)
    assert (w.fz, w.sample, w.status.ok) == (-9.81, 0, True)
    clock.advance(5.0)
    assert s.receive(0x010, b"\x04") == [] and s.biased
    w = decode(s, s.receive(0x010, b"\x02"))
    assert w.axes() == dict.fromkeys(ft.AXES, 0.0) and w.sample == 1
    clock.advance(5.0)  # the drift goes on after the bias
    assert decode(s, s.receive(0x010, b"\x02")).fx == pytest.approx(0.5)


def test_a_silent_sensor_answers_nothing():
    clock = ManualClock()
    s = sensor(dataclasses.replace(QUIET, silent_at=1.0), clock=clock)
    assert s.receive(0x010, b"\x02")
    clock.advance(1.0)
    assert s.receive(0x010, b"\x02") == []


def test_bias_survives_between_sim_commands_and_a_power_cycle_forgets_it():
    s = sensor()
    s.receive(0x010, b"\x04")
    again = sensor()
    again.restore_ram(s.ram_snapshot())
    assert again.biased and again.bias == s.bias
    with pytest.raises(ValueError):
        again.restore_ram({"ram": True})


# -- on the simulated arm's bus ---------------------------------------------------------------------

def test_the_tool_reads_the_simulated_sensor_on_its_bus():
    cfg = load_config(ARM)
    dev = cfg.devices["wrist_ft"]
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as session:
        with ft.open_reader(session, dev, wait_s=2.0) as reader:
            w = reader.read()
            assert w.frame == "wrist_ft_link" and w.status.ok
            assert w.fz == pytest.approx(-9.81 * math.cos(session.sim.joint_position("wrist") * 2 * math.pi / CPR),
                                         abs=0.1)
            reader.bias()
            assert reader.read().force < 0.1
        with session.sim.lock:
            sim = session.sim.ft_sensors["wrist_ft"][1]
            assert sim.requests == 2 and sim.bias_commands == 1


def test_a_silent_simulated_sensor_times_out():
    cfg = load_config(ARM)
    cfg = dataclasses.replace(cfg, sim_ft={"wrist_ft": dataclasses.replace(cfg.sim_ft["wrist_ft"], silent_at=0.0)})
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as session, \
            ft.open_reader(session, cfg.devices["wrist_ft"], wait_s=0.3) as reader, \
            pytest.raises(DriveTimeoutError, match=r"F/T sensor wrist_ft \(base 0x010\): no reply within 300 ms"):
        reader.read()


def test_the_force_watch_sees_the_wrist_press_into_the_simulated_wall():
    """The chain the guard will use, without the guard: the simulated wrist stands past the wall, the
    tool's reader asks the simulated sensor on the bus, the watch names the force."""
    from sherpa_cli.motion.force_watch import ForceLimitError, ForceWatch

    cfg = load_config(ARM)
    dev = cfg.devices["wrist_ft"]
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as session, \
            ft.open_reader(session, dev, wait_s=2.0) as reader:
        watch = ForceWatch.for_device(reader, dev, silent_s=5.0)
        with session.sim.lock:
            session.sim.drives["wrist_drive"].restore_position(280.0)  # 20 counts short of the wall
        assert watch.check() is None
        with session.sim.lock:
            session.sim.drives["wrist_drive"].restore_position(500.0)  # 200 counts past it: about 35 N along z
        err = watch.check()
    assert isinstance(err, ForceLimitError) and err.axis == "Fz"
    tilt = 500 * 2 * math.pi / CPR
    assert err.value == pytest.approx(100 * 200 * 2 * math.pi / CPR - 9.81 * math.cos(tilt), abs=0.1)
    assert err.message.startswith("force limit: F/T sensor wrist_ft read |F| ") and "> 20 N (mostly Fz +" in err.message
