"""CiA 301 conformance of the simulated drive.

- NMT Stopped: only NMT and error control (heartbeat) work; no SDO answer, no interpreter.
- SDO: after an abort (either side) or a finished transfer a stray segment request is aborted,
  not served from the old transfer; block transfers are aborted with "command specifier not
  valid"; frames that are not 8 bytes are no SDO requests.
- The interpreter accepts long queries with and without the float type bit.
- A stock `canopen` client against `sherpa sim --serve` gets no SDO answer from a Stopped node.

The rows a third-party master meets first are driven with stock canopen only (``canopen.Network``, a
``RemoteNode`` on the shipped EDS, its SdoClient and PdoMap) against the arm on a ManualClock: the
TPDO inhibit time (frames per simulated second), 0x1005 COB-ID SYNC, a segmented download longer
than it said, the guide's CA[1]=4 -> EC 21 example, malformed interpreter frames, reset node vs reset
communication, RTR frames on the SYNC id, the EMCY rules and clearing 0x1003. A test waits in wall time
only for frames to travel (bounded): the simulator answers frames in order, so whatever a frame made
a node send is on the bus before the answer to an SDO request sent after it.
"""

from __future__ import annotations

import struct
import uuid
from collections.abc import Iterator
from pathlib import Path

import canopen
import pytest
from canopen.sdo.exceptions import SdoAbortedError
from test_cross_process import served_sim  # noqa: F401  (the fixture: `sherpa sim --serve` in a subprocess)

from sherpa_cli.config import load_config
from sherpa_cli.elmo.codec import decode_reply, encode_execute, encode_query, encode_set
from sherpa_cli.sim import ManualClock, SimSettings
from sherpa_cli.sim.arm import SimArm
from sherpa_cli.sim.drive import STOPPED, SimDrive
from sherpa_cli.sim.sdo import ABORT_COMMAND, SdoServer

NODE = 3
RPDO2, TPDO2, HB = 0x300 + NODE, 0x280 + NODE, 0x700 + NODE
SDO_RX, SDO_TX = 0x600 + NODE, 0x580 + NODE


class Node:
    """A drive and its SDO server wired like the arm's bus loop: SDO only when receive() says so."""

    def __init__(self, **settings) -> None:
        self.clock = ManualClock()
        self.drive = SimDrive(NODE, clock=self.clock, settings=SimSettings(**settings), serial=0x1234)
        self.sdo_out: list[bytes] = []
        self.sdo = SdoServer(NODE, self.drive, lambda can_id, data: self.sdo_out.append(bytes(data)))
        self.drive.pop_frames()

    def frame(self, can_id: int, data: bytes) -> list[tuple[int, bytes]]:
        """Send a frame; everything the node put on the bus in answer (SDO answers included)."""
        self.sdo_out.clear()
        if self.drive.receive(can_id, data) and can_id == SDO_RX:
            self.sdo.receive(can_id, data)
        return self.drive.pop_frames() + [(SDO_TX, d) for d in self.sdo_out]

    def sdo_request(self, hexdata: str) -> list[bytes]:
        return [d for c, d in self.frame(SDO_RX, bytes.fromhex(hexdata)) if c == SDO_TX]

    def nmt(self, command: int) -> None:
        self.frame(0x000, bytes([command, NODE]))


def abort_code(frame: bytes) -> int | None:
    return struct.unpack_from("<L", frame, 4)[0] if frame[0] == 0x80 else None


# -- NMT Stopped ------------------------------------------------------------------------------

