"""`sherpa stop`: every (or the named) drive stopped and switched off, no confirmation, buses at once."""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import canopen
import pytest

from sherpa_cli.bus.session import ArmSession, resolve_target
from sherpa_cli.bus.targets import drive_refs
from sherpa_cli.config import load_config
from sherpa_cli.config.model import SimDriveConfig
from sherpa_cli.motion.settings import MotionSettings
from sherpa_cli.ops.stop import stop_drives
from sherpa_cli.sim.arm import SimArm

ARM = Path(__file__).resolve().parent.parent / "configs" / "sherpa-arm.yaml"


@pytest.mark.golden
@pytest.mark.realbus
def test_stop_everything_golden(arm_golden):
    arm_golden("stop-all", ["stop"], exit_code=0)


def test_stop_stops_moving_drives_and_leaves_the_others_alone(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path))
    monkeypatch.setattr(canopen.Network, "NOTIFIER_CYCLE", 0.02)
    cfg = load_config(ARM)
    # wrist_2a's firmware refuses ST in speed mode: stopped with JV=0 + BG instead
    cfg = dataclasses.replace(cfg, sim={"wrist_2a": SimDriveConfig(st_refused_in_speed_mode=True)})
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg), buses=["can1", "can2"]) as s:
        for name, um in (("elbow_1a", 5), ("wrist_2a", 2)):
            c = s.client(resolve_target(cfg, name))
            c.nmt_start()
            c.set("UM", 0, um)
            c.motor_on()
            c.set("JV", 0, 300)
            c.execute("BG")
        time.sleep(0.1)
        refs = drive_refs(cfg, ["elbow_pitch", "wrist_2", "wrist_3"])
        results = stop_drives(s, refs, MotionSettings.from_config(cfg))
        states = {n: (s.sim.drives[n].motor_on, s.sim.drives[n].motor.v) for n in ("elbow_1a", "wrist_2a")}
        wrist_3a_sets = [d for _, cid, d in s.sim.drives["wrist_3a"].received if cid == 0x300 + 70 and len(d) == 8]
    by = {r.drive: r for r in results}
    assert (by["elbow_1a"].stopped_by, by["elbow_1a"].standstill, by["elbow_1a"].motor_off) == ("ST", True, True)
    assert (by["wrist_2a"].stopped_by, by["wrist_2a"].motor_off) == ("JV=0 + BG", True)
    assert (by["wrist_3a"].stopped_by, by["wrist_3a"].motor_off) == ("motor was off", False)
    assert states == {"elbow_1a": (False, 0.0), "wrist_2a": (False, 0.0)}
    assert wrist_3a_sets == []  # a motor that is off gets no write
    assert all(r.ok for r in results)


def test_a_silent_drive_makes_stop_exit_1(cli, tmp_path, monkeypatch):
    import yaml

    data = yaml.safe_load(ARM.read_text())
    data["sim"] = {"drives": {"elbow_1b": {"die_at": 0.0}}}
    path = tmp_path / "arm.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    result = cli("--sim", "--config", str(path), "stop", "elbow_1a", "elbow_1b")
    assert result.exit_code == 1, result.transcript()
    assert "1 drive not confirmed stopped: elbow_1b" in result.stderr
    assert "elbow_1a" in result.stdout and "motor off" in result.stdout


@pytest.mark.parametrize("failing", ["UM", "ST", "nmt"])
def test_a_failed_step_never_skips_mo0(tmp_path, monkeypatch, failing):
    from sherpa_cli.errors import DriveTimeoutError
    from sherpa_cli.ops.stop import stop_one

    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path))
    monkeypatch.setattr(canopen.Network, "NOTIFIER_CYCLE", 0.02)
    cfg = load_config(ARM)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg), buses=["can1"]) as s:
        ref = resolve_target(cfg, "elbow_1a")
        c = s.client(ref)
        c.nmt_start()
        c.set("UM", 0, 5)
        c.motor_on()
        c.set("JV", 0, 300)
        c.execute("BG")
        real_get, real_execute = c.get, c.execute

        def timeout(*a, **k):
            raise DriveTimeoutError(f"{failing}: no reply")
        if failing == "UM":
            monkeypatch.setattr(c, "get", lambda letters, *a: timeout() if letters == "UM" else real_get(letters, *a))
        elif failing == "ST":
            monkeypatch.setattr(c, "execute", lambda cmd: timeout() if cmd == "ST" else real_execute(cmd))
        else:
            monkeypatch.setattr(c, "nmt_start", timeout)
        settings = dataclasses.replace(MotionSettings.from_config(cfg), standstill_timeout=0.3)
        r = stop_one(c, ref, settings)
        motor_on = s.sim.drives["elbow_1a"].motor_on
    assert r.motor_off and not motor_on, r
    if failing == "UM":
        assert r.stopped_by == "TC=0 + ST"  # unreadable UM: stopped as in torque mode
    elif failing == "ST":
        assert r.stopped_by == "not stopped" and "stop: ST: no reply" in r.problems


