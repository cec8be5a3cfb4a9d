"""Byte-exact transcripts of DriveClient talking to a SimDrive.

``SimLink`` is a synchronous in-test Transport: every client frame is handed to the SimDrive
(``receive`` then ``tick``) and whatever the drive puts out is recorded and delivered to the
client's subscribers before ``send`` returns. One ManualClock is shared by the drive and the
client (``clock=`` / ``sleep=``), so the MO settle window and the SV blackout run in simulated
time and every transcript below is exact: each frame in both directions, in order, byte for byte.

The only real-time waits are the client's ``Event.wait(timeout)`` for replies that never come;
``timeout`` is 1 ms so an unanswered poll costs next to nothing.
"""

from __future__ import annotations

import pytest

from sherpa_cli.elmo.client import ClientSettings, DriveClient
from sherpa_cli.elmo.transport import frame_text
from sherpa_cli.errors import DriveRefusedError
from sherpa_cli.sim import ManualClock, SimSettings
from sherpa_cli.sim.drive import SimDrive

NODE = 10
NMT, RPDO2, TPDO2, HB = 0x000, 0x300 + NODE, 0x280 + NODE, 0x700 + NODE
REPLY_TIMEOUT = 0.001  # real seconds the client waits for a reply that the drive never sends
POLL = 0.01  # ClientSettings.mo_poll_interval used below (simulated seconds)
SLEEP_STEP = 0.005  # the fake sleep advances the drive in steps this small, so nothing is skipped


def hx(text: str) -> bytes:
    return bytes.fromhex(text)


def tx(can_id: int, text: str) -> tuple[str, int, bytes]:
    return ("tx", can_id, hx(text))


def rx(can_id: int, text: str) -> tuple[str, int, bytes]:
    return ("rx", can_id, hx(text))


class SimLink:
    """Transport that wires a DriveClient straight to one SimDrive, synchronously, and records everything."""

    def __init__(self, drive: SimDrive, clock: ManualClock) -> None:
        self.drive = drive
        self.clock = clock
        self.log: list[tuple[str, int, bytes]] = []
        self.times: list[float] = []  # simulated time of each log entry
        self._subscribers: dict[int, list] = {}
        self.flush()  # the boot-up frame the drive sent at power-up

    # -- Transport --
    def subscribe(self, can_id: int, callback) -> None:
        self._subscribers.setdefault(can_id, []).append(callback)

    def send(self, can_id: int, data: bytes) -> None:
        data = bytes(data)
        self._record("tx", can_id, data)
        self.drive.receive(can_id, data)
        self.drive.tick()
        self.flush()

    # -- helpers --
    def flush(self) -> None:
        for can_id, data in self.drive.pop_frames():
            self._record("rx", can_id, bytes(data))
            for callback in list(self._subscribers.get(can_id, ())):
                callback(can_id, bytes(data), self.clock.now())

    def sleep(self, seconds: float) -> None:
        """The client's sleep: simulated time passes, the drive runs, its frames are delivered."""
        left = seconds
        while left > 1e-12:
            step = min(SLEEP_STEP, left)
            self.clock.advance(step)
            left -= step
            self.drive.tick()
            self.flush()

    def take(self) -> list[tuple[str, int, bytes]]:
        """The log so far, cleared: each test step asserts just its own frames."""
        log, self.log, self.times = self.log, [], []
        return log

    def _record(self, direction: str, can_id: int, data: bytes) -> None:
        self.log.append((direction, can_id, data))
        self.times.append(self.clock.now())


def text(log) -> list[str]:
    """Readable form for assertion messages (``tx 0x30A 41 43 00 00``)."""
    return [frame_text(*step) for step in log]


def assert_transcript(got, want) -> None:
    assert text(got) == text(want)
    assert got == want  # and the raw tuples, types included