def test_stopped_node_answers_no_sdo_and_no_interpreter_but_keeps_its_heartbeat():
    node = Node(heartbeat_ms=100)
    node.nmt(0x01)  # operational: both services answer
    assert node.sdo_request("40 18 10 04 00 00 00 00")[0][:4] == bytes.fromhex("43 18 10 04")
    assert [c for c, _ in node.frame(RPDO2, encode_query("AC"))] == [TPDO2]

    node.nmt(0x02)  # stop remote node
    assert node.drive.nmt_state == STOPPED
    assert node.sdo_request("40 18 10 04 00 00 00 00") == []
    assert node.frame(RPDO2, encode_query("AC")) == []
    node.clock.advance(0.25)
    node.drive.tick()
    beats = [d for c, d in node.drive.pop_frames() if c == HB]
    assert beats and all(d == bytes([STOPPED]) for d in beats)  # heartbeat goes on, state 0x04

    node.nmt(0x80)  # pre-operational: SDO again (PDOs, hence the interpreter, still not)
    assert node.sdo_request("40 18 10 04 00 00 00 00")[0][:4] == bytes.fromhex("43 18 10 04")
    assert node.frame(RPDO2, encode_query("AC")) == []


# -- SDO transfer state -----------------------------------------------------------------------

def test_segment_request_after_a_client_abort_is_aborted_not_served():
    node = Node(device_name="Whistle simulated drive")
    first = node.sdo_request("40 08 10 00 00 00 00 00")  # 0x1008: a segmented upload
    assert first[0][0] == 0x41
    seg = node.sdo_request("60 00 00 00 00 00 00 00")
    assert seg[0][0] & 0xE0 == 0x00  # the first segment
    node.sdo_request("80 08 10 00 00 00 04 05")  # the client aborts (toggle bit not alternated)
    after = node.sdo_request("70 00 00 00 00 00 00 00")  # the next segment of the aborted transfer
    assert len(after) == 1 and abort_code(after[0]) == ABORT_COMMAND
    # a new transfer starts from the beginning
    again = node.sdo_request("40 08 10 00 00 00 00 00")
    assert again == first
    assert node.sdo_request("60 00 00 00 00 00 00 00") == seg


def test_segment_request_after_a_server_abort_is_aborted():
    node = Node()
    assert node.sdo_request("40 08 10 00 00 00 00 00")[0][0] == 0x41
    wrong_toggle = node.sdo_request("70 00 00 00 00 00 00 00")  # first segment must have toggle 0
    assert abort_code(wrong_toggle[0]) == 0x05030000
    stray = node.sdo_request("60 00 00 00 00 00 00 00")
    assert abort_code(stray[0]) == ABORT_COMMAND


def test_segment_request_without_any_transfer_is_aborted():
    node = Node()
    for request in ("60 00 00 00 00 00 00 00", "00 41 42 43 44 45 46 47"):
        answer = node.sdo_request(request)
        assert len(answer) == 1 and abort_code(answer[0]) == ABORT_COMMAND


@pytest.mark.parametrize("request_hex", [
    "A4 18 10 04 7F 00 00 00",  # initiate block upload of 0x1018:4, 127 segments per block
    "A0 08 10 00 10 00 00 00",
    "C2 17 10 00 02 00 00 00",  # initiate block download
])
def test_block_transfers_are_aborted_with_the_index_asked(request_hex):
    node = Node()
    answer = node.sdo_request(request_hex)
    assert len(answer) == 1
    assert answer[0][:4] == bytes([0x80]) + bytes.fromhex(request_hex)[1:4]
    assert abort_code(answer[0]) == ABORT_COMMAND
    # and the server is idle afterwards: an expedited upload works
    assert node.sdo_request("40 18 10 04 00 00 00 00")[0][:4] == bytes.fromhex("43 18 10 04")


@pytest.mark.parametrize("request_hex", ["40", "40 18 10", "40 18 10 04 00 00 00", "40 18 10 04 00 00 00 00 00", ""])
def test_sdo_frames_of_the_wrong_length_get_no_answer(request_hex):
    node = Node()
    assert node.sdo_request(request_hex) == []
    assert node.sdo_request("40 18 10 04 00 00 00 00")[0][:4] == bytes.fromhex("43 18 10 04")


# -- interpreter: the type bit in long queries --------------------------------------------------

