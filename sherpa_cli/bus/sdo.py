"""SDO transfers through canopen's client without an object dictionary (scan, identify, monitor, program).

:class:`DriveSdo` is one drive's SDO client for a whole session (``ArmSession.sdo(ref)``): one
canopen ``RemoteNode``, associated with the bus's network once, instead of a new one per
transfer. Every failure -- no answer, an abort, an answer that is not a valid SDO reply, a
request that could not be sent -- raises :class:`sherpa_cli.errors.SdoError` naming the drive
and the object; callers never see canopen's exceptions. ``sdo_upload`` / ``sdo_download`` do
one transfer through a short-lived client, with the same errors.

The CANopen name tables (NMT states, vendor ids, abort codes) live in bus/canopen_names.py.
"""

from __future__ import annotations

import contextlib
import logging
import queue
import struct
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING

from sherpa_cli.bus.canopen_names import abort_text
from sherpa_cli.errors import SdoError

log = logging.getLogger(__name__)

if TYPE_CHECKING:
    import canopen

    from sherpa_cli.bus.machine_lock import TransferLock

# canopen logs every SDO it aborts at ERROR; this tool reports each failed transfer itself (as a
# note or an error naming the drive), so without a handler Python's last resort would print it twice.
logging.getLogger("canopen.sdo.client").addHandler(logging.NullHandler())

NO_ANSWER_HINT = "check that the drive is powered and on this bus with this node id"

#: CiA 301 VISIBLE_STRING objects (device name, hardware and software version): segmented on every
#: drive, so they go to canopen's client at once instead of through the expedited fast path first
SEGMENTED_OBJECTS = frozenset({(0x1008, 0), (0x1009, 0), (0x100A, 0)})
ABORT_TIMED_OUT = 0x05040000  # what canopen's client sends when an SDO answer does not come


def object_text(index: int, sub: int = 0, name: str | None = None) -> str:
    """``0x1018:4 (serial number)``; sub-index 0 is left out."""
    text = f"0x{index:04X}" + (f":{sub}" if sub else "")
    return f"{text} ({name})" if name else text


def _transfer_failures() -> tuple[type[BaseException], ...]:
    """What a transfer can fail with: canopen's SDO errors, a short frame, python-can or the adapter."""
    import can
    from canopen.sdo.exceptions import SdoError as CanopenSdoError

    return (CanopenSdoError, struct.error, can.CanError, OSError)


class _Answer:
    """The one expedited upload of a drive waiting for its answer (``arrived``: held until it is in)."""

    __slots__ = ("arrived", "data", "index", "sub")

    def __init__(self, index: int, sub: int) -> None:
        self.arrived = threading.Lock()
        self.arrived.acquire()
        self.data: bytes | None = None
        self.index, self.sub = index, sub

    def answers(self, data: bytes) -> bool:
        """Whether ``data`` can be this upload's answer: an upload response or an abort of its object.
        A frame too short to tell is taken (and refused as malformed); anything else is the late answer
        of another transfer (another process's on this drive, one that timed out before), never ours."""
        if len(data) < 4:
            return True
        command, index, sub = data[0], data[1] | data[2] << 8, data[3]
        return (index, sub) == (self.index, self.sub) and (command == 0x80 or command & 0xE0 == 0x40)


