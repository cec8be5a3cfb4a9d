"""DriveClient: byte-exact transcripts (FakeTransport), a threaded two-drive bus, a real canopen Network.

Node 10 throughout: requests on 0x30A, replies on 0x28A, EMCY on 0x08A. Frames are the manual's
vectors where it prints them (elmo-protocol.md 1.2/1.3), derived by the same rules otherwise.
"""

from __future__ import annotations

import queue
import threading
import time

import pytest

from sherpa_cli.elmo import codec
from sherpa_cli.elmo.client import ClientSettings, DriveClient
from sherpa_cli.elmo.codec import decode_request, encode_reply
from sherpa_cli.elmo.faults import Emcy
from sherpa_cli.elmo.transport import FakeTransport, NetworkTransport, parse_transcript
from sherpa_cli.errors import CommunicationError, DriveRefusedError, DriveTimeoutError, ProtocolError

NODE = 10
TX, RX, EMCY = 0x30A, 0x28A, 0x08A
# Unanswered waits are real time; keep them short so a whole dead-node test costs milliseconds.
SHORT = 0.01


class FakeClock:
    """Injected clock/sleep: sleeping advances time instantly and is recorded."""

    def __init__(self, transport: FakeTransport | None = None) -> None:
        self.now = 0.0
        self.sleeps: list[float] = []
        self.frames_before_sleep: list[int] = []
        self.transport = transport

    def __call__(self) -> float:
        return self.now

    def sleep(self, seconds: float) -> None:
        self.sleeps.append(seconds)
        if self.transport is not None:
            self.frames_before_sleep.append(len(self.transport.sent))
        self.now += seconds


def drive(script, *, clock: FakeClock | None = None, timeout: float = SHORT, retries: int = 1,
          **settings) -> tuple[DriveClient, FakeTransport, FakeClock]:
    transport = FakeTransport(script)
    clock = clock or FakeClock()
    clock.transport = transport
    client = DriveClient(transport, NODE, name="shoulder_1a", timeout=timeout, retries=retries,
                         clock=clock, sleep=clock.sleep, settings=ClientSettings(**settings))
    return client, transport, clock


# -- queries ------------------------------------------------------------------------------------

def test_get_ac_short_query():
    client, bus, _ = drive([
        ("tx", TX, "41 43 00 00"),
        ("rx", RX, "41 43 00 00 F0 49 02 00"),
    ])
    assert client.get("AC") == 150000
    bus.done()


def test_get_long_query_option():
    client, bus, _ = drive([
        ("tx", TX, "41 43 00 40 00 00 00 00"),
        ("rx", RX, "41 43 00 00 F0 49 02 00"),
    ], query_long=True)
    assert client.get("AC") == 150000
    bus.done()


def test_get_float_follows_reply_type_bit():
    client, bus, _ = drive([
        ("tx", TX, "43 4C 01 00"),
        ("rx", RX, "43 4C 01 80 00 00 80 3F"),
    ])
    value = client.get("CL", 1)
    assert value == 1.0 and isinstance(value, float)
    bus.done()


def test_reply_for_other_letters_or_index_is_ignored():
    client, bus, _ = drive([
        ("tx", TX, "4C 4C 03 00"),
        ("rx", RX, "50 58 00 00 07 00 00 00"),  # PX = 7: other letters
        ("rx", RX, "4C 4C 02 00 09 00 00 00"),  # LL[2] = 9: other index
        ("rx", RX, "50 58 00 00"),  # DLC 4 of other letters: malformed and not ours, dropped
        ("rx", RX, "4C 4C 03 00 10 FF FF FF"),  # LL[3] = -240: the answer
    ])
    assert client.get("LL", 3) == -240
    bus.done()