def make(*, sim: SimSettings | None = None, client: ClientSettings | None = None, start: bool = True):
    clock = ManualClock()
    drive = SimDrive(NODE, clock=clock, settings=sim or SimSettings(), serial=0x5A00010A)
    link = SimLink(drive, clock)
    c = DriveClient(link, NODE, name="drive1", timeout=REPLY_TIMEOUT, retries=0,
                    clock=clock.now, sleep=link.sleep,
                    settings=client or ClientSettings(mo_poll_interval=POLL))
    assert_transcript(link.take(), [rx(HB, "00")])  # boot-up, before anything else
    if start:
        c.nmt_start()
        assert_transcript(link.take(), [tx(NMT, "01 0A")])
    return clock, drive, link, c


def motor_on(c: DriveClient, link: SimLink) -> None:
    c.motor_on()
    link.take()


# -- plain get / set -----------------------------------------------------------------------------

def test_nmt_start_then_get_ac_returns_factory_value():
    _clock, _drive, link, c = make(start=False)
    c.nmt_start()
    assert c.get("AC") == 100_000  # factory AC of the simulated drive
    assert_transcript(link.take(), [
        tx(NMT, "01 0A"),
        tx(RPDO2, "41 43 00 00"),  # DLC 4 query
        rx(TPDO2, "41 43 00 00 A0 86 01 00"),  # 100000
    ])


def test_set_ac_with_echo_then_get():
    _clock, drive, link, c = make()
    c.set("AC", 0, 150_000)
    assert c.get("AC") == 150_000
    assert_transcript(link.take(), [
        tx(RPDO2, "41 43 00 00 F0 49 02 00"),  # [IG] example AC=150000
        rx(TPDO2, "41 43 00 00 F0 49 02 00"),  # echo
        tx(RPDO2, "41 43 00 00"),
        rx(TPDO2, "41 43 00 00 F0 49 02 00"),
    ])
    assert drive.ram["AC"] == 150_000


def test_bg_with_motor_off_is_refused_with_error_58():
    _clock, _drive, link, c = make()
    with pytest.raises(DriveRefusedError) as info:
        c.execute("BG")
    assert info.value.code == 58
    assert "drive1 (node 10)" in str(info.value)
    assert_transcript(link.take(), [
        tx(RPDO2, "42 47 00 00"),
        rx(TPDO2, "42 47 00 40 3A 00 00 00"),  # [IG] example: error bit, EC 58 in byte 4
    ])


def test_set_ll3_with_motor_on_is_refused_with_error_57():
    _clock, drive, link, c = make(sim=SimSettings(mo_settle_s=0.05))
    motor_on(c, link)
    with pytest.raises(DriveRefusedError) as info:
        c.set("LL", 3, -240)
    assert info.value.code == 57
    assert c.get("LL", 3) == -1_000_000_000  # unchanged factory value
    assert_transcript(link.take(), [
        tx(RPDO2, "4C 4C 03 00 10 FF FF FF"),  # LL[3]=-240
        rx(TPDO2, "4C 4C 03 40 39 00 00 00"),  # error 57: motor must be off
        tx(RPDO2, "4C 4C 03 00"),
        rx(TPDO2, "4C 4C 03 00 00 36 65 C4"),  # -1e9
    ])
    assert drive.last_error == 57


# -- composite operations ------------------------------------------------------------------------

def test_motor_on_polls_through_the_settle_window():
    # Settle 50 ms, polls every 10 ms: the polls at t = 0, 10, 20, 30, 40 ms are ignored by the
    # drive, the one at 50 ms is answered with MO=1.
    clock, drive, link, c = make(sim=SimSettings(mo_settle_s=0.05))
    c.motor_on()
    mo_query = tx(RPDO2, "4D 4F 00 00")
    assert_transcript(link.take(), [
        tx(RPDO2, "4D 4F 00 00 01 00 00 00"),  # MO=1
        rx(TPDO2, "4D 4F 00 00 01 00 00 00"),  # echo (the reply leaves before the window starts)
        *[mo_query] * 5,  # unanswered
        mo_query,
        rx(TPDO2, "4D 4F 00 00 01 00 00 00"),
    ])
    assert drive.motor_on
    assert clock.now() == pytest.approx(0.05)


