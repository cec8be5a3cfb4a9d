"""The CANopen absolute encoder (CiA 406) by TPDO1 on the simulated arm (tests/data/home-arm.yaml,
elbow_encoder on can0:45): cyclic by 0x6200 or on SYNC, SDO as the fallback, and every RAM change
put back on every exit path (never saved)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from sherpa_cli.bus.session import ArmSession
from sherpa_cli.config import load_config
from sherpa_cli.devices import encoder
from sherpa_cli.errors import ConfigError
from sherpa_cli.sim.arm import SimArm

ROOT = Path(__file__).resolve().parent.parent
ARM = ROOT / "tests" / "data" / "home-arm.yaml"
TPDO_OBJECTS = [(0x1800, 1, 4), (0x1800, 2, 1), (0x1A00, 0, 1), (0x1A00, 1, 4), (0x6200, 0, 2)]


def with_device(cfg, **changes):
    dev = dataclasses.replace(cfg.devices["elbow_encoder"], **changes)
    return dataclasses.replace(cfg, devices={**cfg.devices, dev.name: dev})


def objects(session, dev):
    sdo = session.sdo(encoder.device_ref(dev))
    return {(i, s): int.from_bytes(bytes(sdo.upload(i, s))[:n], "little") for i, s, n in TPDO_OBJECTS}


def sim_encoder(session):
    with session.sim.lock:
        return session.sim.extras["elbow_encoder"][1]


def writes(session):
    with session.sim.lock:
        return [(i, s, v) for _, i, s, v in sim_encoder(session).od_writes]


def test_cyclic_tpdo_reads_the_position_and_puts_0x6200_back():
    cfg = load_config(ARM)
    dev = cfg.devices["elbow_encoder"]
    assert (dev.position_from, dev.tpdo_trigger, dev.cyclic_ms) == ("tpdo", "cyclic", 10)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        before = objects(s, dev)
        # CiA 406 defaults of the simulated encoder: TPDO1 valid at 0x180 + node, asynchronous, 0x6004
        assert before == {(0x1800, 1): 0x180 + 45, (0x1800, 2): 254, (0x1A00, 0): 1, (0x1A00, 1): 0x60040020,
                          (0x6200, 0): 0}
        reading = encoder.read_position(s, dev)
        assert reading.by_tpdo and reading.position == -544  # the joint's -444 minus the offset 100
        assert reading.changed == [(0x6200, 0, 2, 0)]  # its cyclic timer was 0: 10 ms in RAM, then back
        assert objects(s, dev) == before
        assert writes(s) == [(0x6200, 0, 10), (0x6200, 0, 0)]
        enc = sim_encoder(s)
        with s.sim.lock:
            assert enc.tpdo_frames >= 1 and enc.save_count == 0 and enc.cyclic_ms == 0
            assert not [w for w in enc.od_writes if w[1] == 0x1010]  # never "store parameters"


def test_an_encoder_that_already_sends_cyclically_is_only_listened_to():
    cfg = load_config(ARM)
    dev = cfg.devices["elbow_encoder"]
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        with s.sim.lock:
            enc = sim_encoder(s)
            enc._default_cyclic_ms = enc.cyclic_ms = 50  # another maker: 50 ms from the factory
        reading = encoder.read_position(s, dev)
        assert reading.by_tpdo and reading.position == -544 and reading.changed == []
        assert writes(s) == []


def test_sync_trigger_sets_transmission_type_1_sends_one_sync_and_puts_it_back():
    cfg = with_device(load_config(ARM), tpdo_trigger="sync")
    dev = cfg.devices["elbow_encoder"]
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        reading = encoder.read_position(s, dev)
        assert reading.by_tpdo and reading.position == -544
        assert writes(s) == [(0x1800, 2, 1), (0x1800, 2, 254)]
        with s.sim.lock:
            received = [i for _, i, _ in sim_encoder(s).received]
        assert 0x080 in received  # the SYNC it sent


def test_sdo_only_and_the_fallbacks():
    cfg = load_config(ARM)
    with ArmSession.open(with_device(cfg, position_from="sdo"), sim=SimArm.in_process(cfg)) as s:
        reading = encoder.read_position(s, s.cfg.devices["elbow_encoder"])
        assert reading.via == "SDO" and reading.position == -544 and writes(s) == []
    dev = cfg.devices["elbow_encoder"]
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        s.sdo(encoder.device_ref(dev)).download(0x1800, 1, (0x80000000 | 0x1AD).to_bytes(4, "little"))  # PDO off,
        s.sdo(encoder.device_ref(dev)).download(0x1A00, 0, b"\x00")  # then TPDO1 maps nothing (CiA 301 order)
        reading = encoder.read_position(s, dev)
        assert reading.via == "SDO (TPDO1 does not carry 0x6004 first)" and reading.position == -544


def test_no_tpdo_within_the_wait_falls_back_to_sdo_and_restores(monkeypatch):
    from sherpa_cli.sim.encoder import SimEncoder

    monkeypatch.setattr(SimEncoder, "_send_tpdo", lambda self, *frame: None)  # an encoder whose TPDO never comes
    cfg = load_config(ARM)
    dev = cfg.devices["elbow_encoder"]
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        reading = encoder.read_position(s, dev, wait_s=0.1)
        assert reading.via == "SDO (no TPDO1 within 0.1 s)" and reading.position == -544
        assert objects(s, dev)[(0x6200, 0)] == 0


def test_ctrl_c_while_waiting_still_restores():
    cfg = load_config(ARM)
    dev = cfg.devices["elbow_encoder"]

    def interrupted(_s):
        raise KeyboardInterrupt

    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        with s.sim.lock:
            sim_encoder(s)._send_tpdo = lambda: None  # nothing arrives: the wait sleeps, and is interrupted
        with pytest.raises(KeyboardInterrupt):
            encoder.read_position(s, dev, sleep=interrupted)
        assert objects(s, dev)[(0x6200, 0)] == 0
        assert writes(s) == [(0x6200, 0, 10), (0x6200, 0, 0)]


def test_the_simulated_encoder_sends_tpdo1_every_cyclic_period_and_on_sync():
    from sherpa_cli.sim.clock import ManualClock
    from sherpa_cli.sim.encoder import SimEncoder

    clock = ManualClock()
    pos = [1234]
    enc = SimEncoder(45, position=lambda: pos[0], clock=clock, cyclic_ms=100)
    enc.pop_frames()  # boot-up
    enc.receive(0x000, bytes([0x01, 45]))  # NMT start: CiA 406 sends TPDO1 on entering Operational
    assert enc.pop_frames() == [(0x1AD, (1234).to_bytes(4, "little", signed=True))]
    pos[0] = -5
    clock.advance(0.25)
    enc.tick()
    assert enc.pop_frames() == [(0x1AD, (-5).to_bytes(4, "little", signed=True))] * 2  # at 0.1 and 0.2 s
    enc.od_write(0x1800, 2, 1)  # synchronous: on every SYNC, no longer cyclic
    clock.advance(0.3)
    enc.tick()
    assert enc.pop_frames() == []
    enc.receive(0x080, b"")
    # TPDO1 now synchronous, and TPDO2 (0x280 + node), synchronous from the factory (CiA 406)
    assert enc.pop_frames() == [(0x1AD, (-5).to_bytes(4, "little", signed=True)),
                                (0x2AD, (-5).to_bytes(4, "little", signed=True))]
    enc.receive(0x000, bytes([0x81, 45]))  # reset node: RAM defaults again, Pre-operational
    assert (enc.od_read(0x1800, 2), enc.cyclic_ms) == (254, 100)


def test_encoder_settings_are_checked(tmp_path):
    text = ARM.read_text(encoding="utf-8")
    for old, new, message in (
            ("node: 45}", "node: 45, position_from: pdo}", "position_from 'pdo'; expected one of: tpdo, sdo"),
            ("node: 45}", "node: 45, tpdo_trigger: event}", "tpdo_trigger 'event'; expected one of: cyclic, sync"),
            ("node: 45}", "node: 45, cyclic_ms: 0}", "cyclic_ms 0 out of range 1..65535")):
        path = tmp_path / "arm.yaml"
        path.write_text(text.replace(old, new), encoding="utf-8")
        with pytest.raises(ConfigError, match=message) as info:
            load_config(path)
        assert "arm.yaml:" in str(info.value)


def test_encoder_settings_round_trip_through_the_dump():
    from sherpa_cli.config import dump_native, load_config_text

    cfg = with_device(load_config(ARM), tpdo_trigger="sync", cyclic_ms=25)
    text = dump_native(cfg)
    assert "tpdo_trigger: sync" in text and "cyclic_ms: 25" in text and "position_from" not in text
    again = load_config_text(text, "again.yaml")
    assert again.devices["elbow_encoder"] == cfg.devices["elbow_encoder"]


def test_the_simulated_encoder_refuses_a_mapping_change_while_tpdo1_is_valid():
    from sherpa_cli.sim.clock import ManualClock
    from sherpa_cli.sim.encoder import SimEncoder
    from sherpa_cli.sim.od import ODError

    enc = SimEncoder(45, position=lambda: 0, clock=ManualClock())
    with pytest.raises(ODError) as info:
        enc.od_write(0x1A00, 0, 0)
    assert info.value.abort_code == 0x06010000  # CiA 301 (CANopenNode: ODR_UNSUPP_ACCESS)
    enc.od_write(0x1800, 1, 0x80000000 | 0x1AD)
    enc.od_write(0x1A00, 0, 0)
    assert enc.od_read(0x1A00, 0) == 0