@pytest.mark.parametrize("query_hex", ["43 4C 01 C0 00 00 00 00", "43 4C 01 40 00 00 00 00", "43 4C 01 00"])
def test_drive_accepts_long_queries_with_or_without_the_float_bit(query_hex):
    node = Node()
    node.nmt(0x01)
    frames = node.frame(RPDO2, bytes.fromhex(query_hex))
    assert [c for c, _ in frames] == [TPDO2]
    answer = decode_reply(frames[0][1])
    assert answer.ok and answer.is_float and answer.value == 5.0  # factory CL[1]


def test_long_float_query_from_the_tool_is_the_typed_form():
    assert encode_query("CL", 1, long=True) == bytes.fromhex("43 4C 01 C0 00 00 00 00")


# -- a stock canopen client against `sherpa sim --serve` ------------------------------------------

@pytest.mark.crossprocess
def test_stock_canopen_client_gets_no_sdo_answer_from_a_stopped_node(served_sim):  # noqa: F811 (pytest fixture)
    import canopen
    from canopen.sdo.exceptions import SdoCommunicationError

    _, bus_map = served_sim
    channel = dict(item.split("=", 1) for item in bus_map.split(","))["can0"].split(":", 1)[1]
    network = canopen.Network()
    network.connect(interface="remote", channel=channel)
    try:
        node = network.add_node(10)  # shoulder_1a
        node.sdo.RESPONSE_TIMEOUT = 1.0
        node.sdo.MAX_RETRIES = 1  # canopen: 1 = one attempt (0 would retry for ever)
        serial = node.sdo.upload(0x1018, 4)  # pre-operational: SDO answers
        assert len(serial) == 4
        node.nmt.state = "STOPPED"
        with pytest.raises(SdoCommunicationError):
            node.sdo.upload(0x1018, 4)
        node.nmt.state = "PRE-OPERATIONAL"
        assert node.sdo.upload(0x1018, 4) == serial
    finally:
        network.disconnect()


# -- a stock canopen master against the simulated arm (ManualClock) -------------------------------

ROOT = Path(__file__).resolve().parent.parent
ARM = ROOT / "tests" / "data" / "home-arm.yaml"
WHISTLE_EDS = ROOT / "configs" / "eds" / "whistle.eds"
W, OTHER = 10, 11  # yaw_drive and stiff_drive on can0
INVALID, TOO_LONG = 0x06090030, 0x06070012
WAIT_S = 5.0  # wall time for an SDO answer from the simulator's thread (a loaded machine)


class Master:
    """canopen as a third-party master would use it: a Network, RemoteNodes on the shipped EDS."""

    def __init__(self, arm: SimArm, network: canopen.Network, clock: ManualClock) -> None:
        self.arm, self.network, self.clock = arm, network, clock
        self.node = network.add_node(W, str(WHISTLE_EDS))
        # another drive on the bus answers the SDO request that marks "everything before is out", so
        # raw SDO frames to W (and their answers) never meet W's own SdoClient
        self.other = network.add_node(OTHER, str(WHISTLE_EDS))
        for node in (self.node, self.other):
            node.sdo.RESPONSE_TIMEOUT = WAIT_S

    def flush(self) -> None:
        """Every frame sent so far has been handled and what it made the nodes send is in."""
        self.other.sdo.upload(0x1000, 0)

    def read(self, index: int, sub: int = 0) -> int:
        return int.from_bytes(self.node.sdo.upload(index, sub), "little")

    def write(self, index: int, sub: int, value: int, size: int = 4) -> None:
        self.node.sdo.download(index, sub, value.to_bytes(size, "little"))

    def refused(self, index: int, sub: int, value: int, size: int = 4) -> int:
        with pytest.raises(SdoAbortedError) as info:
            self.write(index, sub, value, size)
        return info.value.code

    def heard(self, cob: int, *frames: tuple[int, bytes] | tuple[int, bytes, bool]) -> list[bytes]:
        """Send ``frames`` ((can_id, data[, remote])), then an SDO request; what came on ``cob`` before
        its answer (the simulator answers in order)."""
        got: list[bytes] = []

        def collect(can_id: int, data: bytearray, timestamp: float) -> None:
            got.append(bytes(data))

        self.network.subscribe(cob, collect)
        try:
            for can_id, data, *remote in frames:
                self.network.send_message(can_id, data, remote=bool(remote and remote[0]))
            self.flush()
        finally:
            self.network.unsubscribe(cob, collect)
        return got

    def interpreter(self, data: bytes) -> list[bytes]:
        """The TPDO2 replies to one RPDO2 frame (the node must be Operational)."""
        return self.heard(0x280 + W, (0x300 + W, data))

    def nmt(self, cs: int) -> None:
        self.node.nmt.send_command(cs)
        self.flush()

    def sync_tpdo1(self) -> None:
        """TPDO1 = PX (0x6064), sent at every SYNC, configured by canopen's PdoMap."""
        self.node.tpdo.read()
        tpdo = self.node.tpdo[1]
        tpdo.clear()
        tpdo.add_variable(0x6064)
        tpdo.trans_type = 1
        tpdo.cob_id = 0x180 + W
        tpdo.enabled = True
        tpdo.save()