def test_motor_on_with_the_default_500ms_window():
    clock, _drive, link, c = make()
    c.motor_on()
    log = link.take()
    polls = log[2:-2]
    assert log[:2] == [tx(RPDO2, "4D 4F 00 00 01 00 00 00"), rx(TPDO2, "4D 4F 00 00 01 00 00 00")]
    assert polls == [tx(RPDO2, "4D 4F 00 00")] * 50  # 0 .. 490 ms, none answered
    assert log[-2:] == [tx(RPDO2, "4D 4F 00 00"), rx(TPDO2, "4D 4F 00 00 01 00 00 00")]
    assert clock.now() == pytest.approx(0.5)


def test_save_sv_reply_silent_blackout_then_confirming_query():
    clock, drive, link, c = make()
    c.set("AC", 0, 150_000)
    link.take()
    t0 = clock.now()
    c.save()
    times = list(link.times)
    assert_transcript(link.take(), [
        tx(RPDO2, "53 56 00 00"),
        rx(TPDO2, "53 56 00 00 00 00 00 00"),
        # nothing in either direction during the blackout
        tx(RPDO2, "4D 4F 00 00"),
        rx(TPDO2, "4D 4F 00 00 00 00 00 00"),
    ])
    assert times[0] == t0 and times[1] == t0
    assert times[2] - t0 == pytest.approx(0.5)  # ClientSettings.sv_blackout
    assert drive.lost == []  # the client sent nothing into the drive's 300 ms blackout
    assert drive.save_count == 1
    assert drive.flash["AC"] == 150_000


def test_save_with_heartbeat_shows_the_drive_silent_during_its_blackout():
    # With a 100 ms heartbeat the only frames between the SV reply and the confirming query are
    # heartbeats, and none of them falls inside the drive's 300 ms blackout.
    clock, _drive, link, c = make(sim=SimSettings(heartbeat_ms=100))
    link.sleep(0.05)
    link.take()
    t0 = clock.now()
    c.save()
    log = link.take()
    frames = [(d, i) for d, i, _ in log]
    assert frames[:2] == [("tx", RPDO2), ("rx", TPDO2)]
    assert frames[-2:] == [("tx", RPDO2), ("rx", TPDO2)]
    middle = log[2:-2]
    assert all(step == rx(HB, "05") for step in middle), text(middle)
    assert len(middle) == 2  # beats at 0.4 and 0.5 s; 0.1 .. 0.3 s fall into the blackout
    assert clock.now() - t0 == pytest.approx(0.5)


# -- protocol variants ---------------------------------------------------------------------------

def test_long_queries():
    _clock, _drive, link, c = make(client=ClientSettings(query_long=True, mo_poll_interval=POLL))
    assert c.get("AC") == 100_000
    c.set("AC", 0, 150_000)
    assert c.get("AC") == 150_000
    assert_transcript(link.take(), [
        tx(RPDO2, "41 43 00 40 00 00 00 00"),  # DLC 8 with the query bit
        rx(TPDO2, "41 43 00 00 A0 86 01 00"),
        tx(RPDO2, "41 43 00 00 F0 49 02 00"),
        rx(TPDO2, "41 43 00 00 F0 49 02 00"),
        tx(RPDO2, "41 43 00 40 00 00 00 00"),
        rx(TPDO2, "41 43 00 00 F0 49 02 00"),
    ])


def test_long_queries_for_an_array_entry():
    _clock, _drive, link, c = make(client=ClientSettings(query_long=True, mo_poll_interval=POLL))
    assert c.get("LL", 3) == -1_000_000_000
    assert_transcript(link.take(), [
        tx(RPDO2, "4C 4C 03 40 00 00 00 00"),
        rx(TPDO2, "4C 4C 03 00 00 36 65 C4"),
    ])