@pytest.mark.parametrize("reply, problem", [
    ("4C 4C 03 00", "must be 8 bytes, got 4"),  # the right header, the wrong length
    ("4C", "must be 8 bytes, got 1"),  # too short to carry any header: it can only be the answer
    ("4C 4C 03 00 10 FF FF FF 00", "must be 8 bytes, got 9"),
    ("43 4C 01 80 00 00 C0 7F", "not a finite number"),  # CL[1] = NaN
    ("43 4C 01 80 00 00 80 7F", "not a finite number"),  # CL[1] = +Inf
    ("FF FE 03 00 00 00 00 00", "not ASCII"),
])
def test_malformed_reply_fails_the_request_naming_drive_and_frame(reply, problem):
    letters, index = ("CL", 1) if reply.startswith("43 4C") else ("LL", 3)
    query = "43 4C 01 00" if letters == "CL" else "4C 4C 03 00"
    client, bus, _ = drive([("tx", TX, query), ("rx", RX, reply)], timeout=5.0)
    started = time.monotonic()
    with pytest.raises(ProtocolError) as info:
        client.get(letters, index)
    assert time.monotonic() - started < 2.0  # failed at once, not after the timeout
    text = str(info.value)
    assert text.startswith(f"shoulder_1a (node 10): malformed reply to {letters}[{index}]: TPDO2 0x28A")
    assert reply in text and problem in text and "no answer" not in text
    assert info.value.exit_code == 3
    bus.done()


def test_malformed_reply_fails_a_set_and_the_next_request_works():
    client, bus, _ = drive([
        ("tx", TX, "43 4C 01 80 00 00 80 3F"),
        ("rx", RX, "43 4C 01 80 00 00 C0 7F"),  # the echo carries NaN
        ("tx", TX, "41 43 00 00"),
        ("rx", RX, "41 43 00 00 F0 49 02 00"),
    ], timeout=5.0)
    with pytest.raises(ProtocolError, match="malformed reply to CL\\[1\\]"):
        client.set("CL", 1, 1.0)
    assert client.get("AC") == 150000
    bus.done()


def test_long_query_of_a_float_parameter_carries_the_float_bit():
    client, bus, _ = drive([
        ("tx", TX, "43 4C 01 C0 00 00 00 00"),  # [IG] 9-3: the type bit in every frame
        ("rx", RX, "43 4C 01 80 00 00 80 3F"),
    ], query_long=True)
    assert client.get("CL", 1) == 1.0
    bus.done()


def test_dead_node_times_out_naming_drive_command_and_timeout():
    client, bus, _ = drive([
        ("tx", TX, "4C 4C 03 00"),
        ("tx", TX, "4C 4C 03 00"),  # the one resend (retries=1)
    ], timeout=0.02)
    started = time.monotonic()
    with pytest.raises(DriveTimeoutError) as info:
        client.get("LL", 3)
    assert time.monotonic() - started < 1.0
    assert str(info.value) == "shoulder_1a (node 10): no answer to LL[3] within 0.02 s (2 attempts)"
    bus.done()


# -- sets -----------------------------------------------------------------------------------------

def test_set_confirmed_by_echo():
    client, bus, _ = drive([
        ("tx", TX, "41 43 00 00 F0 49 02 00"),
        ("rx", RX, "41 43 00 00 F0 49 02 00"),
    ])
    client.set("AC", 0, 150000)
    bus.done()


def test_set_float_echo_compared_after_float32_rounding():
    client, bus, _ = drive([
        ("tx", TX, "43 4C 01 80 CD CC CC 3D"),
        ("rx", RX, "43 4C 01 80 CD CC CC 3D"),
    ])
    client.set("CL", 1, 0.1)  # 0.1 is not a float32; the echo carries the rounded value
    bus.done()


def test_set_echo_with_other_value_is_an_error():
    client, bus, _ = drive([
        ("tx", TX, "41 43 00 00 F0 49 02 00"),
        ("rx", RX, "41 43 00 00 E8 03 00 00"),
    ])
    with pytest.raises(CommunicationError, match=r"AC=150000 was echoed as AC=1000"):
        client.set("AC", 0, 150000)
    bus.done()