@pytest.fixture
def master() -> Iterator[Master]:
    cfg = load_config(ARM)
    clock = ManualClock()
    channel = f"conformance-{uuid.uuid4().hex[:8]}"
    arm = SimArm(cfg, {"can0": {"interface": "virtual", "channel": channel}}, clock=clock)
    network = canopen.Network()
    with arm:
        network.connect(interface="virtual", channel=channel)
        try:
            yield Master(arm, network, clock)
        finally:
            network.disconnect()
    assert arm.errors == []


def test_inhibit_time_spaces_an_event_driven_tpdo_in_simulated_time(master):
    """0x1800:3 (100 us units) is the least time between two sends of an event-driven TPDO: a 10 ms
    event timer with a 50 ms inhibit time sends 20 frames per simulated second, not 100."""
    node = master.node
    node.tpdo.read()
    tpdo = node.tpdo[1]
    tpdo.clear()
    tpdo.add_variable(0x6064)
    tpdo.trans_type, tpdo.event_timer, tpdo.inhibit_time = 254, 10, 500
    tpdo.cob_id, tpdo.enabled = 0x180 + W, True
    tpdo.save()
    assert master.read(0x1800, 3) == 500
    per_100ms = []
    got: list[bytes] = []
    master.network.subscribe(0x180 + W, lambda can_id, data, ts: got.append(bytes(data)))
    master.nmt(0x01)  # the event timer counts from entering Operational (t = 0)
    for _ in range(10):
        before = len(got)
        master.clock.advance(0.1)
        master.flush()  # the bus stepped to the present: every TPDO due is out before this answer
        per_100ms.append(len(got) - before)
    master.network.unsubscribe(0x180 + W)
    # sends at 10, 60, 110, ... ms: the timer's 20 ms is held to 60 ms by the inhibit time, and so on
    assert per_100ms == [2] * 10
    assert set(got) == {bytes(4)}  # PX = 0: the mapped value, byte-exact


def test_inhibit_time_zero_keeps_the_event_timer(master):
    node = master.node
    node.tpdo.read()
    tpdo = node.tpdo[1]
    tpdo.clear()
    tpdo.add_variable(0x6064)
    tpdo.trans_type, tpdo.event_timer, tpdo.inhibit_time = 254, 10, 0
    tpdo.cob_id, tpdo.enabled = 0x180 + W, True
    tpdo.save()
    got: list[bytes] = []
    master.network.subscribe(0x180 + W, lambda can_id, data, ts: got.append(bytes(data)))
    master.nmt(0x01)
    master.clock.advance(0.1)
    master.flush()
    master.network.unsubscribe(0x180 + W)
    assert len(got) == 10


