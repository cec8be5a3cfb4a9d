"""Host side of one Elmo drive's binary interpreter (elmo-protocol.md sections 1, 3.2, 3.6, 4).

Requests go out on RPDO2 (0x300+node), replies come back on TPDO2 (0x280+node) and are matched
on (letters, index). At most one request is in flight per drive (section 4.2: the drive's
receive buffer is overwritten by the next frame). The client owns no bus: it talks through a
:class:`~sherpa_cli.elmo.transport.Transport`, whose callbacks may arrive on a receive thread
or, in tests, synchronously inside ``send``.

Protocol points the sources leave open are :class:`ClientSettings`, not guesses in the code.
"""

from __future__ import annotations

import functools
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

from sherpa_cli.elmo import codec
from sherpa_cli.elmo.codec import Reply
from sherpa_cli.elmo.commands import COMMANDS
from sherpa_cli.elmo.faults import Emcy, decode_emcy, ec_text
from sherpa_cli.elmo.protocol import EMCY_BASE, NMT_ID, NMT_START
from sherpa_cli.elmo.transport import Transport, waiter
from sherpa_cli.errors import (
    CodecError,
    CommunicationError,
    DriveRefusedError,
    DriveTimeoutError,
    ProtocolError,
    SherpaError,
)

log = logging.getLogger(__name__)


class SetMismatchError(CommunicationError):
    """A set the drive took (no error reply) whose read-back is another value: ``readback`` is what
    the drive holds now (exit 3, like every unconfirmed exchange)."""

    def __init__(self, message: str, *, readback: int | float, hint: str | None = None) -> None:
        super().__init__(message, hint=hint)
        self.readback = readback

RPDO2_BASE = 0x300
TPDO2_BASE = 0x280
NMT_COB_ID = NMT_ID
NMT_RESET_NODE = 0x81
NMT_RESET_COMMUNICATION = 0x82
BOOTUP_BASE = 0x700  # boot-up (byte 0 = 0x00) and heartbeat
EMCY_RPDO_ERROR = 0x6300  # "RPDO-mapped object returned an interpretation error" (0x2F21 bit 8)

_TIMEOUT_HINT = "check that the drive is powered, on this bus with this node id, and NMT-started"