def test_set_without_echo_is_confirmed_by_query():
    client, bus, _ = drive([
        ("tx", TX, "41 43 00 00 F0 49 02 00"),
        ("tx", TX, "41 43 00 00"),
        ("rx", RX, "41 43 00 00 F0 49 02 00"),
    ], expect_set_echo=False)
    client.set("AC", 0, 150000)
    bus.done()


def test_missing_echo_is_requeried_once_and_matching_value_accepted():
    client, bus, _ = drive([
        ("tx", TX, "41 43 00 00 F0 49 02 00"),  # echo lost: not resent
        ("tx", TX, "41 43 00 00"),
        ("rx", RX, "41 43 00 00 F0 49 02 00"),
    ])
    client.set("AC", 0, 150000)
    bus.done()


def test_missing_echo_and_other_value_on_requery_is_an_error():
    client, bus, _ = drive([
        ("tx", TX, "41 43 00 00 F0 49 02 00"),
        ("tx", TX, "41 43 00 00"),
        ("rx", RX, "41 43 00 00 E8 03 00 00"),
    ])
    with pytest.raises(CommunicationError, match=r"AC=150000 not confirmed: AC reads back 1000"):
        client.set("AC", 0, 150000)
    bus.done()


def test_error_reply_57_on_ll3_raises_refused_with_code_and_text():
    client, bus, _ = drive([
        ("tx", TX, "4C 4C 03 00 10 FF FF FF"),
        ("rx", RX, "4C 4C 03 40 39 00 00 00"),
    ])
    with pytest.raises(DriveRefusedError) as info:
        client.set("LL", 3, -240)
    err = info.value
    assert str(err) == "shoulder_1a (node 10): LL[3]=-240 refused: error 57 motor must be off"
    assert (err.code, err.command, err.drive) == (57, "LL[3]=-240", "shoulder_1a (node 10)")
    bus.done()


def test_unechoed_set_refused_through_emcy_6300():
    # Elmo's table (IG 9-1): no reply to a set, an EMCY 0x6300 carrying the EC if it fails.
    client, bus, _ = drive([
        ("tx", TX, "4C 4C 03 00 10 FF FF FF"),
        ("rx", EMCY, "00 63 01 39 01 20 00 00"),
        ("tx", TX, "4C 4C 03 00"),
        ("rx", RX, "4C 4C 03 00 00 00 00 00"),
    ], expect_set_echo=False)
    with pytest.raises(DriveRefusedError) as info:
        client.set("LL", 3, -240)
    assert info.value.code == 57
    bus.done()


# -- execute, raw ---------------------------------------------------------------------------------

def test_execute_bg_success():
    client, bus, _ = drive([
        ("tx", TX, "42 47 00 00"),
        ("rx", RX, "42 47 00 00 00 00 00 00"),
    ])
    client.execute("BG")
    bus.done()


def test_execute_bg_motor_off_refused():
    client, bus, _ = drive([
        ("tx", TX, "42 47 00 00"),
        ("rx", RX, "42 47 00 40 3A 00 00 00"),
    ])
    with pytest.raises(DriveRefusedError, match=r"^shoulder_1a \(node 10\): BG refused: error 58 motor must be on$"):
        client.execute("BG")
    bus.done()


def test_raw_request_returns_error_reply_without_raising():
    client, bus, _ = drive([
        ("tx", TX, "43 41 01 00 04 00 00 00"),
        ("rx", RX, "43 41 01 40 15 00 00 00"),
    ])
    reply = client.request(bytes.fromhex("43 41 01 00 04 00 00 00"))
    assert (reply.letters, reply.index, reply.error_code, reply.error_text) == ("CA", 1, 21, "operand out of range")
    bus.done()


# -- SV and MO ------------------------------------------------------------------------------------