def test_cob_id_sync_0x1005_reads_writes_and_moves_the_sync_the_node_hears(master):
    assert master.read(0x1005) == 0x080  # CiA 301's default
    master.sync_tpdo1()
    master.nmt(0x01)
    assert master.heard(0x180 + W, (0x080, b"")) == [bytes(4)]
    master.write(0x1005, 0, 0x0A0)
    assert master.read(0x1005) == 0x0A0
    assert master.heard(0x180 + W, (0x080, b"")) == []  # 0x080 is no SYNC for this node any more
    assert master.heard(0x180 + W, (0x0A0, b"")) == [bytes(4)]
    # a SYNC consumer with 11-bit ids only: gen (bit 30), frame (bit 29) and bits 11..28 are refused,
    # and so are CiA 301's restricted CAN-IDs (CANopenNode's OD_write_1005 answers the same)
    for value in (0x40000080, 0x20000080, 0x00000880, 0x000, 0x07F, 0x101, 0x581, 0x601, 0x701):
        assert master.refused(0x1005, 0, value) == INVALID, hex(value)
    assert master.read(0x1005) == 0x0A0
    # a communication object: reset communication puts back its saved value (nothing saved: 0x080)
    master.nmt(0x82)
    assert master.read(0x1005) == 0x080


def test_a_segmented_download_longer_than_it_said_is_aborted(master):
    sdo_tx, sdo_rx = 0x580 + W, 0x600 + W
    heartbeat_before = master.read(0x1017)
    # initiate a segmented download of 0x1017:0 announcing 10 bytes
    assert master.heard(sdo_tx, (sdo_rx, bytes.fromhex("21 17 10 00 0A 00 00 00")))[0] == \
        bytes.fromhex("60 17 10 00 00 00 00 00")
    # 7 bytes: within the 10
    assert master.heard(sdo_tx, (sdo_rx, bytes.fromhex("00 01 02 03 04 05 06 07")))[0] == \
        bytes.fromhex("20 00 00 00 00 00 00 00")
    # 7 more: 14 > 10, aborted at once with "length of service parameter too high"
    answer = master.heard(sdo_tx, (sdo_rx, bytes.fromhex("10 08 09 0A 0B 0C 0D 0E")))
    assert answer[0] == bytes.fromhex("80 17 10 00 12 00 07 06"), answer[0].hex(" ")
    assert struct.unpack_from("<L", answer[0], 4)[0] == TOO_LONG
    # the transfer is over: its next segment is a stray one
    stray = master.heard(sdo_tx, (sdo_rx, bytes.fromhex("00 0F 10 11 12 13 14 15")))
    assert stray[0] == bytes.fromhex("80 17 10 00 01 00 04 05")
    assert master.read(0x1017) == heartbeat_before


def test_ca1_4_is_answered_ec_21_as_in_the_guide(master):
    master.nmt(0x01)
    assert master.interpreter(encode_set("CA", 1, 4)) == [bytes.fromhex("43 41 01 40 15 00 00 00")]  # [IG] 9-4
    assert decode_reply(master.interpreter(encode_query("EC"))[0]).value == 21
    assert master.interpreter(encode_set("CA", 1, 3)) == [encode_set("CA", 1, 3)]  # echoed: accepted
    assert master.interpreter(encode_set("CA", 18, 4096)) == [encode_set("CA", 18, 4096)]  # the guide's other CA


@pytest.mark.parametrize(("request_hex", "reply_hex"), [
    ("61 63 00 00", "61 63 00 40 02 00 00 00"),  # "ac": lower case, a short query
    ("41 63 00 00 F0 49 02 00", "41 63 00 40 02 00 00 00"),  # "Ac=150000"
    ("31 32 05 00", "31 32 05 40 02 00 00 00"),  # not letters; the index is repeated
    ("C4 43 00 00", "C4 43 00 40 02 00 00 00"),  # not ASCII
    ("41 43 00 00 F0 49", "41 43 00 40 02 00 00 00"),  # 6 bytes: neither a query nor a set
])
def test_malformed_interpreter_frames_get_the_error_reply(master, request_hex, reply_hex):
    master.nmt(0x01)
    assert master.interpreter(bytes.fromhex(request_hex)) == [bytes.fromhex(reply_hex)]
    assert decode_reply(master.interpreter(encode_query("EC"))[0]).value == 2
    assert decode_reply(master.interpreter(encode_query("AC"))[0]).value == 100_000  # nothing was set


