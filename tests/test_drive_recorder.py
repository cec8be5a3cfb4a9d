"""The drive's recorder (elmo/recorder.py) against the simulated drive's (sim/recorder.py): byte-exact
transcripts of configuring, arming, polling and the segmented 0x2030 upload, and every bad upload.

The link is test_client_sim_transcripts.py's SimLink with the drive's SDO server behind 0x600+node;
the SDO client is the session's (bus/sdo.py DriveSdo) on that link, so what is tested here is what
`log record --source drive` runs. One ManualClock: the recorder samples on the drive's own time.
"""

from __future__ import annotations

import struct

import pytest

from sherpa_cli.bus.sdo import DriveSdo
from sherpa_cli.elmo.client import DriveClient
from sherpa_cli.elmo.recorder import (
    LAYOUTS,
    DriveRecorder,
    RecorderPlan,
    RecorderSettings,
    decode_upload,
    encode_upload,
    plan_recording,
)
from sherpa_cli.errors import DriveRefusedError, ProtocolError, SdoError, UsageError
from sherpa_cli.sim import ManualClock, SimSettings
from sherpa_cli.sim.drive import SimDrive
from sherpa_cli.sim.sdo import SdoServer
from tests.test_client_sim_transcripts import NODE, RPDO2, TPDO2, SimLink, assert_transcript, rx, tx

SDO_RX, SDO_TX = 0x600 + NODE, 0x580 + NODE


class SdoSimLink(SimLink):
    """SimLink that also serves SDO (0x600+node) from the drive's object dictionary."""

    def __init__(self, drive: SimDrive, clock: ManualClock) -> None:
        super().__init__(drive, clock)
        self.server = SdoServer(NODE, drive, lambda can_id, data: drive.send_later(can_id, data, 0.0))

    def send(self, can_id: int, data: bytes) -> None:
        data = bytes(data)
        if can_id != SDO_RX:
            super().send(can_id, data)
            return
        self._record("tx", can_id, data)
        if self.drive.receive(can_id, data):
            self.server.receive(can_id, data)
        self.drive.tick()
        self.flush()

    def send_message(self, can_id: int, data: bytes, remote: bool = False) -> None:  # canopen's Network
        self.send(can_id, data)


def make(sim: SimSettings | None = None, settings: RecorderSettings | None = None):
    clock = ManualClock()
    drive = SimDrive(NODE, clock=clock, settings=sim or SimSettings())
    link = SdoSimLink(drive, clock)
    client = DriveClient(link, NODE, name="drive1", timeout=0.001, retries=0, clock=clock.now, sleep=link.sleep)
    sdo = DriveSdo(link, NODE, label="drive1 (node 10)", timeout=0.05)
    rec = DriveRecorder(client, sdo.upload, settings or RecorderSettings(), clock=clock.now, sleep=link.sleep)
    client.nmt_start()
    client.set("PX", 0, 1234)  # the motor is off: the recorded position is constant
    link.take()
    return drive, link, client, rec


PLAN = RecorderPlan(("pos",), gap=1, length=3, trigger="now")
UPLOAD_1234 = [  # 0x2030:1, 19 bytes: header 40 | 03 00 | 1.0f | then 3 x 1234
    tx(SDO_RX, "40 30 20 01 00 00 00 00"),
    rx(SDO_TX, "41 30 20 01 13 00 00 00"),  # segmented, size 19
    tx(SDO_RX, "60 00 00 00 00 00 00 00"),
    rx(SDO_TX, "00 40 03 00 00 00 80 3F"),  # type 4 (long), 3 samples, scale 1.0
    tx(SDO_RX, "70 00 00 00 00 00 00 00"),
    rx(SDO_TX, "10 D2 04 00 00 D2 04 00"),
    tx(SDO_RX, "60 00 00 00 00 00 00 00"),
    rx(SDO_TX, "05 00 D2 04 00 00 00 00"),  # last segment, 5 bytes
]


