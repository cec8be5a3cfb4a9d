"""bus/sdo.py: every SDO failure is one SdoError naming drive and object; one client per drive per session."""

from __future__ import annotations

import struct
from collections.abc import Callable

import pytest

from sherpa_cli.bus.canopen_names import abort_text, nmt_text
from sherpa_cli.bus.sdo import DriveSdo, sdo_download, sdo_upload
from sherpa_cli.bus.session import ArmSession
from sherpa_cli.bus.targets import drive_ref
from sherpa_cli.config import load_config
from sherpa_cli.errors import CommunicationError, ExitCode, SdoError
from sherpa_cli.sim.arm import SimArm

EXAMPLE1 = "configs/appendix-c/example1.yaml"


class ScriptedNetwork:
    """What canopen's SDO client needs of a network; each request is answered by ``answer`` at once."""

    def __init__(self, answer: Callable[[int, bytes], bytes | None] | None = None,
                 fail: BaseException | None = None, sdo_timeout: float = 0.01) -> None:
        self.answer = answer
        self.fail = fail
        self.sdo_timeout = sdo_timeout
        self.subscribers: dict[int, list[Callable]] = {}
        self.sent: list[tuple[int, bytes]] = []

    def subscribe(self, can_id: int, callback: Callable) -> None:
        self.subscribers.setdefault(can_id, []).append(callback)

    def unsubscribe(self, can_id: int, callback: Callable | None = None) -> None:
        callbacks = self.subscribers.get(can_id, [])
        if callback in callbacks:
            callbacks.remove(callback)

    def send_message(self, can_id: int, data: bytes, remote: bool = False) -> None:
        if self.fail is not None:
            raise self.fail
        self.sent.append((can_id, bytes(data)))
        if self.answer is None or not 0x600 < can_id < 0x680 or data[0] == 0x80:
            return  # nobody answers; a client's abort gets no answer either
        reply = self.answer(can_id, bytes(data))
        if reply is not None:
            for callback in list(self.subscribers.get(can_id - 0x600 + 0x580, [])):
                callback(can_id - 0x600 + 0x580, reply, 0.0)


def expedited(data: bytes, index: int = 0x1018, sub: int = 4) -> Callable[[int, bytes], bytes]:
    n = 4 - len(data)
    return lambda can_id, req: bytes([0x43 | n << 2]) + struct.pack("<HB", index, sub) + data.ljust(4, b"\0")


def test_upload_through_a_scripted_network():
    net = ScriptedNetwork(expedited(bytes.fromhex("28 01 00 5A")))
    sdo = DriveSdo(net, 10, label="drive1 (node 10)")
    assert sdo.upload(0x1018, 4) == bytes.fromhex("28 01 00 5A")
    assert net.sent == [(0x60A, bytes.fromhex("40 18 10 04 00 00 00 00"))]
    assert sdo.timeout == 0.01  # the network's protocol.sdo_timeout
    sdo.close()
    assert all(not callbacks for callbacks in net.subscribers.values())


def test_timeout():
    sdo = DriveSdo(ScriptedNetwork(), 10, label="drive1 (node 10)")
    with pytest.raises(SdoError) as info:
        sdo.upload(0x1000, 0)
    e = info.value
    assert isinstance(e, CommunicationError) and e.exit_code == ExitCode.BUS
    assert str(e) == "drive1 (node 10): no answer to the SDO upload of 0x1000 within 0.01 s"
    assert e.detail == "no answer to the SDO upload of 0x1000 within 0.01 s"
    assert (e.reason, e.node, e.index, e.sub, e.abort_code) == ("timeout", 10, 0x1000, 0, None)
    assert e.hint == "check that the drive is powered and on this bus with this node id"


