"""`log record` records a joint's CANopen absolute encoder beside it (tests/data/home-arm.yaml: elbow
on elbow_drive, elbow_encoder on can0:45, offset 100): the encoder's TPDO1 on every SYNC (RAM only,
put back), columns ``elbow_encoder.pos`` (counts) and ``elbow.ext_pos_rad``; simulated time as in
test_log_record.py."""

from __future__ import annotations

import csv
import math
import uuid
from pathlib import Path

import pytest

from sherpa_cli.bus.session import ArmSession
from sherpa_cli.bus.targets import drive_refs
from sherpa_cli.config import load_config
from sherpa_cli.devices import encoder
from sherpa_cli.errors import UsageError
from sherpa_cli.joints.units import counts_to_rad
from sherpa_cli.log.record import Recorder, bus_budget
from sherpa_cli.sim.arm import SimArm
from sherpa_cli.sim.clock import ManualClock
from tests.test_log_record import Lockstep

ROOT = Path(__file__).resolve().parent.parent
ARM = ROOT / "tests" / "data" / "home-arm.yaml"


def _arm(cfg, clock):
    tag = uuid.uuid4().hex[:8]
    return SimArm(cfg, {b: {"interface": "virtual", "channel": f"enc-{tag}-{b}"} for b in cfg.buses}, clock=clock)


def _tpdo1(session, dev):
    sdo = session.sdo(encoder.device_ref(dev))
    return [int.from_bytes(bytes(sdo.upload(0x1800, s))[:n], "little") for s, n in ((1, 4), (2, 1))]


def test_the_encoder_is_recorded_beside_its_joint_and_its_tpdo_put_back():
    cfg = load_config(ARM)
    dev = cfg.devices["elbow_encoder"]
    clock = ManualClock()
    lock = Lockstep(clock)
    with ArmSession.open(cfg, sim=_arm(cfg, clock)) as session:
        refs = drive_refs(cfg, ["elbow"])
        before = _tpdo1(session, dev)
        assert before == [0x180 + 45, 254]
        with Recorder(session, refs, 100, clock=clock.now, sync_factory=lock.factory) as rec:
            assert [t.dev.name for t in rec.encoders] == ["elbow_encoder"]
            assert rec.budget[0].bits_per_sync > bus_budget(cfg, refs, 100, current=False)[0].bits_per_sync
            lock.run(rec, 20)
        assert _tpdo1(session, dev) == before  # transmission type 1 while recording, 254 again after
        with session.sim.lock:
            enc = session.sim.extras["elbow_encoder"][1]
            assert [(i, s, v) for _, i, s, v in enc.od_writes] == [(0x1800, 2, 1), (0x1800, 2, 254)]
            assert enc.save_count == 0
    assert rec.counts() == {"elbow_drive": 20, "elbow_encoder": 20}
    recording = rec.recording()
    assert len(recording.times) == 20
    # the encoder reads the joint's real -444 minus the offset 100; PX reads 0 (not homed): the two differ
    assert recording.columns["elbow_encoder.pos"] == [-544.0] * 20
    assert recording.columns["elbow.ext_pos_rad"] == [pytest.approx(counts_to_rad(-444, 3600))] * 20
    assert recording.columns["elbow.pos_rad"] == [0.0] * 20


def test_a_drive_without_an_encoder_gets_no_encoder_columns():
    cfg = load_config(ARM)
    assert encoder.recorded_encoders(cfg, ["yaw_drive", "twist_drive"]) == []  # twist: drive:PY, not a device
    clock = ManualClock()
    lock = Lockstep(clock)
    with (
        ArmSession.open(cfg, sim=_arm(cfg, clock)) as session,
        Recorder(session, drive_refs(cfg, ["yaw"]), 100, clock=clock.now, sync_factory=lock.factory) as rec,
    ):
        lock.run(rec, 3)
    assert not [c for c in rec.recording().columns if "ext_pos" in c or c.endswith(".pos")]