def test_save_waits_out_blackout_then_checks_drive_answers():
    client, bus, clock = drive([
        ("tx", TX, "53 56 00 00"),
        ("rx", RX, "53 56 00 00 00 00 00 00"),
        ("tx", TX, "4D 4F 00 00"),
        ("rx", RX, "4D 4F 00 00 00 00 00 00"),
    ])
    client.save()
    assert clock.sleeps == [0.5]
    assert clock.frames_before_sleep == [1]  # silent from SV until the blackout is over
    bus.done()


def test_save_is_never_resent_when_its_reply_is_lost():
    client, bus, clock = drive([
        ("tx", TX, "53 56 00 00"),
        ("tx", TX, "4D 4F 00 00"),
        ("rx", RX, "4D 4F 00 00 00 00 00 00"),
    ], retries=3)
    client.save()
    assert clock.sleeps == [0.5]
    bus.done()


def test_execute_sv_goes_through_save():
    client, bus, clock = drive([
        ("tx", TX, "53 56 00 00"),
        ("rx", RX, "53 56 00 00 00 00 00 00"),
        ("tx", TX, "4D 4F 00 00"),
        ("rx", RX, "4D 4F 00 00 00 00 00 00"),
    ])
    client.execute("SV")
    assert clock.sleeps == [0.5]
    bus.done()


def test_save_refused_with_motor_on_does_not_wait():
    client, bus, clock = drive([
        ("tx", TX, "53 56 00 00"),
        ("rx", RX, "53 56 00 40 39 00 00 00"),
    ])
    with pytest.raises(DriveRefusedError, match="SV refused: error 57 motor must be off"):
        client.save()
    assert clock.sleeps == []
    bus.done()


def test_motor_on_tolerates_silent_settle_window():
    client, bus, clock = drive([
        ("tx", TX, "4D 4F 00 00 01 00 00 00"),
        ("rx", RX, "4D 4F 00 00 01 00 00 00"),
        ("tx", TX, "4D 4F 00 00"),  # settling: no answer
        ("tx", TX, "4D 4F 00 00"),  # settling: no answer
        ("tx", TX, "4D 4F 00 00"),
        ("rx", RX, "4D 4F 00 00 01 00 00 00"),
    ])
    client.motor_on()
    assert clock.sleeps == [0.01, 0.01]
    bus.done()


def test_an_mo_poll_in_the_settle_window_waits_only_until_the_window_ends(monkeypatch):
    # The drive is deaf for protocol.mo_settle after MO=1: a poll then must not wait out a whole
    # reply timeout (1 s here) but only the rest of the window, so MO=1 confirms at ~mo_settle.
    client, _bus, clock = drive([("tx", TX, "4D 4F 00 00 01 00 00 00"), ("rx", RX, "4D 4F 00 00 01 00 00 00")],
                               timeout=1.0, mo_settle=0.5)
    waits: list[float | None] = []
    real_exchange = client._exchange

    def exchange(frame, letters, index, *, attempts, before=None, wait=None):
        if letters == "MO" and len(frame) == 4:  # a poll: the drive is deaf until t = 0.5
            waits.append(wait)
            clock.now += wait if wait is not None else client.timeout
            if clock.now < 0.5 - 1e-9:
                return None
            return codec.decode_reply(bytes.fromhex("4D 4F 00 00 01 00 00 00"))
        return real_exchange(frame, letters, index, attempts=attempts, before=before)

    monkeypatch.setattr(client, "_exchange", exchange)
    client.motor_on()
    assert waits == [pytest.approx(0.5)]  # not the 1 s reply timeout
    assert clock.now == pytest.approx(0.5)