def test_abort_names_the_code_and_its_text():
    abort = lambda can_id, req: bytes([0x80]) + req[1:4] + struct.pack("<I", 0x06020000)  # noqa: E731
    with pytest.raises(SdoError) as info:
        sdo_upload(ScriptedNetwork(abort), 10, 0x2000, 3, label="drive1 (node 10)")
    e = info.value
    assert str(e) == ("drive1 (node 10): SDO upload of 0x2000:3 aborted with 0x06020000 "
                      "(object does not exist in the object dictionary)")
    assert (e.reason, e.abort_code) == ("abort", 0x06020000)
    with pytest.raises(SdoError, match=r"SDO download of 0x1017 aborted with 0x06010002 \(attempt to write a "
                                       r"read-only object\)"):
        abort_ro = lambda can_id, req: bytes([0x80]) + req[1:4] + struct.pack("<I", 0x06010002)  # noqa: E731
        sdo_download(ScriptedNetwork(abort_ro), 10, 0x1017, 0, b"\x64\x00")
    assert abort_text(0x12345678) == "unknown abort code"


@pytest.mark.parametrize("reply, why", [
    (bytes.fromhex("43 18"), "too short"),  # 2 bytes: not even command and index
    (bytes.fromhex("43 18 10 04 01 02"), "2 data byte(s) where the answer announces 4"),  # expedited, cut short
])
def test_malformed_answers(reply, why):
    with pytest.raises(SdoError) as info:
        DriveSdo(ScriptedNetwork(lambda can_id, req: reply), 10).upload(0x1018, 4, name="serial number")
    e = info.value
    assert e.reason == "malformed" and e.abort_code is None
    assert str(e).startswith("node 10: SDO upload of 0x1018:4 (serial number): malformed answer (")
    assert why in str(e)


@pytest.mark.parametrize("reply", [
    bytes.fromhex("60 18 10 04 00 00 00 00"),  # a download's answer
    bytes.fromhex("43 18 10 05 01 02 03 04"),  # another object's
])
def test_an_answer_that_cannot_be_the_uploads_is_another_transfers_not_a_malformed_one(reply):
    """On the drive's one SDO channel these are the late answers of other transfers (another process's,
    a retried request's second): the upload waits for its own, and without it the drive did not answer."""
    with pytest.raises(SdoError) as info:
        DriveSdo(ScriptedNetwork(lambda can_id, req: reply), 10).upload(0x1018, 4, name="serial number")
    assert info.value.reason == "timeout"


def test_a_request_that_cannot_be_sent():
    import can

    with pytest.raises(SdoError) as info:
        sdo_upload(ScriptedNetwork(fail=can.CanOperationError("Transmit buffer full")), 10, 0x1000)
    assert info.value.reason == "bus" and "could not be sent (Transmit buffer full)" in str(info.value)


def test_nmt_names():
    assert [nmt_text(s) for s in (0x00, 0x04, 0x05, 0x7F, 0x11)] == ["pre-op", "stopped", "operational", "pre-op",
                                                                     "0x11"]


# --------------------------------------------------------------------------- against the simulated arm

def test_one_client_per_drive_for_the_session():
    cfg = load_config(EXAMPLE1)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as session:
        ref = drive_ref(cfg, next(iter(cfg.drives)))
        sdo = session.sdo(ref)
        assert session.sdo(ref) is sdo
        # the in-process simulator shares this machine: its SDO answers get the patient sim timeout
        assert sdo.timeout == max(cfg.protocol.sdo_timeout, cfg.sim_reply_timeout) == 1.0
        assert sdo.upload(0x1008).rstrip(b"\0").startswith(b"Whistle")
        sdo.download(0x1017, 0, (250).to_bytes(2, "little"))
        assert int.from_bytes(sdo.upload(0x1017), "little") == 250
        with pytest.raises(SdoError) as info:
            sdo.upload(0x2FFF, 0)  # the simulated drive has no such object
        assert info.value.reason == "abort" and info.value.abort_code == 0x06020000
        assert str(info.value).startswith(f"{ref.name} (node {ref.node}): SDO upload of 0x2FFF aborted with")
        assert sdo.upload(0x1008)  # the client still works after an abort


