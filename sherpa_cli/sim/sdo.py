"""SDO server of a simulated drive: canopen's LocalNode serving the drive's object dictionary.

LocalNode is fed frames by the arm's bus loop through a small network shim instead of a
canopen.Network, so one thread per bus decides the order of everything a drive does, as
the single CPU of a real drive would.
"""

from __future__ import annotations

from typing import Any, Callable

import canopen
from canopen import objectdictionary as od
from canopen.sdo.exceptions import SdoAbortedError

from sherpa_cli.sim.od import ODError

# (index, sub) -> (name, data type, access); sub None = a plain variable
_OBJECTS: list[tuple[int, int | None, str, int, str]] = [
    (0x1000, None, "Device type", od.UNSIGNED32, "ro"),
    (0x1001, None, "Error register", od.UNSIGNED8, "ro"),
    (0x1003, 1, "Standard error field", od.UNSIGNED32, "ro"),
    (0x1008, None, "Manufacturer device name", od.VISIBLE_STRING, "const"),
    (0x1009, None, "Manufacturer hardware version", od.VISIBLE_STRING, "const"),
    (0x100A, None, "Manufacturer software version", od.VISIBLE_STRING, "const"),
    (0x1016, 1, "Consumer heartbeat time", od.UNSIGNED32, "rw"),
    (0x1017, None, "Producer heartbeat time", od.UNSIGNED16, "rw"),
    (0x1018, 1, "Vendor-ID", od.UNSIGNED32, "ro"),
    (0x1018, 2, "Product code", od.UNSIGNED32, "ro"),
    (0x1018, 3, "Revision number", od.UNSIGNED32, "ro"),
    (0x1018, 4, "Serial number", od.UNSIGNED32, "ro"),
    (0x1029, 1, "Communication error behaviour", od.UNSIGNED8, "rw"),
    (0x6007, None, "Abort connection option code", od.INTEGER16, "rw"),
    (0x2040, None, "Group ID", od.UNSIGNED8, "rw"),
]
_RECORD_NAMES = {0x1003: "Pre-defined error field", 0x1016: "Consumer heartbeat time", 0x1018: "Identity object", 0x1029: "Error behaviour"}


def build_object_dictionary() -> "od.ObjectDictionary":
    dictionary = od.ObjectDictionary()
    records: dict[int, Any] = {}
    for index, sub, name, data_type, access in _OBJECTS:
        var = od.ODVariable(name, index, sub or 0)
        var.data_type = data_type
        var.access_type = access
        if sub is None:
            dictionary.add_object(var)
            continue
        record = records.get(index)
        if record is None:
            record = records[index] = od.ODRecord(_RECORD_NAMES[index], index)
            count = od.ODVariable("Highest sub-index supported", index, 0)
            count.data_type, count.access_type = od.UNSIGNED8, "ro"
            record.add_member(count)
            dictionary.add_object(record)
        record.add_member(var)
    for index, record in records.items():
        record[0].default = max(k for k in record.subindices)
    return dictionary


class _Task:
    def stop(self) -> None:
        pass


class NetworkShim:
    """What LocalNode needs of a network: subscriptions and send; frames go to ``send``."""

    def __init__(self, send: Callable[[int, bytes], None]) -> None:
        self._send = send
        self.subscribers: dict[int, list[Callable]] = {}

    def subscribe(self, can_id: int, callback: Callable) -> None:
        self.subscribers.setdefault(can_id, []).append(callback)

    def unsubscribe(self, can_id: int, callback: Callable | None = None) -> None:
        self.subscribers.pop(can_id, None)

    def send_message(self, can_id: int, data: bytes, remote: bool = False) -> None:
        self._send(can_id, bytes(data))

    def send_periodic(self, *args: Any, **kwargs: Any) -> _Task:
        # heartbeats are the simulated drive's own business (0x1017 goes through od_write)
        return _Task()

    def check(self) -> None:
        pass


class SdoServer:
    """Answers SDO requests (0x600+node) from a simulated drive's od_read/od_write."""

    def __init__(self, node: int, drive: Any, send: Callable[[int, bytes], None]) -> None:
        self.node = node
        self.drive = drive
        self.shim = NetworkShim(send)
        self.local = canopen.LocalNode(node, build_object_dictionary())
        self.local.add_read_callback(self._read)
        self.local.add_write_callback(self._write)
        self.local.associate_network(self.shim)
        # NMT is the simulated drive's own state machine, not LocalNode's
        self.shim.unsubscribe(0)

    def _read(self, index: int, subindex: int, od: Any) -> Any:
        if subindex == 0 and isinstance(od, canopen.objectdictionary.ODVariable) and od.parent is not None \
                and not isinstance(od.parent, canopen.objectdictionary.ObjectDictionary) and index != 0x1003:
            return od.default  # 0x1003:0 counts the stored errors: the drive's, not a constant
        try:
            return self.drive.od_read(index, subindex)
        except ODError as exc:
            raise SdoAbortedError(exc.abort_code) from None

    def _write(self, index: int, subindex: int, od: Any, data: bytes) -> None:
        try:
            self.drive.od_write(index, subindex, od.decode_raw(data))
        except ODError as exc:
            raise SdoAbortedError(exc.abort_code) from None

    def receive(self, can_id: int, data: bytes, timestamp: float = 0.0) -> None:
        for callback in self.shim.subscribers.get(can_id, ()):
            callback(can_id, bytearray(data), timestamp)