def test_motor_on_not_confirmed_by_deadline():
    polls = [("tx", TX, "4D 4F 00 00")] * 5  # at t = 0, 0.25, 0.5, 0.75, 1.0 on the fake clock
    client, bus, clock = drive([
        ("tx", TX, "4D 4F 00 00 01 00 00 00"),
        ("rx", RX, "4D 4F 00 00 01 00 00 00"),
        *polls,
        ("rx", RX, "4D 4F 00 00 00 00 00 00"),
    ], mo_confirm_timeout=1.0, mo_poll_interval=0.25)
    with pytest.raises(CommunicationError, match=r"MO=1 not confirmed: MO still reads 0 after 1 s"):
        client.motor_on()
    assert clock.now == 1.0
    bus.done()


def test_motor_off_never_answering_is_a_timeout():
    client, bus, _ = drive([
        ("tx", TX, "4D 4F 00 00 00 00 00 00"),
        ("tx", TX, "4D 4F 00 00"),
        ("tx", TX, "4D 4F 00 00"),
    ], mo_confirm_timeout=0.5, mo_poll_interval=0.5)
    with pytest.raises(DriveTimeoutError, match=r"shoulder_1a \(node 10\): MO=0 not confirmed: no answer to MO"):
        client.motor_off()
    bus.done()


def test_motor_on_refused():
    client, bus, _ = drive([
        ("tx", TX, "4D 4F 00 00 01 00 00 00"),
        ("rx", RX, "4D 4F 00 40 33 00 00 00"),
    ])
    with pytest.raises(DriveRefusedError, match="MO=1 refused: error 51 inhibit or abort input active"):
        client.motor_on()
    bus.done()


# -- NMT, EMCY ------------------------------------------------------------------------------------

def test_nmt_frames():
    client, bus, _ = drive([
        ("tx", 0x000, "01 0A"),
        ("tx", 0x000, "82 0A"),
    ])
    client.nmt_start()
    client.nmt_reset_communication()
    bus.done()


def test_emcy_decoded_to_callback_and_kept():
    client, bus, _ = drive([
        ("rx", 0x08B, "80 86 81 00 00 00 00 00"),  # node 11: not ours
        ("rx", EMCY, "80 86 81 00 00 00 00 00"),
    ])
    seen: list[Emcy] = []
    client.on_emcy(seen.append)
    bus.pump()
    assert [(e.code, e.error_register, e.meaning) for e in seen] == [(0x8680, 0x81, "position limit exceeded")]
    assert client.last_emcy == seen[0]
    bus.done()


# -- FakeTransport itself -------------------------------------------------------------------------

def test_fake_transport_reports_both_frames_on_mismatch():
    client, _bus, _ = drive([("tx", TX, "41 43 00 40 00 00 00 00")])
    with pytest.raises(AssertionError, match=r"expected tx 0x30A 41 43 00 40 00 00 00 00, got tx 0x30A 41 43 00 00"):
        client.get("AC")


def test_fake_transport_done_fails_on_leftover_steps():
    _, bus, _ = drive([("tx", TX, "41 43 00 00")])
    with pytest.raises(AssertionError, match="1 step"):
        bus.done()


def test_transcript_text_form():
    steps = parse_transcript("""
        # get AC (IG 9-2)
        tx 30A 41 43 00 00
        rx 0x28A 41 43 00 00 F0 49 02 00
    """)
    client, bus, _ = drive(steps)
    assert client.get("AC") == 150000
    bus.done()


# -- two drives, replies from another thread ------------------------------------------------------

