"""SDO transfers through canopen's client without an object dictionary (scan, identify, monitor, program).

A failed transfer raises canopen's SdoError; :func:`sdo_error_text` words it for a note or an error.
"""

from __future__ import annotations

import logging
from contextlib import contextmanager
from typing import Any, Iterator

# canopen logs every SDO it aborts at ERROR; this tool reports each failed transfer itself (as a
# note or an error naming the drive), so without a handler Python's last resort would print it twice.
logging.getLogger("canopen.sdo.client").addHandler(logging.NullHandler())


@contextmanager
def _remote(network: Any, node: int) -> Iterator[Any]:
    """A RemoteNode on ``network`` for the length of one transfer."""
    import canopen

    remote = canopen.RemoteNode(node, canopen.ObjectDictionary())
    # protocol.sdo_timeout, set on the session's networks (tests pass bare fakes: canopen's default)
    timeout = getattr(network, "sdo_timeout", None)
    if isinstance(timeout, (int, float)):
        remote.sdo.RESPONSE_TIMEOUT = timeout
    remote.associate_network(network)
    try:
        yield remote
    finally:
        remote.remove_network()


def sdo_upload(network: Any, node: int, index: int, sub: int = 0) -> bytes:
    """One SDO upload (expedited or segmented)."""
    with _remote(network, node) as remote:
        return remote.sdo.upload(index, sub)


def sdo_download(network: Any, node: int, index: int, sub: int, data: bytes) -> None:
    """One SDO download (expedited or segmented)."""
    with _remote(network, node) as remote:
        remote.sdo.download(index, sub, data)


def sdo_error_text(what: str, exc: BaseException) -> str:
    from canopen.sdo.exceptions import SdoAbortedError

    if isinstance(exc, SdoAbortedError):
        return f"{what} aborted with 0x{exc.code:08X}"
    return f"no answer to {what}"