@dataclass(frozen=True)
class ClientSettings:
    """Choices for protocol behaviour no source confirms (elmo-protocol.md 1.3, 4.1)."""

    expect_set_echo: bool = True  # False: a set is confirmed by reading it back
    query_long: bool = False  # True: DLC 8 queries with the query bit instead of DLC 4
    mo_confirm_timeout: float = 3.0  # s to wait for MO to read back after MO=0/1
    mo_poll_interval: float = 0.01  # s between MO polls
    mo_settle: float = 0.0  # s the drive may be deaf after MO=0/1: an MO poll then waits no longer than that
    sv_blackout: float = 0.5  # s of silence after SV before the drive is asked anything
    timeout_hint: str = _TIMEOUT_HINT  # what a timeout tells the user to check (the simulator has its own)

    def __post_init__(self) -> None:
        for name in ("mo_confirm_timeout", "mo_poll_interval", "mo_settle", "sv_blackout"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not value >= 0:
                raise ValueError(f"ClientSettings.{name} must be a number >= 0, got {value!r}")


class _Pending:
    """The one request of a drive that is waiting for its reply.

    ``arrived`` is a plain lock held until the reply is in: the receive thread releases it once,
    the requester's timed ``acquire`` is the wait. A lock costs a fraction of an Event (whose
    every wait builds a Condition waiter), and every interpreter round trip makes one.
    """

    __slots__ = ("arrived", "error", "index", "letters", "reply")

    def __init__(self, letters: str, index: int) -> None:
        self.letters = letters
        self.index = index
        self.arrived = threading.Lock()
        self.arrived.acquire()
        self.reply: Reply | None = None
        self.error: SherpaError | None = None  # a frame we cannot read, or abort_pending's reason


@functools.lru_cache(maxsize=1024)
def _cached_query(letters: str, index: int, long: bool) -> bytes:
    return codec.encode_query(letters, index, long=long)


def _query(letters: str, index: int, long: bool) -> bytes:
    """A query frame, encoded once per (letters, index): a poll loop asks the same few (an
    encode costs ~9 us). Anything but a plain str/int is encoded (and refused) uncached."""
    if type(letters) is str and type(index) is int:
        return _cached_query(letters, index, long)
    return codec.encode_query(letters, index, long=long)


@functools.lru_cache(maxsize=1024)
def _key(letters: str, index: int) -> str:
    spec = COMMANDS.get(letters)
    return f"{letters}[{index}]" if index or (spec is not None and spec.is_array) else letters


def _answers(data: bytes, letters: str, index: int) -> bool:
    """Whether a frame's header is (letters, index), or unreadable so that it may be."""
    try:
        head = data[:2].decode("ascii")
    except UnicodeDecodeError:
        return True
    if not head.isalpha() or not head.isupper():
        return True
    return head == letters and (data[2] | data[3] << 8) & codec.INDEX_MASK == index


def _request_text(request: codec.Request) -> str:
    key = _key(request.letters, request.index)
    return f"{key}={request.value}" if request.kind == "set" else key


class DriveClient:
    """One drive's binary interpreter. Thread-safe: callers queue on a per-drive lock.

    ``timeout`` is the wait for one reply; a request is sent ``1 + retries`` times before
    :class:`DriveTimeoutError`. That wait is real time: the transport's ``wait`` (the caller reads
    the bus itself, bus/reader.py) or a timed lock acquire while another thread delivers.
    ``clock`` and ``sleep`` drive every longer wait (MO settle window, SV blackout) so tests can
    run them on a fake clock.
    """

    def __init__(self, transport: Transport, node: int, *, name: str, timeout: float = 0.1, retries: int = 1,
                 clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep,
                 settings: ClientSettings | None = None) -> None:
        if isinstance(node, bool) or not isinstance(node, int) or not 1 <= node <= 127:
            raise ValueError(f"node id must be 1..127, got {node!r}")
        if not timeout > 0:
            raise ValueError(f"timeout must be > 0 s, got {timeout!r}")
        if isinstance(retries, bool) or not isinstance(retries, int) or retries < 0:
            raise ValueError(f"retries must be an integer >= 0, got {retries!r}")
        self.transport = transport
        self.node = node
        self.name = name
        self.timeout = timeout
        self.retries = retries
        self.settings = settings or ClientSettings()
        self._clock = clock
        self._sleep = sleep
        # Reentrant so composite operations (save, motor_on) keep the drive for their whole
        # sequence while reusing the single-request helpers.
        self._lock = threading.RLock()
        # Guards what the receive thread touches; never held while sending or waiting.
        self._state = threading.Lock()
        self._pending: _Pending | None = None
        self._aborted: SherpaError | None = None  # abort_pending since the last clear_abort
        self._emcy_callbacks: list[Callable[[Emcy], None]] = []
        self._last_emcy: Emcy | None = None
        self._emcy_count = 0
        self._boots = 0  # boot-ups heard since reset_node first listened
        # True after a request that got no answer at any attempt, until the next answer: the exit
        # paths skip a silent drive instead of spending a timeout per step on it
        self.silent = False
        # called on the caller's thread before every attempt of a request (the session's request
        # watchers: a motion guard takes a request its command's thread sends as a sign of life)
        self.on_request: Callable[[], None] | None = None
        self._boot_listening = False
        self._late = 0.0  # how much later than asked the last request's waits came back (s)
        self._wait = waiter(transport)  # resolved once: every round trip waits through it
        transport.subscribe(TPDO2_BASE + node, self._on_reply)
        transport.subscribe(EMCY_BASE + node, self._on_emcy)

    @property
    def label(self) -> str:
        """``"shoulder_1a (node 10)"``: how every message names this drive."""
        return f"{self.name} (node {self.node})"

    @property
    def last_emcy(self) -> Emcy | None:
        with self._state:
            return self._last_emcy

    # -- interpreter commands ---------------------------------------------------------------------

    def get(self, letters: str, index: int = 0) -> int | float:
        """Query ``letters[index]``; the value's type follows the reply's type bit."""
        frame = _query(letters, index, self.settings.query_long)
        what = _key(letters, index)
        with self._lock:
            reply = self._transact(frame, letters, index, what)
        return self._value(reply, what)

    def set(self, letters: str, index: int, value: int | float, *,
            reads_back: Callable[[int | float], bool] | None = None) -> None:
        """Assign and confirm, by the drive's echo or (echo off or missing) by reading it back.

        ``reads_back``: what else a read-back may show after a successful set, for commands whose
        value is not what they read (RR=0 reads the recorder's state, HM[1]=1 reads 0 once the
        homing event fired): without an echo only an error reply then says the set failed."""
        frame = codec.encode_set(letters, index, value)
        # The drive holds the float32-rounded value; compare against that, not the caller's float.
        expected = codec.decode_request(frame).value
        key = _key(letters, index)
        what = f"{key}={expected if isinstance(expected, int) else value}"
        with self._lock:
            emcy_before = self._emcy_seen()
            if self.settings.expect_set_echo:
                echo = self._exchange(frame, letters, index, attempts=1)
                if echo is not None:
                    if not echo.ok:
                        raise self._refused(what, echo.error_code)
                    if echo.value != expected:
                        raise CommunicationError(f"{self.label}: {what} was echoed as {key}={echo.value}")
                    return
                # elmo-protocol.md 1.3: a missing echo means "unknown", not "failed".
                log.info("%s: no echo to %s within %g s; reading it back", self.label, what, self.timeout)
                readback = self._value(self._transact(self._query_frame(letters, index), letters, index, key), key)
            else:
                # No echo on success, but an error reply on failure: the set and its read-back go
                # out under one pending (letters, index), so whichever answers first is caught --
                # the set's error reply (replies come in order) or the read-back value.
                reply = self._transact(self._query_frame(letters, index), letters, index, key, before=frame)
                if not reply.ok:
                    # the read-back's own answer is still on its way: take it off the bus now, or
                    # the next request for this (letters, index) would take it for its answer
                    self._exchange(b"", letters, index, attempts=1)
                    raise self._refused(what, reply.error_code)
                readback = self._value(reply, key)
            if readback == expected or (reads_back is not None and reads_back(readback)):
                return
            emcy = self._emcy_since(emcy_before)
            if emcy is not None and emcy.code == EMCY_RPDO_ERROR and emcy.elmo_code:
                raise self._refused(what, emcy.elmo_code)
            raise SetMismatchError(f"{self.label}: {what} not confirmed: {key} reads back {readback}",
                                   readback=readback)

    def execute(self, letters: str, index: int = 0) -> None:
        """Run an execute command (BG, ST, ...). ``SV`` goes through :meth:`save`."""
        if letters == "SV":
            self.save()
            return
        frame = codec.encode_execute(letters, index)
        what = _key(letters, index)
        with self._lock:
            self._value(self._transact(frame, letters, index, what), what)

    def request(self, frame: bytes) -> Reply:
        """Send one raw RPDO2 frame and return the matching reply, error replies included.

        It always waits for a TPDO2, so a raw set to a drive that does not echo sets times out.
        A raw SV is sent once and its blackout is the caller's business; prefer :meth:`save`.
        """
        req = codec.decode_request(frame)
        attempts = 1 if req.letters == "SV" else None
        with self._lock:
            return self._transact(bytes(frame), req.letters, req.index, _request_text(req), attempts=attempts)

    def send_only(self, letters: str, index: int = 0, value: int | float | None = None) -> None:
        """Send one command (``value`` None: execute) without waiting for its reply: the motion
        guard's first stop pass, so every drive hears its stop before a dead drive's timeouts."""
        frame = codec.encode_execute(letters, index) if value is None else codec.encode_set(letters, index, value)
        self.transport.send(RPDO2_BASE + self.node, frame)

    # -- composite operations ---------------------------------------------------------------------

    def motor_on(self) -> None:
        """MO=1, then poll MO until it reads 1 (the drive is deaf while it settles)."""
        self._switch_motor(1)

    def motor_off(self) -> None:
        """MO=0, then poll MO until it reads 0."""
        self._switch_motor(0)

    def save(self) -> None:
        """SV once, stay silent for the blackout, then check that the drive answers again."""
        frame = codec.encode_execute("SV")
        with self._lock:
            start = self._clock()
            # Never resent: every SV is a flash write, and a lost reply is normal during the save.
            reply = self._exchange(frame, "SV", 0, attempts=1)
            if reply is not None and not reply.ok:
                raise self._refused("SV", reply.error_code)
            remaining = start + self.settings.sv_blackout - self._clock()
            if remaining > 0:
                self._sleep(remaining)
            self._value(self._transact(self._query_frame("MO", 0), "MO", 0, "MO (after SV)"), "MO (after SV)")

    def _switch_motor(self, value: int) -> None:
        what = f"MO={value}"
        timeout = self.settings.mo_confirm_timeout
        with self._lock:
            frame = codec.encode_set("MO", 0, value)
            if self.settings.expect_set_echo:
                echo = self._exchange(frame, "MO", 0, attempts=1)
                if echo is not None and not echo.ok:
                    raise self._refused(what, echo.error_code)
            else:
                if self.on_request is not None:
                    self.on_request()
                self.transport.send(RPDO2_BASE + self.node, frame)
            query = self._query_frame("MO", 0)
            start = self._clock()
            deadline = start + timeout
            deaf_until = start + self.settings.mo_settle
            last: int | float | None = None
            while True:
                with self._state:
                    aborted = self._aborted
                if aborted is not None:
                    raise aborted  # the guard's watch ended the motion (a reset drive, an EMCY)
                # One attempt per poll: the poll loop is the retry, bounded by the deadline. While the
                # drive may still be settling (deaf), a poll waits only until the window ends, not a
                # whole reply timeout: the next poll, sent then, is the one it can hear.
                now = self._clock()
                wait = self.timeout if now >= deaf_until else \
                    min(self.timeout, max(deaf_until - now, self.settings.mo_poll_interval))
                reply = self._exchange(query, "MO", 0, attempts=1, wait=wait)
                if reply is not None:
                    self.silent = False
                    last = self._value(reply, "MO")
                    if last == value:
                        return
                if self._clock() >= deadline:
                    break
                self._sleep(self.settings.mo_poll_interval)
            if last is None:
                self.silent = True  # not one answer for the whole confirmation time
                raise DriveTimeoutError(f"{self.label}: {what} not confirmed: no answer to MO within {timeout:g} s",
                                        hint=self.settings.timeout_hint)
            raise CommunicationError(f"{self.label}: {what} not confirmed: MO still reads {last} after {timeout:g} s",
                                     hint="read MF and EC for the reason")

    # -- NMT and EMCY -----------------------------------------------------------------------------

    def nmt_start(self) -> None:
        """NMT "start remote node": PDOs, hence the binary interpreter, work only in Operational."""
        self._nmt(NMT_START)

    def nmt_reset_communication(self) -> None:
        self._nmt(NMT_RESET_COMMUNICATION)

    def reset_node(self, boot_timeout: float) -> None:
        """NMT reset node, wait for the drive's boot-up, then NMT start it again.

        The drive reloads RAM from flash (elmo-protocol.md 3.2): what it holds afterwards is what
        its flash holds. Its position counter starts again and the motor is off. Raises
        DriveTimeoutError when no boot-up (0x700+node, byte 0 = 0x00) comes within ``boot_timeout``.
        """
        self._reset(NMT_RESET_NODE, "NMT reset node", boot_timeout)

    def reset_communication(self, boot_timeout: float) -> None:
        """NMT reset communication, wait for the boot-up, then NMT start again.

        CiA 301: the communication objects (0x1000-0x1FFF: heartbeat consumer and producer, 0x1029,
        the PDOs) go back to their saved values; the application keeps its RAM. What a command armed
        there (the dead-man) must be armed again by the caller."""
        self._reset(NMT_RESET_COMMUNICATION, "NMT reset communication", boot_timeout)

    def _reset(self, command: int, name: str, boot_timeout: float) -> None:
        with self._state:
            if not self._boot_listening:
                self._boot_listening = True
                self.transport.subscribe(BOOTUP_BASE + self.node, self._on_boot)
        with self._lock:
            with self._state:
                seen = self._boots
            self.transport.send(NMT_COB_ID, bytes([command, self.node]))
            deadline = self._clock() + boot_timeout
            while True:
                with self._state:
                    if self._boots > seen:
                        break
                if self._clock() >= deadline:
                    raise DriveTimeoutError(f"{self.label}: no boot-up within {boot_timeout:g} s after {name}",
                                            hint="check the drive's power and CAN wiring; protocol.boot_timeout "
                                            "sets the wait")
                self._sleep(0.005)
            self.transport.send(NMT_COB_ID, bytes([NMT_START, self.node]))

    def _on_boot(self, can_id: int, data: bytes, timestamp: float) -> None:
        if len(data) >= 1 and data[0] == 0x00:  # boot-up; heartbeats carry the NMT state instead
            with self._state:
                self._boots += 1

    def _nmt(self, command: int) -> None:
        # Under the drive lock so NMT never lands inside an SV blackout or between a request and its reply.
        with self._lock:
            self.transport.send(NMT_COB_ID, bytes([command, self.node]))

    def on_emcy(self, callback: Callable[[Emcy], None]) -> None:
        """Call ``callback(emcy)`` for every EMCY of this drive (on the transport's receive thread)."""
        with self._state:
            self._emcy_callbacks.append(callback)

    # -- internals --------------------------------------------------------------------------------

    def _query_frame(self, letters: str, index: int) -> bytes:
        return _query(letters, index, self.settings.query_long)

    def _transact(self, frame: bytes, letters: str, index: int, what: str, *, attempts: int | None = None,
                  before: bytes | None = None) -> Reply:
        attempts = 1 + self.retries if attempts is None else attempts
        reply = self._exchange(frame, letters, index, attempts=attempts, before=before)
        self.silent = reply is None
        if reply is None:
            tries = f" ({attempts} attempts)" if attempts > 1 else ""
            busy = ""
            if self._late > self.timeout / 4:
                # the waiting thread itself came back that much later than it asked: the host was
                # too busy to tell a silent drive from its own scheduling
                busy = (f"; this computer was too busy: the tool's own thread came back {self._late * 1000:.0f} ms "
                        "late while it waited, so the drive may well be fine")
            raise DriveTimeoutError(f"{self.label}: no answer to {what} within {self.timeout:g} s{tries}{busy}",
                                    hint="close what loads this computer and try again" if busy
                                    else self.settings.timeout_hint)
        return reply

    def _exchange(self, frame: bytes, letters: str, index: int, *, attempts: int,
                  before: bytes | None = None, wait: float | None = None) -> Reply | None:
        """Send ``frame`` up to ``attempts`` times; the matching reply, or None if none came.

        ``before`` (sent once, first) is a frame whose only possible answer is an error reply
        with the same (letters, index): a set while the drive does not echo sets. ``wait``: how
        long each attempt waits for its reply (default: the reply timeout).
        """
        pending = _Pending(letters, index)
        self._late = 0.0
        # Registered before sending: with a synchronous transport the reply arrives inside send().
        with self._state:
            self._pending = pending
        try:
            for attempt in range(attempts):
                if self.on_request is not None:
                    self.on_request()  # first: it may refuse the request (the guard's watch tripped)
                if before is not None and attempt == 0:
                    self.transport.send(RPDO2_BASE + self.node, before)
                if frame:  # an empty frame only waits (for a reply already on its way)
                    self.transport.send(RPDO2_BASE + self.node, frame)
                # the transport may let this thread read the bus itself until the reply is in
                asked = self.timeout if wait is None else wait
                began = self._clock()
                arrived = self._wait(pending.arrived, asked)
                late = self._clock() - began - asked
                if not arrived and late > asked / 4:
                    # this thread came back late (the host ran something else): the answer may be on
                    # its way through a receive thread just as late, so the wait gets that lateness
                    # once more (at most its own length) before the request counts as unanswered
                    arrived = self._wait(pending.arrived, min(late, asked))
                self._late = max(self._late, late)
                if arrived:
                    if pending.error is not None:
                        raise pending.error
                    return pending.reply
                log.debug("%s: no reply to %s (attempt %d of %d)", self.label, frame.hex(" "), attempt + 1, attempts)
            return None
        finally:
            with self._state:
                self._pending = None

    def _on_reply(self, can_id: int, data: bytes, timestamp: float) -> None:
        try:
            reply = codec.decode_reply(data)
        except CodecError as exc:
            self._on_malformed(can_id, bytes(data), exc)
            return
        with self._state:
            pending = self._pending
            if pending is None or pending.reply is not None or pending.error is not None \
                    or reply.letters != pending.letters or reply.index != pending.index:
                log.debug("%s: ignoring unrequested reply %s", self.label, bytes(data).hex(" "))
                return
            pending.reply = reply
            pending.arrived.release()

    def _on_malformed(self, can_id: int, data: bytes, exc: CodecError) -> None:
        """A TPDO2 frame that is no valid reply (wrong length, NaN/Inf, non-ASCII letters).

        If it answers the pending request -- its letters and index match, or it is too short or
        garbled to carry any -- that request fails with a ProtocolError naming the drive and the
        frame: the drive did answer, so a timeout ("no answer") would send the technician to the
        wrong problem. A readable header for another command is someone else's stale reply.
        """
        with self._state:
            pending = self._pending
            if pending is None or pending.reply is not None or pending.error is not None:
                log.warning("%s: ignoring malformed TPDO2 frame %s: %s", self.label, data.hex(" "), exc)
                return
            if len(data) >= 4 and not _answers(data, pending.letters, pending.index):
                log.debug("%s: ignoring malformed unrequested reply %s", self.label, data.hex(" "))
                return
            what = _key(pending.letters, pending.index)
            pending.error = ProtocolError(
                f"{self.label}: malformed reply to {what}: TPDO2 0x{can_id:03X} [{len(data)}] "
                f"{data.hex(' ').upper() or '(no data)'}: {exc.message}",
                hint="a drive or another device on this bus sends frames the binary interpreter does not "
                     "define; check the node id and the drive's firmware")
            pending.arrived.release()

    def _on_emcy(self, can_id: int, data: bytes, timestamp: float) -> None:
        try:
            emcy = decode_emcy(data)
        except CodecError as exc:
            log.warning("%s: ignoring malformed EMCY frame: %s", self.label, exc)
            return
        with self._state:
            self._last_emcy = emcy
            self._emcy_count += 1
            callbacks = list(self._emcy_callbacks)
        for callback in callbacks:
            callback(emcy)

    def remove_emcy(self, callback: Callable[[Emcy], None]) -> None:
        """Undo :meth:`on_emcy` (the motion guard's drive watch, at its exit)."""
        with self._state:
            if callback in self._emcy_callbacks:
                self._emcy_callbacks.remove(callback)

    def abort_pending(self, error: SherpaError) -> bool:
        """End the request a caller is waiting for now, raising ``error`` there (the motion guard's
        drive watch: a drive that left Operational is deaf, and its command must not wait out the
        reply timeouts). True if a request was waiting; none: nothing happens. Sends nothing."""
        with self._state:
            self._aborted = error  # also ends a motor switch's confirmation between two polls
            pending = self._pending
            if pending is None or pending.reply is not None or pending.error is not None:
                return False
            pending.error = error
        pending.arrived.release()
        return True

    def clear_abort(self) -> None:
        """The watch that called :meth:`abort_pending` has stopped (a guard's exit): requests wait again."""
        with self._state:
            self._aborted = None

    def _emcy_seen(self) -> int:
        with self._state:
            return self._emcy_count

    def _emcy_since(self, count: int) -> Emcy | None:
        with self._state:
            return self._last_emcy if self._emcy_count > count else None

    def _value(self, reply: Reply, what: str) -> int | float:
        if not reply.ok:
            raise self._refused(what, reply.error_code)
        assert reply.value is not None  # decode_reply sets a value on every success reply
        return reply.value

    def _refused(self, what: str, code: int | None) -> DriveRefusedError:
        text = ec_text(code) if code is not None else "unknown error"
        return DriveRefusedError(f"{self.label}: {what} refused: error {code} {text}",
                                 drive=self.label, command=what, code=code)