def test_set_echo_off_confirms_by_read_back():
    _clock, _drive, link, c = make(sim=SimSettings(echo_sets=False),
                                 client=ClientSettings(expect_set_echo=False, mo_poll_interval=POLL))
    assert c.get("AC") == 100_000
    c.set("AC", 0, 150_000)
    assert_transcript(link.take(), [
        tx(RPDO2, "41 43 00 00"),
        rx(TPDO2, "41 43 00 00 A0 86 01 00"),
        tx(RPDO2, "41 43 00 00 F0 49 02 00"),  # the drive stays silent on success
        tx(RPDO2, "41 43 00 00"),  # read-back
        rx(TPDO2, "41 43 00 00 F0 49 02 00"),
    ])


def test_set_echo_off_with_long_queries():
    _clock, _drive, link, c = make(sim=SimSettings(echo_sets=False),
                                 client=ClientSettings(expect_set_echo=False, query_long=True,
                                                       mo_poll_interval=POLL))
    c.set("AC", 0, 150_000)
    assert_transcript(link.take(), [
        tx(RPDO2, "41 43 00 00 F0 49 02 00"),
        tx(RPDO2, "41 43 00 40 00 00 00 00"),
        rx(TPDO2, "41 43 00 00 F0 49 02 00"),
    ])


def test_missing_echo_is_read_back_when_the_client_expects_one():
    # elmo-protocol.md 1.3: a missing echo means "unknown", so the client re-queries.
    _clock, _drive, link, c = make(sim=SimSettings(echo_sets=False))
    c.set("AC", 0, 150_000)
    assert_transcript(link.take(), [
        tx(RPDO2, "41 43 00 00 F0 49 02 00"),  # sent once, no echo comes
        tx(RPDO2, "41 43 00 00"),
        rx(TPDO2, "41 43 00 00 F0 49 02 00"),
    ])


def test_motor_on_with_echo_off():
    _clock, _drive, link, c = make(sim=SimSettings(echo_sets=False, mo_settle_s=0.02),
                                 client=ClientSettings(expect_set_echo=False, mo_poll_interval=POLL))
    c.motor_on()
    mo_query = tx(RPDO2, "4D 4F 00 00")
    assert_transcript(link.take(), [
        tx(RPDO2, "4D 4F 00 00 01 00 00 00"),
        mo_query, mo_query,  # t = 0, 10 ms: in the settle window
        mo_query,
        rx(TPDO2, "4D 4F 00 00 01 00 00 00"),
    ])


def test_set_echo_off_refusal_reports_the_drive_error_code():
    _clock, _drive, link, c = make(sim=SimSettings(echo_sets=False, mo_settle_s=0.02),
                                 client=ClientSettings(expect_set_echo=False, mo_poll_interval=POLL))
    c.motor_on()
    link.take()
    with pytest.raises(DriveRefusedError) as info:
        c.set("LL", 3, -240)
    assert info.value.code == 57


def test_set_echo_off_refusal_transcript():
    # The set and its read-back go out under one pending (LL,3): the error reply is caught.
    _clock, _drive, link, c = make(sim=SimSettings(echo_sets=False, mo_settle_s=0.02),
                                 client=ClientSettings(expect_set_echo=False, mo_poll_interval=POLL))
    c.motor_on()
    link.take()
    with pytest.raises(DriveRefusedError):
        c.set("LL", 3, -240)
    assert_transcript(link.take(), [
        tx(RPDO2, "4C 4C 03 00 10 FF FF FF"),
        rx(TPDO2, "4C 4C 03 40 39 00 00 00"),  # errors are replied even with echo off
        tx(RPDO2, "4C 4C 03 00"),
        rx(TPDO2, "4C 4C 03 00 00 36 65 C4"),
    ])