class DriveSdo:
    """One drive's SDO client: upload/download with SdoError on every failure; thread-safe per drive.

    On a network with ``wait_for`` (the session's PacedNetwork) an upload first
    goes the expedited fast path: one initiate request, its answer read on the caller's thread
    (bus/reader.py), no canopen queue. An answer that starts a segmented transfer, and every
    download, go through canopen's client, which is then associated with the network only for
    that transfer (so the fast path's answers never pile up in its queue).
    """

    def __init__(self, network: canopen.Network, node: int, *, label: str | None = None, timeout: float | None = None,
                 channel_lock: TransferLock | None = None, clock: Callable[[], float] = time.monotonic,
                 timeout_hint: str = NO_ANSWER_HINT) -> None:
        import canopen

        self.node = node
        self.timeout_hint = timeout_hint  # what an unanswered transfer's error suggests (--sim: its own)
        self._clock = clock
        self.label = label or f"node {node}"
        self._network = network
        self._remote = canopen.RemoteNode(node, canopen.ObjectDictionary())
        if timeout is None:
            # protocol.sdo_timeout, set on the session's networks (tests pass bare fakes: canopen's default)
            found = getattr(network, "sdo_timeout", None)
            timeout = found if isinstance(found, (int, float)) and not isinstance(found, bool) else None
        if timeout is not None:
            self._remote.sdo.RESPONSE_TIMEOUT = timeout
        # canopen's wait for each answer of a transfer, with the allowance of the fast path below
        setattr(self._remote.sdo, "read_response", self._read_response)  # noqa: B010 - a method, not a field
        wait_for = getattr(network, "wait_for", None)
        self._wait = wait_for if callable(wait_for) else None
        self._answer: _Answer | None = None
        self._current: tuple[str, int, int] = ("upload", 0, 0)  # the canopen transfer under way (op, index, sub)
        self._segmented: set[tuple[int, int]] = set(SEGMENTED_OBJECTS)  # (index, sub) learnt or known
        if self._wait is None:
            self._remote.associate_network(network)
        else:
            network.subscribe(0x580 + node, self._on_answer)
        self._lock = threading.Lock()
        self._failures = _transfer_failures()
        # called on the caller's thread before every upload and download (the session's request watchers)
        self.on_request: Callable[[], None] | None = None
        # the drive's SDO channel across the processes of this machine (bus/machine_lock.py), or None
        self._channel = channel_lock

    @contextmanager
    def _transfer(self, op: str, index: int, sub: int, name: str | None) -> Iterator[None]:
        """One transfer at a time on this drive: this process's threads, then the machine's processes."""
        with self._lock:
            if self._channel is None:
                yield
                return
            try:
                held = self._channel.held(3 * self.timeout + 1.0)
                held.__enter__()
            except TimeoutError as exc:
                raise SdoError(f"{self.label}: SDO {op} of {object_text(index, sub, name)}: {exc}",
                               detail=str(exc), reason="busy", node=self.node, index=index, sub=sub,
                               hint="another sherpa command talks to this drive; try again when it ends") from None
            try:
                yield
            finally:
                held.__exit__(None, None, None)

    @contextmanager
    def _canopen(self) -> Iterator[None]:
        """canopen's client on the network for one transfer (fast mode), or as it always is."""
        if self._wait is None:
            yield
            return
        self._remote.associate_network(self._network)
        try:
            yield
        finally:
            self._remote.remove_network()

    def _on_answer(self, can_id: int, data: bytes | bytearray, timestamp: float) -> None:
        answer = self._answer
        if answer is None or answer.data is not None:
            return
        if not answer.answers(bytes(data)):
            log.debug("%s: SDO answer %s is not the upload's of 0x%04X:%d: another transfer's, ignored",
                      self.label, bytes(data).hex(" "), answer.index, answer.sub)
            return
        answer.data = bytes(data)
        answer.arrived.release()

    def _fast_upload(self, index: int, sub: int, name: str | None) -> bytes | None:
        """An expedited upload on the caller's thread; None when the drive starts a segmented one."""
        assert self._wait is not None
        request = bytes((0x40, index & 0xFF, index >> 8, sub, 0, 0, 0, 0))
        answer = self._answer = _Answer(index, sub)
        try:
            try:
                self._network.send_message(0x600 + self.node, request)
            except self._failures as exc:
                raise self._error("upload", index, sub, name, exc) from None
            began = self._clock()
            arrived = self._wait(answer.arrived, self.timeout)
            late = self._clock() - began - self.timeout
            if not arrived and late > self.timeout / 4:
                # this thread came back late (the host ran something else): the answer may be on its
                # way through a receive thread just as late -- the allowance the interpreter's
                # requests get (elmo/client.py), once, at most the timeout again
                log.debug("%s: SDO upload of 0x%04X:%d: this thread was %.0f ms late; waiting once more",
                          self.label, index, sub, late * 1000)
                arrived = self._wait(answer.arrived, min(late, self.timeout))
            if not arrived:
                # as canopen's client does: tell the drive the transfer is over
                with contextlib.suppress(*self._failures):
                    self._network.send_message(0x600 + self.node, bytes((0x80, index & 0xFF, index >> 8, sub))
                                               + ABORT_TIMED_OUT.to_bytes(4, "little"))
                raise self._error("upload", index, sub, name, None, timed_out=True)
        finally:
            self._answer = None
        data = answer.data or b""
        if len(data) < 4:
            raise self._error("upload", index, sub, name, None, malformed="too short")
        command = data[0]
        if command == 0x80:
            code = int.from_bytes(data[4:8].ljust(4, b"\0"), "little")
            raise self._error("upload", index, sub, name, None, aborted=code)
        if command & 0xE0 != 0x40:
            raise self._error("upload", index, sub, name, None, malformed=f"Unexpected response 0x{command:02X}")
        got_index, got_sub = data[1] | data[2] << 8, data[3]
        if (got_index, got_sub) != (index, sub):
            raise self._error("upload", index, sub, name, None,
                              malformed=f"Node returned a value for 0x{got_index:04X}:{got_sub:02X} instead")
        if not command & 0x02:  # not expedited: a segmented transfer, canopen's business
            return None
        size = 4 - (command >> 2 & 0x03) if command & 0x01 else 4
        value = data[4:4 + size]
        if len(value) != size:
            raise self._error("upload", index, sub, name, None,
                              malformed=f"{len(value)} data byte(s) where the answer announces {size}")
        return value

    @property
    def timeout(self) -> float:
        return float(self._remote.sdo.RESPONSE_TIMEOUT)

    def upload(self, index: int, sub: int = 0, *, name: str | None = None) -> bytes:
        """One SDO upload (expedited or segmented); ``name`` words the object in an error."""
        if self.on_request is not None:
            self.on_request()
        with self._transfer("upload", index, sub, name):
            if self._wait is not None and (index, sub) not in self._segmented:
                fast = self._fast_upload(index, sub, name)
                if fast is not None:
                    return fast
                self._segmented.add((index, sub))  # next time straight to canopen
            try:
                size, data = self._canopen_upload(index, sub)
            except self._failures as exc:
                raise self._error("upload", index, sub, name, exc) from None
        if isinstance(size, int) and len(data) != size:
            raise self._error("upload", index, sub, name, None,
                              malformed=f"{len(data)} data byte(s) where the answer announces {size}")
        return data

    def _read_response(self) -> bytes:
        """canopen's ``SdoClient.read_response`` for this drive's transfers, with the fast path's allowance:
        a wait that came back late (the host ran something else) waits once more, at most its own length,
        for the answer that may be on its way just as late. Asking again instead (a second transfer) took
        the first one's late answers for its own: "malformed answer (Unexpected response 0x41)"."""
        from canopen.sdo.exceptions import SdoAbortedError, SdoCommunicationError

        client = self._remote.sdo
        responses = client.responses  # the queue of this transfer (canopen replaces it between transfers)
        timeout = float(client.RESPONSE_TIMEOUT)
        began = self._clock()
        deadline, extended = began + timeout, False
        while True:
            try:
                response: bytes = responses.get(block=True, timeout=max(deadline - self._clock(), 0.0))
            except queue.Empty:
                late = self._clock() - began - timeout
                if extended or late <= timeout / 4:
                    raise SdoCommunicationError("No SDO response received") from None
                log.debug("%s: SDO answer: this thread was %.0f ms late; waiting once more", self.label, late * 1000)
                deadline, extended = self._clock() + min(late, timeout), True
                continue
            if not self._stray(bytes(response)):
                break
            # the late answer of another transfer on this drive (another process's, or a retried
            # request's second answer): not this transfer's, which may still come
            log.debug("%s: SDO answer %s is not this transfer's (%s of 0x%04X:%d): ignored", self.label,
                      bytes(response).hex(" "), *self._current)
        if response[:1] == b"\x80":
            raise SdoAbortedError(struct.unpack_from("<L", response.ljust(8, b"\0"), 4)[0])
        return response

    def _stray(self, response: bytes) -> bool:
        """Whether ``response`` cannot answer the transfer under way (:attr:`_current`): an upload's
        answer in a download, a download's in an upload, or an initiate answer or abort of another
        object. Segment answers carry no object: those are taken, as canopen takes them."""
        if len(response) < 4:
            return False  # too short to tell: canopen refuses it as malformed
        op, index, sub = self._current
        command, obj = response[0], (response[1] | response[2] << 8, response[3])
        kind = command & 0xE0
        if kind == 0x40:  # an initiate upload answer
            return op != "upload" or obj != (index, sub)
        if kind == 0x60:  # an initiate download answer
            return op != "download" or obj != (index, sub)
        if command == 0x80:
            return obj != (index, sub)
        return False

    def _canopen_upload(self, index: int, sub: int) -> tuple[int | None, bytes]:
        """One upload through canopen's client: (the size the drive announced, the data)."""
        self._current = ("upload", index, sub)
        with self._canopen(), self._remote.sdo.open(index, sub, "rb", buffering=0) as fp:
            size = getattr(fp, "size", None)
            return (size if isinstance(size, int) else None), bytes(fp.read())

    def download(self, index: int, sub: int, data: bytes, *, name: str | None = None) -> None:
        """One SDO download (expedited or segmented)."""
        if self.on_request is not None:
            self.on_request()
        with self._transfer("download", index, sub, name):
            self._current = ("download", index, sub)
            try:
                with self._canopen():
                    self._remote.sdo.download(index, sub, data)
            except self._failures as exc:
                raise self._error("download", index, sub, name, exc) from None

    def close(self) -> None:
        """Stop listening on the network (the session's networks go away with it anyway)."""
        if self._wait is None:
            self._remote.remove_network()
        if self._channel is not None:
            self._channel.close()
        else:
            self._network.unsubscribe(0x580 + self.node, self._on_answer)

    # -- errors -----------------------------------------------------------------------------------

    def _error(self, op: str, index: int, sub: int, name: str | None, exc: BaseException | None, *,
               malformed: str | None = None, aborted: int | None = None, timed_out: bool = False) -> SdoError:
        from canopen.sdo.exceptions import SdoAbortedError, SdoCommunicationError

        what = object_text(index, sub, name)
        code = None
        hint = None
        if malformed is not None:
            reason, detail = "malformed", f"SDO {op} of {what}: malformed answer ({malformed})"
        elif aborted is not None:
            code = aborted
            reason, detail = "abort", f"SDO {op} of {what} aborted with 0x{code:08X} ({abort_text(code)})"
        elif timed_out:
            reason, detail = "timeout", f"no answer to the SDO {op} of {what} within {self.timeout:g} s"
            hint = self.timeout_hint
        elif isinstance(exc, SdoAbortedError):
            code = exc.code
            reason, detail = "abort", f"SDO {op} of {what} aborted with 0x{code:08X} ({abort_text(code)})"
        elif isinstance(exc, SdoCommunicationError) and isinstance(exc.__context__, queue.Empty):
            reason, detail = "timeout", f"no answer to the SDO {op} of {what} within {self.timeout:g} s"
            hint = self.timeout_hint
        elif isinstance(exc, (SdoCommunicationError, struct.error)):
            why = "too short" if isinstance(exc, struct.error) else str(exc)
            reason, detail = "malformed", f"SDO {op} of {what}: malformed answer ({why})"
        else:  # python-can's CanError, an OSError from the adapter, ...
            reason, detail = "bus", f"SDO {op} of {what}: the request could not be sent ({exc})"
        return SdoError(f"{self.label}: {detail}", detail=detail, reason=reason, node=self.node,
                        index=index, sub=sub, abort_code=code, hint=hint)


def sdo_upload(network: canopen.Network, node: int, index: int, sub: int = 0, *, label: str | None = None,
               name: str | None = None) -> bytes:
    """One SDO upload through a client of its own (prefer ``session.sdo(ref).upload``)."""
    client = DriveSdo(network, node, label=label)
    try:
        return client.upload(index, sub, name=name)
    finally:
        client.close()


def sdo_download(network: canopen.Network, node: int, index: int, sub: int, data: bytes, *, label: str | None = None,
                 name: str | None = None) -> None:
    """One SDO download through a client of its own (prefer ``session.sdo(ref).download``)."""
    client = DriveSdo(network, node, label=label)
    try:
        client.download(index, sub, data, name=name)
    finally:
        client.close()
