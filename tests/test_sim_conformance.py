"""CiA 301 conformance of the simulated drive.

- NMT Stopped: only NMT and error control (heartbeat) work; no SDO answer, no interpreter.
- SDO: after an abort (either side) or a finished transfer a stray segment request is aborted,
  not served from the old transfer; block transfers are aborted with "command specifier not
  valid"; frames that are not 8 bytes are no SDO requests.
- The interpreter accepts long queries with and without the float type bit.
- A stock `canopen` client against `sherpa sim --serve` gets no SDO answer from a Stopped node.
"""

from __future__ import annotations

import struct

import pytest
from test_cross_process import served_sim  # noqa: F401  (the fixture: `sherpa sim --serve` in a subprocess)

from sherpa_cli.elmo.codec import decode_reply, encode_query
from sherpa_cli.sim import ManualClock, SimSettings
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