def test_identify_and_dump_read_identity_through_the_session_clients():
    from sherpa_cli.ops.params_read import read_live

    cfg = load_config(EXAMPLE1)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as session:
        live = read_live(session, list(cfg.drives))
        assert set(session._sdo) == {(d.bus, d.node) for d in cfg.drives.values()}
        assert all(d.identity["serial"] for d in live.values())


class SteppingClock:
    def __init__(self, step: float) -> None:
        self.t, self.step = 0.0, step

    def __call__(self) -> float:
        self.t += self.step
        return self.t


class LateQueue:
    """canopen's answer queue of a transfer whose first answer is on its way while the wait gives up: the
    first wait comes back ``late`` s after its timeout and the answer is in only then (a starved host)."""

    def __init__(self, clock: SteppingClock, late: float, first: bytes) -> None:
        self.clock, self.late, self.first = clock, late, first
        self.items: list[bytes] = []
        self.gets = 0

    def empty(self) -> bool:
        return not self.items

    def put(self, item: bytes) -> None:
        self.items.append(item)

    def get(self, block: bool = True, timeout: float | None = None) -> bytes:
        import queue

        self.gets += 1
        if self.gets == 1:
            self.clock.t += (timeout or 0) + self.late
            self.items.append(self.first)  # arrives just after the wait gave up
            raise queue.Empty
        if not self.items:
            raise queue.Empty
        return self.items.pop(0)


DEVICE_NAME = b"Whistle"


def _device_name(can_id: int, req: bytes) -> bytes | None:
    """A drive's segmented 0x1008: the initiate is answered through the LateQueue, each segment at once."""
    if req[0] == 0x40:
        return None
    toggle = req[0] & 0x10
    return bytes([toggle | (7 - len(DEVICE_NAME)) << 1 | 0x01]) + DEVICE_NAME


@pytest.mark.parametrize("late,answered", [(0.02, True), (0.001, False)])
def test_a_canopen_transfer_whose_wait_came_back_late_waits_once_more_on_the_same_transfer(late, answered):
    """A segmented read through canopen's client on a starved host: the wait for the initiate's answer came
    back late and the answer is in just after. It is that transfer's answer: no second transfer is
    started (a second one took the first one's late answers for its own, "malformed answer (Unexpected
    response 0x41)"). A wait that came back on time is a drive that did not answer."""
    clock = SteppingClock(0.0)
    net = ScriptedNetwork(_device_name)
    sdo = DriveSdo(net, 10, label="drive1 (node 10)", clock=clock)
    initiate_answer = bytes([0x41, 0x08, 0x10, 0x00]) + struct.pack("<I", len(DEVICE_NAME))
    sdo._remote.sdo.responses = LateQueue(clock, late, initiate_answer)
    if answered:
        assert sdo.upload(0x1008, 0) == DEVICE_NAME
    else:  # a quarter of the timeout late at most: the drive's silence, not the host's
        with pytest.raises(SdoError, match=r"no answer to the SDO upload of 0x1008 within 0\.01 s"):
            sdo.upload(0x1008, 0)
    assert [d[:4] for _, d in net.sent if d[0] == 0x40] == [bytes.fromhex("40 08 10 00")]  # one transfer


class LateNetwork(ScriptedNetwork):
    """A session network (``wait_for``: the fast path) whose first wait comes back ``late`` s late and
    finds the answer only after it gave up."""

    def __init__(self, clock: SteppingClock, late: float) -> None:
        super().__init__()
        self.clock, self.late, self.waits = clock, late, 0

    def wait_for(self, lock, timeout: float) -> bool:
        self.waits += 1
        if self.waits == 1:
            self.clock.t += timeout + self.late
            for callback in list(self.subscribers.get(0x58A, [])):  # the answer, after the wait gave up
                callback(0x58A, bytes.fromhex("43 18 10 04 28 01 00 5A"), 0.0)
            return False
        return lock.acquire(timeout=0)


