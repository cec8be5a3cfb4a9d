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

import logging
import queue
import struct
import threading
from typing import TYPE_CHECKING

from sherpa_cli.bus.canopen_names import abort_text
from sherpa_cli.errors import SdoError

if TYPE_CHECKING:
    import canopen

# canopen logs every SDO it aborts at ERROR; this tool reports each failed transfer itself (as a
# note or an error naming the drive), so without a handler Python's last resort would print it twice.
logging.getLogger("canopen.sdo.client").addHandler(logging.NullHandler())

NO_ANSWER_HINT = "check that the drive is powered and on this bus with this node id"


def object_text(index: int, sub: int = 0, name: str | None = None) -> str:
    """``0x1018:4 (serial number)``; sub-index 0 is left out."""
    text = f"0x{index:04X}" + (f":{sub}" if sub else "")
    return f"{text} ({name})" if name else text


def _transfer_failures() -> tuple[type[BaseException], ...]:
    """What a transfer can fail with: canopen's SDO errors, a short frame, python-can or the adapter."""
    import can
    from canopen.sdo.exceptions import SdoError as CanopenSdoError

    return (CanopenSdoError, struct.error, can.CanError, OSError)


class DriveSdo:
    """One drive's SDO client: upload/download with SdoError on every failure; thread-safe per drive."""

    def __init__(self, network: canopen.Network, node: int, *, label: str | None = None, timeout: float | None = None) -> None:
        import canopen

        self.node = node
        self.label = label or f"node {node}"
        self._remote = canopen.RemoteNode(node, canopen.ObjectDictionary())
        if timeout is None:
            # protocol.sdo_timeout, set on the session's networks (tests pass bare fakes: canopen's default)
            found = getattr(network, "sdo_timeout", None)
            timeout = found if isinstance(found, (int, float)) and not isinstance(found, bool) else None
        if timeout is not None:
            self._remote.sdo.RESPONSE_TIMEOUT = timeout
        self._remote.associate_network(network)
        self._lock = threading.Lock()
        self._failures = _transfer_failures()

    @property
    def timeout(self) -> float:
        return float(self._remote.sdo.RESPONSE_TIMEOUT)

    def upload(self, index: int, sub: int = 0, *, name: str | None = None) -> bytes:
        """One SDO upload (expedited or segmented); ``name`` words the object in an error."""
        with self._lock:
            try:
                with self._remote.sdo.open(index, sub, "rb", buffering=0) as fp:
                    size = getattr(fp, "size", None)
                    data = bytes(fp.read())
            except self._failures as exc:
                raise self._error("upload", index, sub, name, exc) from None
        if isinstance(size, int) and len(data) != size:
            raise self._error("upload", index, sub, name, None,
                              malformed=f"{len(data)} data byte(s) where the answer announces {size}")
        return data

    def download(self, index: int, sub: int, data: bytes, *, name: str | None = None) -> None:
        """One SDO download (expedited or segmented)."""
        with self._lock:
            try:
                self._remote.sdo.download(index, sub, data)
            except self._failures as exc:
                raise self._error("download", index, sub, name, exc) from None

    def close(self) -> None:
        """Stop listening on the network (the session's networks go away with it anyway)."""
        self._remote.remove_network()

    # -- errors -----------------------------------------------------------------------------------

    def _error(self, op: str, index: int, sub: int, name: str | None, exc: BaseException | None, *,
               malformed: str | None = None) -> SdoError:
        from canopen.sdo.exceptions import SdoAbortedError, SdoCommunicationError

        what = object_text(index, sub, name)
        code = None
        hint = None
        if malformed is not None:
            reason, detail = "malformed", f"SDO {op} of {what}: malformed answer ({malformed})"
        elif isinstance(exc, SdoAbortedError):
            code = exc.code
            reason, detail = "abort", f"SDO {op} of {what} aborted with 0x{code:08X} ({abort_text(code)})"
        elif isinstance(exc, SdoCommunicationError) and isinstance(exc.__context__, queue.Empty):
            reason, detail = "timeout", f"no answer to the SDO {op} of {what} within {self.timeout:g} s"
            hint = NO_ANSWER_HINT
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