def _can0_cannot_open(monkeypatch):
    """A seam test of the best effort: opening bus can0 fails as a missing adapter does."""
    from sherpa_cli.bus import links
    from sherpa_cli.errors import CommunicationError

    real = links.open_bus

    def open_bus(bus_cfg):
        if bus_cfg.name == "can0":
            raise CommunicationError("bus can0 (socketcan:can0): cannot open: [Errno 19] No such device")
        return real(bus_cfg)
    monkeypatch.setattr(links, "open_bus", open_bus)


def test_stop_with_one_bus_unreachable_still_stops_the_others(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path))
    monkeypatch.setattr(canopen.Network, "NOTIFIER_CYCLE", 0.02)
    _can0_cannot_open(monkeypatch)
    cfg = load_config(ARM)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg), best_effort=True) as s:
        assert sorted(s.unreachable) == ["can0"] and "can0" not in s.links
        c = s.client(resolve_target(cfg, "elbow_1a"))
        c.nmt_start()
        c.set("UM", 0, 5)
        c.motor_on()
        c.set("JV", 0, 300)
        c.execute("BG")
        refs = drive_refs(cfg, None)
        results = stop_drives(s, refs, MotionSettings.from_config(cfg))
        moving = s.sim.drives["elbow_1a"].motor_on
    by = {r.drive: r for r in results}
    assert moving is False
    assert (by["elbow_1a"].stopped_by, by["elbow_1a"].motor_off) == ("ST", True)
    on_can0 = [r for r in results if r.address.startswith("can0:")]
    assert on_can0 and all(not r.reached and r.stopped_by == "not reached" for r in on_can0)
    assert all("No such device" in r.problems[0] for r in on_can0)
    assert all(r.reached and r.ok for r in results if not r.address.startswith("can0:"))


def test_a_session_without_best_effort_still_refuses_an_unreachable_bus(tmp_path, monkeypatch):
    from sherpa_cli.errors import CommunicationError

    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path))
    _can0_cannot_open(monkeypatch)
    cfg = load_config(ARM)
    with pytest.raises(CommunicationError, match="can0"), ArmSession.open(cfg, sim=SimArm.in_process(cfg)):
        pass


def test_cli_stop_reports_partly_stopped_naming_the_unreached_drives(cli, monkeypatch):
    _can0_cannot_open(monkeypatch)
    result = cli("--sim", "stop")
    assert result.exit_code == 1, result.transcript()
    assert "partly stopped" in result.stderr and "not reached (bus could not be opened)" in result.stderr
    assert "NOT REACHED" in result.stdout and "motor off" in result.stdout
    assert "Traceback" not in result.stderr


def test_stop_with_no_bus_reachable_says_nothing_was_stopped_names_every_bus_and_the_power(cli):
    """It used to print only the socket error (exit 3), not that nothing was stopped, nor
    the other buses, nor what is left to do."""
    closed = ",".join(f"{bus}=remote:127.0.0.1:1" for bus in ("can0", "can1", "can2"))
    result = cli("--bus-map", closed, "stop")
    assert result.exit_code == 3, result.transcript()
    err = result.stderr
    assert "NOTHING WAS STOPPED: no bus could be opened (can0, can1, can2)" in err, err
    assert all(f"bus {bus}: not reached" in err for bus in ("can0", "can1", "can2")), err
    assert "cut the motor power" in err and "Traceback" not in err, err