def test_configure_arm_poll_and_upload_transcript():
    drive, link, _client, rec = make()
    rec.configure(PLAN)
    assert_transcript(link.take(), [
        tx(RPDO2, "52 52 00 00 00 00 00 00"), rx(TPDO2, "52 52 00 00 00 00 00 00"),  # RR=0: kill
        tx(RPDO2, "52 56 01 00 02 00 00 00"), rx(TPDO2, "52 56 01 00 02 00 00 00"),  # RV[1]=2: position
        tx(RPDO2, "52 43 00 00 01 00 00 00"), rx(TPDO2, "52 43 00 00 01 00 00 00"),  # RC=1
        tx(RPDO2, "52 47 00 00 01 00 00 00"), rx(TPDO2, "52 47 00 00 01 00 00 00"),  # RG=1
        tx(RPDO2, "52 4C 00 00 03 00 00 00"), rx(TPDO2, "52 4C 00 00 03 00 00 00"),  # RL=3
        tx(RPDO2, "52 50 03 00 00 00 00 00"), rx(TPDO2, "52 50 03 00 00 00 00 00"),  # RP[3]=0: immediate
    ])
    rec.arm(PLAN)
    assert not rec.ready()  # one sample of three so far
    rec.wait_ready(1.0)
    assert_transcript(link.take(), [
        tx(RPDO2, "52 52 00 00 02 00 00 00"), rx(TPDO2, "52 52 00 00 02 00 00 00"),  # RR=2: start now
        tx(RPDO2, "52 52 00 00"), rx(TPDO2, "52 52 00 00 02 00 00 00"),  # recording
        tx(RPDO2, "52 52 00 00"), rx(TPDO2, "52 52 00 00 02 00 00 00"),
        tx(RPDO2, "52 52 00 00"), rx(TPDO2, "52 52 00 00 00 00 00 00"),  # 0: data ready
    ])
    assert drive.recorder.samples_taken == 3
    assert rec.read(PLAN) == {"pos": [1234.0, 1234.0, 1234.0]}
    assert_transcript(link.take(), UPLOAD_1234)


def test_poll_by_sr_bits_16_17():
    _drive, link, client, rec = make(settings=RecorderSettings(state_from="SR"))
    rec.configure(PLAN)
    assert (client.get("SR") >> 16) & 3 == 0  # inactive
    rec.arm(PLAN)
    link.take()
    assert (client.get("SR") >> 16) & 3 == 3  # recording
    rec.wait_ready(1.0)
    assert (client.get("SR") >> 16) & 3 == 2  # data ready
    assert rec.read(PLAN)["pos"] == [1234.0] * 3


def test_snapshot_and_restore_put_the_ram_back():
    drive, _link, _client, rec = make()
    plan = plan_recording(0.5, rec.settings)
    saved = rec.snapshot(plan)
    before = dict(drive.ram)
    rec.configure(plan)
    rec.arm(plan)
    assert drive.ram["RC"] == 0b11111 and drive.recorder.state == 3
    rec.restore(saved)
    assert drive.recorder.state == 0 and drive.recorder.rr == -1
    assert {k: v for k, v in drive.ram.items() if k != "RR"} == {k: v for k, v in before.items() if k != "RR"}
    assert drive.save_count == 0 and not drive.od_writes  # RAM only: no SV, no SDO write


def test_bg_trigger_waits_for_the_begin_and_records_the_motion():
    drive, link, client, rec = make(sim=SimSettings(mo_settle_s=0.0))
    plan = RecorderPlan(("pos", "vel", "vel_cmd"), gap=10, length=50, trigger="bg")
    rec.configure(plan)
    rec.arm(plan)
    link.sleep(0.1)
    assert drive.recorder.state == 1 and client.get("RR") == 1  # waiting for the BG
    client.set("UM", 0, 2)
    client.motor_on()
    client.set("JV", 0, 10_000)
    client.execute("BG")
    rec.wait_ready(2.0)
    data = rec.read(plan)
    assert len(data["pos"]) == 50
    assert data["vel_cmd"][0] == 0.0 and data["vel_cmd"][-1] > 0  # the jog's profile, from the BG on
    assert data["pos"][-1] > data["pos"][0]