class ThreadedDrives:
    """Fake drives answering from their own thread, like a bus's receive thread.

    Requests are held until every drive has one outstanding (or the bus goes quiet), so the two
    drives are provably in flight at once. Each answer is preceded by a decoy reply (SR) that a
    client must not take for its answer. A second request from a drive that has not been answered
    yet is recorded as a violation of the one-request-per-drive rule.
    """

    def __init__(self, nodes: tuple[int, ...]) -> None:
        self.nodes = nodes
        self.subscribers: dict[int, list] = {}
        self.outstanding: dict[int, bytes] = {}
        self.violations: list[str] = []
        self.max_in_flight = 0
        self._inbox: queue.Queue[tuple[int, bytes]] = queue.Queue()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    @staticmethod
    def value(node: int, letters: str) -> int:
        return node * 1000 + {"PX": 1, "VX": 2}[letters]

    def subscribe(self, can_id, callback):
        self.subscribers.setdefault(can_id, []).append(callback)

    def send(self, can_id, data):
        self._inbox.put((can_id, bytes(data)))

    def close(self):
        self._stop.set()
        self._thread.join(timeout=5)

    def _run(self):
        while not self._stop.is_set():
            try:
                can_id, data = self._inbox.get(timeout=0.005)
            except queue.Empty:
                self._answer_all()
                continue
            node = can_id - 0x300
            if node in self.outstanding:
                self.violations.append(f"node {node}: {data.hex(' ')} while {self.outstanding[node].hex(' ')} open")
            self.outstanding[node] = data
            self.max_in_flight = max(self.max_in_flight, len(self.outstanding))
            if len(self.outstanding) == len(self.nodes):
                self._answer_all()

    def _answer_all(self):
        answers = list(self.outstanding.items())
        self.outstanding.clear()
        for node, data in answers:
            req = decode_request(data)
            self._deliver(0x280 + node, encode_reply("SR", 0, 0x7777, False))
            self._deliver(0x280 + node, encode_reply(req.letters, req.index, self.value(node, req.letters), False))

    def _deliver(self, can_id, data):
        for callback in self.subscribers.get(can_id, ()):
            callback(can_id, data, time.monotonic())


def test_two_drives_in_flight_one_request_each_no_cross_talk():
    bus = ThreadedDrives((10, 11))
    clients = [DriveClient(bus, n, name=f"d{n}", timeout=2.0) for n in (10, 11)]
    results: dict[tuple[int, str], list] = {}
    errors: list[BaseException] = []

    def worker(client: DriveClient, letters: str):
        got = results.setdefault((client.node, letters), [])
        try:
            for _ in range(15):
                got.append(client.get(letters))
        except BaseException as exc:  # noqa: BLE001  surfaced by the assertion below, not lost in the thread
            errors.append(exc)

    # Two threads per drive: without the per-drive lock they would overlap on the bus.
    threads = [threading.Thread(target=worker, args=(c, letters)) for c in clients for letters in ("PX", "VX")]
    try:
        for t in threads:
            t.start()
        for t in threads:
            t.join(timeout=20)
    finally:
        bus.close()
    assert errors == []
    assert bus.violations == []
    assert bus.max_in_flight == 2
    for (node, letters), got in results.items():
        assert got == [ThreadedDrives.value(node, letters)] * 15, (node, letters)


# -- the canopen adapter on a real (virtual) bus --------------------------------------------------

def test_network_transport_over_canopen_virtual_bus():
    can = pytest.importorskip("can")
    canopen = pytest.importorskip("canopen")
    channel = "sherpa-test-elmo-client"
    network = canopen.Network()
    network.NOTIFIER_CYCLE = 0.01  # its receive thread checks for shutdown this often
    network.connect(interface="virtual", channel=channel)
    drive_side = can.Bus(interface="virtual", channel=channel)

    def answer(msg):
        if msg.arbitration_id == TX and bytes(msg.data) == bytes.fromhex("41 43 00 00"):
            drive_side.send(can.Message(arbitration_id=RX, is_extended_id=False,
                                        data=bytes.fromhex("41 43 00 00 F0 49 02 00")))

    notifier = can.Notifier(drive_side, [answer], timeout=0.01)
    try:
        client = DriveClient(NetworkTransport(network), NODE, name="shoulder_1a", timeout=1.0)
        assert client.get("AC") == 150000
    finally:
        notifier.stop()
        drive_side.shutdown()
        network.disconnect()