def test_an_encoder_that_cannot_be_recorded_refuses_and_the_drives_are_put_back():
    cfg = load_config(ARM)
    dev = cfg.devices["elbow_encoder"]
    clock = ManualClock()
    with ArmSession.open(cfg, sim=_arm(cfg, clock)) as session:
        refs = drive_refs(cfg, ["elbow"])
        session.sdo(encoder.device_ref(dev)).download(0x1800, 1, (0x80000000 | 0x1AD).to_bytes(4, "little"))  # PDO off,
        session.sdo(encoder.device_ref(dev)).download(0x1A00, 0, b"\x00")  # then TPDO1 maps nothing (CiA 301 order)
        drive_sdo = session.sdo(refs[0])
        before = [bytes(drive_sdo.upload(0x1800, 2)), bytes(drive_sdo.upload(0x1A00, 0))]
        with (
            pytest.raises(UsageError, match="elbow_encoder: its TPDO1 does not carry the position value 0x6004"),
            Recorder(session, refs, 100, clock=clock.now, sync_factory=Lockstep(clock).factory),
        ):
            pass
        assert [bytes(drive_sdo.upload(0x1800, 2)), bytes(drive_sdo.upload(0x1A00, 0))] == before


def test_targets_name_the_encoder_device_for_its_joint():
    cfg = load_config(ARM)
    assert encoder.targets_with_encoders(cfg, ["elbow_encoder", "yaw"]) == ["elbow", "yaw"]
    assert encoder.targets_with_encoders(cfg, ["can0:45"]) == ["elbow"]
    assert encoder.targets_with_encoders(cfg, None) is None


def test_cli_records_the_encoder_by_its_device_name(cli, tmp_path):
    out = tmp_path / "enc.csv"
    result = cli("--config", str(ARM), "--sim", "log", "record", "elbow_encoder", "--rate", "50", "--for", "0.3",
                 "-o", str(out))
    assert result.exit_code == 0, result.transcript()
    assert "elbow_encoder:" in result.stdout
    with out.open(encoding="utf-8") as fp:
        rows = list(csv.DictReader(fp))
    assert rows and "elbow_encoder.pos" in rows[0] and "elbow.ext_pos_rad" in rows[0]
    values = [float(r["elbow_encoder.pos"]) for r in rows if r["elbow_encoder.pos"] not in ("", "nan")]
    assert values and all(v == -544 for v in values)
    assert all(math.isclose(float(r["elbow.ext_pos_rad"]), counts_to_rad(-444, 3600), abs_tol=1e-6)  # CSV digits
               for r in rows if r["elbow.ext_pos_rad"] not in ("", "nan"))


def test_an_encoder_on_another_bus_gets_its_own_sync(tmp_path):
    text = ARM.read_text(encoding="utf-8")
    text = text.replace("  can0: {interface: socketcan, channel: can0}\n",
                        "  can0: {interface: socketcan, channel: can0}\n  can1: {interface: socketcan, channel: can1}\n")
    text = text.replace("{type: canopen-encoder, bus: can0, node: 45}", "{type: canopen-encoder, bus: can1, node: 45}")
    text = text.replace('source: "can0:45"', 'source: "can1:45"')
    path = tmp_path / "arm.yaml"
    path.write_text(text, encoding="utf-8")
    cfg = load_config(path)
    clock = ManualClock()
    lock = Lockstep(clock)
    with (
        ArmSession.open(cfg, sim=_arm(cfg, clock)) as session,
        Recorder(session, drive_refs(cfg, ["elbow"]), 100, clock=clock.now, sync_factory=lock.factory) as rec,
    ):
        assert sorted(lock.buses) == ["can0", "can1"]
        assert [b.bus for b in rec.budget] == ["can0", "can1"]
        lock.run(rec, 5)
    assert rec.counts() == {"elbow_drive": 5, "elbow_encoder": 5}
    assert rec.recording().columns["elbow_encoder.pos"] == [-544.0] * 5