def test_aligned_header_layout_both_ways():
    sim = SimSettings(recorder_header="aligned", recorder_type=5)
    _drive, _link, _client, rec = make(sim=sim, settings=RecorderSettings(header="aligned"))
    rec.configure(PLAN)
    rec.arm(PLAN)
    rec.wait_ready(1.0)
    assert rec.read(PLAN) == {"pos": [1234.0] * 3}
    # the other reading of the same bytes is refused with one clear error
    _drive, _link, _client, rec = make(sim=sim)
    rec.configure(PLAN)
    rec.arm(PLAN)
    rec.wait_ready(1.0)
    with pytest.raises(ProtocolError, match=r"0x2030:1 \(pos\): header says"):
        rec.read(PLAN)


@pytest.mark.parametrize(("fault", "error", "match"), [
    ("short", ProtocolError, r"header says 3 sample\(s\) \(12 bytes\), the upload carries 10 byte"),
    ("bad_type", ProtocolError, r"data type nibble 15 \(unknown\)"),
    ("abort", SdoError, r"SDO upload of 0x2030:1 aborted with 0x08000021"),
])
def test_bad_uploads_give_one_clear_error(fault, error, match):
    _drive, link, _client, rec = make(sim=SimSettings(recorder_upload_fault=fault))
    rec.configure(PLAN)
    rec.arm(PLAN)
    rec.wait_ready(1.0)
    link.take()
    with pytest.raises(error, match=match):
        rec.read(PLAN)
    if fault == "abort":
        assert_transcript(link.take(), [tx(SDO_RX, "40 30 20 01 00 00 00 00"),
                                        rx(SDO_TX, "80 30 20 01 21 00 00 08")])


def test_upload_before_data_is_aborted():
    _drive, _link, _client, rec = make()
    with pytest.raises(SdoError, match="0x08000024"):
        rec.read(PLAN)


def test_the_drive_refuses_more_than_8_signals_and_a_too_long_recording():
    _drive, _link, client, _rec = make()
    with pytest.raises(DriveRefusedError) as info:
        client.set("RC", 0, 0x1FF)
    assert info.value.code == 21
    client.set("RC", 0, 0xFF)
    client.set("RL", 0, 1000)  # 8 x 1000 > 4096
    with pytest.raises(DriveRefusedError):
        client.set("RR", 0, 2)


def test_plan_picks_the_finest_gap_that_holds_the_time():
    s = RecorderSettings()
    plan = plan_recording(0.2, s)  # 819 samples per signal hold 0.29 s at RG=1
    assert (plan.gap, plan.length, plan.mask) == (1, 556, 0b11111)
    plan = plan_recording(2.0, s)
    assert plan.gap == 7 and plan.length * plan.gap * s.sample_time_s >= 2.0
    with pytest.raises(UsageError, match="holds at most"):
        plan_recording(2000.0, s)
    with pytest.raises(UsageError, match=r"1\.\.8 signals"):
        plan_recording(1.0, s, signals=["pos"] * 9)


def test_encode_decode_round_trip_and_header_bytes():
    data = encode_upload(LAYOUTS["cob"], 4, 0.001, [1500, -250])
    assert data.hex(" ") == "40 02 00 6f 12 83 3a dc 05 00 00 06 ff ff ff"
    assert decode_upload(data, LAYOUTS["cob"], what="x") == pytest.approx([1.5, -0.25])
    floats = encode_upload(LAYOUTS["aligned"], 5, 2.0, [0.5])
    assert floats[:8] == bytes([0x50, 0, 1, 0]) + struct.pack("<f", 2.0)
    assert decode_upload(floats, LAYOUTS["aligned"], what="x") == [1.0]
    with pytest.raises(ProtocolError, match="shorter than the 7-byte header"):
        decode_upload(b"\x40\x00", LAYOUTS["cob"], what="x")
    with pytest.raises(ProtocolError, match="half float"):
        decode_upload(bytes([0x10, 0, 0, 0, 0, 0x80, 0x3F]), LAYOUTS["cob"], what="x")