@pytest.mark.parametrize("late,answered", [(0.02, True), (0.001, False)])
def test_an_expedited_read_whose_wait_came_back_late_waits_once_more(late, answered):
    clock = SteppingClock(0.0)
    net = LateNetwork(clock, late)
    sdo = DriveSdo(net, 10, label="drive1 (node 10)", clock=clock)
    if answered:
        assert sdo.upload(0x1018, 4) == bytes.fromhex("28 01 00 5A") and net.waits == 2
    else:  # a quarter of the timeout late at most: the drive's silence, not the host's
        with pytest.raises(SdoError, match="no answer"):
            sdo.upload(0x1018, 4)
        assert net.waits == 1


class StrayAnswerNetwork(ScriptedNetwork):
    """A session network whose wait first hears another transfer's late answer (a download's 0x60 of the
    same object, from another process on the drive), then the upload's own."""

    def __init__(self, stray: bytes) -> None:
        super().__init__()
        self.stray = stray

    def wait_for(self, lock, timeout: float) -> bool:
        for frame in (self.stray, bytes.fromhex("43 16 10 01 2C 01 7E 00")):
            for callback in list(self.subscribers.get(0x58A, [])):
                callback(0x58A, frame, 0.0)
        return lock.acquire(timeout=0)


@pytest.mark.parametrize("stray", ["60 16 10 01 00 00 00 00", "43 17 10 00 01 00 00 00"])
def test_a_late_answer_of_another_transfer_is_never_taken_for_the_uploads(stray):
    """A jog's read of 0x1016:1 took a recording's download answer (0x60) for its own and failed as
    "malformed answer (Unexpected response 0x60)"; nor is another object's upload answer ours."""
    sdo = DriveSdo(StrayAnswerNetwork(bytes.fromhex(stray)), 10, label="drive1 (node 10)")
    assert sdo.upload(0x1016, 1) == bytes.fromhex("2C 01 7E 00")


class StrayThenAnswer(ScriptedNetwork):
    """canopen's path: each request is first "answered" by ``stray`` (another transfer's late answer on
    the drive), then by the drive's own answer."""

    def __init__(self, stray: bytes, answer: Callable[[int, bytes], bytes | None]) -> None:
        super().__init__(answer)
        self.stray = stray

    def send_message(self, can_id: int, data: bytes, remote: bool = False) -> None:
        if 0x600 < can_id < 0x680 and data[0] != 0x80:
            for callback in list(self.subscribers.get(can_id - 0x600 + 0x580, [])):
                callback(can_id - 0x600 + 0x580, self.stray, 0.0)
        super().send_message(can_id, data, remote)


@pytest.mark.parametrize("stray", [
    "43 00 1A 02 10 00 60 60",  # a recording's expedited upload answer, late
    "60 16 10 01 00 00 00 00",  # a download answer of another object
    "80 00 1A 02 00 00 04 05",  # another transfer's abort
])
def test_a_download_never_takes_another_transfers_late_answer_for_its_own(stray):
    """A jog's download of 0x6007 took a recording's late upload answer for its own, beside a
    `log record` on a busy host: "malformed answer (Unexpected response 0x43)"."""
    net = StrayThenAnswer(bytes.fromhex(stray), lambda can_id, req: bytes([0x60]) + req[1:4] + bytes(4))
    sdo = DriveSdo(net, 10, label="drive1 (node 10)")
    sdo.download(0x6007, 0, bytes.fromhex("01 00"))
    assert [d for _, d in net.sent] == [bytes.fromhex("2B 07 60 00 01 00 00 00")]


def test_a_download_whose_only_answer_is_another_transfers_is_no_answer():
    net = StrayThenAnswer(bytes.fromhex("43 00 1A 02 10 00 60 60"), lambda can_id, req: None)
    sdo = DriveSdo(net, 10, label="drive1 (node 10)")
    with pytest.raises(SdoError, match=r"no answer to the SDO download of 0x6007"):
        sdo.download(0x6007, 0, bytes.fromhex("01 00"))