def test_frames_too_short_for_letters_and_index_stay_unanswered(master):
    master.nmt(0x01)
    for request_hex in ("", "41", "41 43 00"):
        assert master.interpreter(bytes.fromhex(request_hex)) == [], request_hex


def test_the_malformed_frame_error_code_is_a_setting():
    node = Node(malformed_command_error=19)
    node.nmt(0x01)
    assert node.frame(RPDO2, bytes.fromhex("61 63 00 00")) == [(TPDO2, bytes.fromhex("61 63 00 40 13 00 00 00"))]
    with pytest.raises(ValueError, match="malformed_command_error"):
        SimSettings(malformed_command_error=256)


def test_reset_communication_keeps_the_application_reset_node_does_not(master):
    master.nmt(0x01)
    assert master.interpreter(encode_set("AC", 0, 150_000)) == [encode_set("AC", 0, 150_000)]
    master.write(0x1017, 0, 100, size=2)
    boot = master.heard(0x700 + W, (0x000, bytes([0x82, W])))
    assert boot == [b"\x00"]  # boot-up, Pre-operational
    assert master.read(0x1017) == 0  # communication objects: their saved values
    master.nmt(0x01)
    assert decode_reply(master.interpreter(encode_query("AC"))[0]).value == 150_000  # RAM kept
    assert master.heard(0x700 + W, (0x000, bytes([0x81, W]))) == [b"\x00"]
    master.nmt(0x01)
    assert decode_reply(master.interpreter(encode_query("AC"))[0]).value == 100_000  # RAM from flash


def test_remote_frames_on_the_sync_id_are_no_sync(master):
    master.sync_tpdo1()
    master.nmt(0x01)
    assert master.heard(0x180 + W, *[(0x080, b"", True)] * 5) == []
    assert master.heard(0x180 + W, (0x080, b"")) == [bytes(4)]


def test_no_emcy_while_stopped_the_error_is_stored_and_clearing_it_sends_0000(master):
    emcy = 0x080 + W
    got: list[bytes] = []
    master.network.subscribe(emcy, lambda can_id, data, ts: got.append(bytes(data)))
    master.nmt(0x02)  # Stopped
    drive = master.arm.drives["yaw_drive"]
    with master.arm.lock:
        drive.trip()  # a drive fault now (position limit: MF 0x400000, EMCY 0x8680)
        drive.tick()
    master.nmt(0x80)  # Pre-operational: SDO again
    assert got == []  # CiA 301: a Stopped node sends no EMCY
    assert master.read(0x1003, 0) == 1
    assert master.read(0x1003, 1) == 0x8680 | 0x01 << 16  # but it keeps the error
    master.nmt(0x01)
    assert master.interpreter(encode_set("MO", 0, 1)) == [encode_set("MO", 0, 1)]
    assert got == [bytes(8)]  # MO=1 cleared the fault: EMCY 0x0000 "error reset / no error"
    # 0x1003:0 := 0 deletes the history; any other value is refused
    assert master.refused(0x1003, 0, 1, size=1) == INVALID
    master.write(0x1003, 0, 0, size=1)
    assert master.read(0x1003, 0) == 0
    master.network.unsubscribe(emcy)


def test_a_group_id_acts_only_after_reset_communication_as_the_guide_says(master):
    """Elmo's guide (13-10): write 0x2040, then reset communication. Before it a BG to 0x300 + group
    id reaches no drive (no reply); after it the same frame reaches the drive, which answers on its
    own TPDO2 (here the guide's own example: EC 58, the motor is off). 0x2040 is application RAM:
    the reset keeps it."""
    master.nmt(0x01)
    master.write(0x2040, 0, 125, size=1)
    assert master.heard(0x280 + W, (0x300 + 125, encode_execute("BG"))) == []
    assert master.heard(0x700 + W, (0x000, bytes([0x82, W]))) == [b"\x00"]
    assert master.read(0x2040, 0) == 125
    master.nmt(0x01)
    assert master.heard(0x280 + W, (0x300 + 125, encode_execute("BG"))) == [bytes.fromhex("424700403A000000")]
