"""SDO server of a simulated drive: canopen's LocalNode serving the drive's object dictionary.

LocalNode is fed frames by the arm's bus loop through a small network shim instead of a
canopen.Network, so one thread per bus decides the order of everything a drive does, as
the single CPU of a real drive would.
"""

from __future__ import annotations

import logging
import struct
from collections.abc import Callable
from typing import Protocol, cast

import canopen
from canopen import objectdictionary as od
from canopen.sdo.exceptions import SdoAbortedError

from sherpa_cli.elmo.protocol import SDO_TX_BASE
from sherpa_cli.sim.od import ODError, OdValue

log = logging.getLogger(__name__)

ObjectSpec = tuple[int, int | None, str, int, str]  # index, sub (None: a plain variable), name, data type, access
Callback = Callable[[int, bytearray, float], None]  # a subscriber of canopen's Network: (can_id, data, timestamp)

_OBJECTS: list[ObjectSpec] = [
    (0x1000, None, "Device type", od.UNSIGNED32, "ro"),
    (0x1001, None, "Error register", od.UNSIGNED8, "ro"),
    (0x1003, 1, "Standard error field", od.UNSIGNED32, "ro"),
    (0x1005, None, "COB-ID SYNC message", od.UNSIGNED32, "rw"),
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
# a Whistle's (configs/eds/whistle.eds): the status register, node id and EMCY COB-ID, the binary
# interpreter's RPDO2/TPDO2 objects and the mappable DS402 values (sim/pdo.py)
DRIVE_OBJECTS: tuple[ObjectSpec, ...] = (
    (0x1002, None, "Manufacturer status register", od.UNSIGNED32, "ro"),
    (0x100B, None, "Node-ID", od.UNSIGNED8, "ro"),
    (0x1014, None, "COB-ID EMCY", od.UNSIGNED32, "rw"),
    (0x2012, None, "Binary interpreter input", od.UNSIGNED64, "ro"),
    (0x2013, None, "Binary interpreter output", od.UNSIGNED64, "ro"),
    (0x6064, None, "Position actual value", od.INTEGER32, "ro"),
    (0x6069, None, "Velocity sensor actual value", od.INTEGER32, "ro"),
    (0x606C, None, "Velocity actual value", od.INTEGER32, "ro"),
    (0x6078, None, "Current actual value", od.INTEGER16, "ro"),
)
MAPPABLE_OBJECTS = frozenset({0x1002, 0x2012, 0x2013, 0x6004, 0x6064, 0x6069, 0x606C, 0x6078})
_RECORD_NAMES = {0x2030: "Bring recorded data", 0x1003: "Pre-defined error field", 0x1016: "Consumer heartbeat time", 0x1018: "Identity object", 0x1029: "Error behaviour"}


def build_object_dictionary(extra: tuple[ObjectSpec, ...] = DRIVE_OBJECTS, tpdos: tuple[int, ...] = (0, 1, 2, 3),
                            fixed: frozenset[int] = frozenset({1}), rpdo2: bool = True,
                            rpdos: tuple[int, ...] = ()) -> od.ObjectDictionary:
    """``extra``: more (index, sub or None, name, data type, access) of the device type (a Whistle's by
    default; sim/encoder.py has its own); ``tpdos``: its TPDO numbers - 1, ``fixed`` those that
    refuse writes (the interpreter's TPDO2); ``rpdo2``: it has the interpreter's RPDO2; ``rpdos``: the
    numbers - 1 of its other RPDOs (a Whistle's carry PVT records, sim/pvt.py)."""
    dictionary = od.ObjectDictionary()
    records: dict[int, od.ODRecord] = {}
    for index, sub, name, data_type, access in (*_OBJECTS, *extra):
        var = od.ODVariable(name, index, sub or 0)
        var.data_type = data_type
        var.access_type = access
        var.pdo_mappable = index in MAPPABLE_OBJECTS
        if sub is None:
            dictionary.add_object(var)
            continue
        record = records.get(index)
        if record is None:
            record = records[index] = od.ODRecord(_RECORD_NAMES[index], index)
            count = od.ODVariable("Number of errors" if index == 0x1003 else "Highest sub-index supported", index, 0)
            # 0x1003:0 := 0 clears the error history (CiA 301); every other count is read-only
            count.data_type, count.access_type = od.UNSIGNED8, "rw" if index == 0x1003 else "ro"
            record.add_member(count)
            dictionary.add_object(record)
        record.add_member(var)
    for record in records.values():
        record[0].default = max(k for k in record.subindices)
    _add_pdo_objects(dictionary, tpdos, fixed, rpdo2)
    _add_rpdo_objects(dictionary, rpdos)
    return dictionary


def _record(dictionary: od.ObjectDictionary, name: str, index: int,
            members: tuple[tuple[int, str, int, str], ...]) -> None:
    record = od.ODRecord(name, index)
    for sub, member, data_type, access in members:
        var = od.ODVariable(member, index, sub)
        var.data_type, var.access_type = data_type, access
        record.add_member(var)
    record[0].default = max(sub for sub, *_ in members)
    dictionary.add_object(record)


def _add_pdo_objects(dictionary: od.ObjectDictionary, tpdos: tuple[int, ...], fixed: frozenset[int],
                     rpdo2: bool) -> None:
    """TPDO communication (0x1800 + n: COB-ID, transmission type, inhibit time, event timer) and mapping
    (0x1A00 + n: count, eight entries), served from the node's RAM (sim/pdo.py); and RPDO2's (0x1401 /
    0x1601, the binary interpreter's: only its transmission type is writable)."""
    u8, u16, u32 = od.UNSIGNED8, od.UNSIGNED16, od.UNSIGNED32
    if rpdo2:
        _record(dictionary, "RPDO2 communication parameter", 0x1401,
                ((0, "Highest sub-index supported", u8, "ro"), (1, "COB-ID", u32, "ro"), (2, "Transmission type", u8, "rw")))
        _record(dictionary, "RPDO2 mapping parameter", 0x1601,
                ((0, "Number of mapped objects", u8, "ro"), (1, "Mapped object 1", u32, "ro")))
    for n in tpdos:
        access = "ro" if n in fixed else "rw"
        _record(dictionary, f"TPDO{n + 1} communication parameter", 0x1800 + n,
                ((0, "Highest sub-index supported", u8, "ro"), (1, "COB-ID", u32, access),
                 (2, "Transmission type", u8, access), (3, "Inhibit time", u16, access), (5, "Event timer", u16, access)))
        _record(dictionary, f"TPDO{n + 1} mapping parameter", 0x1A00 + n,
                tuple((sub, "Number of mapped objects" if sub == 0 else f"Mapped object {sub}", u8 if sub == 0 else u32,
                       access) for sub in range(9)))


def _add_rpdo_objects(dictionary: od.ObjectDictionary, rpdos: tuple[int, ...]) -> None:
    """RPDO communication (0x1400 + n: COB-ID, transmission type) and mapping (0x1600 + n: count, eight
    entries), served from the node's RAM (sim/pvt.py)."""
    u8, u32 = od.UNSIGNED8, od.UNSIGNED32
    for n in rpdos:
        _record(dictionary, f"RPDO{n + 1} communication parameter", 0x1400 + n,
                ((0, "Highest sub-index supported", u8, "ro"), (1, "COB-ID", u32, "rw"), (2, "Transmission type", u8, "rw")))
        _record(dictionary, f"RPDO{n + 1} mapping parameter", 0x1600 + n,
                tuple((sub, "Number of mapped objects" if sub == 0 else f"Mapped object {sub}", u8 if sub == 0 else u32,
                       "rw") for sub in range(9)))


class _Task:
    def stop(self) -> None:
        pass


class NetworkShim:
    """What LocalNode needs of a network: subscriptions and send; frames go to ``send``."""

    def __init__(self, send: Callable[[int, bytes], None]) -> None:
        self._send = send
        self.subscribers: dict[int, list[Callback]] = {}

    def subscribe(self, can_id: int, callback: Callback) -> None:
        self.subscribers.setdefault(can_id, []).append(callback)

    def unsubscribe(self, can_id: int, callback: Callback | None = None) -> None:
        self.subscribers.pop(can_id, None)

    def send_message(self, can_id: int, data: bytes, remote: bool = False) -> None:
        self._send(can_id, bytes(data))

    def send_periodic(self, *args: object, **kwargs: object) -> _Task:
        # heartbeats are the simulated drive's own business (0x1017 goes through od_write)
        return _Task()

    def check(self) -> None:
        pass


# client command specifiers (byte 0 bits 7..5 of a request), CiA 301 7.2.4.3
CCS_DOWNLOAD_SEGMENT, CCS_DOWNLOAD, CCS_UPLOAD, CCS_UPLOAD_SEGMENT, CCS_ABORT, CCS_BLOCK_UPLOAD, \
    CCS_BLOCK_DOWNLOAD = 0, 1, 2, 3, 4, 5, 6
ABORT_COMMAND = 0x05040001  # "client/server command specifier not valid or unknown"
ABORT_GENERAL = 0x08000000
ABORT_TOO_LONG = 0x06070012  # "data type does not match, length of service parameter too high"


class ServedDrive(Protocol):
    """What the SDO server needs of a drive (sim/drive.py's SimDrive, sim/encoder.py's SimEncoder);
    one may also have ``sdo_extra``, more objects for the dictionary (:func:`build_object_dictionary`)."""

    def od_read(self, index: int, sub: int) -> OdValue | bytes: ...

    def od_write(self, index: int, sub: int, value: int) -> None: ...


def dictionary_of(drive: object) -> od.ObjectDictionary:
    """The SDO dictionary of a simulated node: a Whistle's, or what its class declares (``sdo_extra``,
    ``sdo_tpdos``, ``sdo_fixed_tpdos``, ``sdo_rpdo2``; sim/encoder.py)."""
    return build_object_dictionary(tuple(getattr(drive, "sdo_extra", DRIVE_OBJECTS)) + tuple(getattr(drive, "sdo_more", ())),
                                   getattr(drive, "sdo_tpdos", (0, 1, 2, 3)),
                                   getattr(drive, "sdo_fixed_tpdos", frozenset({1})), getattr(drive, "sdo_rpdo2", True),
                                   tuple(getattr(drive, "sdo_rpdos", ())))


class SdoServer:
    """Answers SDO requests (0x600+node) from a simulated drive's od_read/od_write.

    canopen's LocalNode does the framing; in front of it this class keeps the CiA 301 rules
    LocalNode leaves open: it knows whether a segmented transfer is in progress, so after an
    abort (sent or received) or a finished transfer a stray segment request is aborted instead
    of continuing the old one; block transfers, which the drive does not offer, are aborted
    (LocalNode would answer a block upload with a plain upload response); frames that are
    not 8 bytes long are not SDO requests and get no answer; a segmented download that brings more
    data than its initiate request indicated is aborted (0x06070012) at the segment that overflows,
    not taken on for as long as the client sends.
    """

    def __init__(self, node: int, drive: ServedDrive, send: Callable[[int, bytes], None]) -> None:
        self.node = node
        self.drive = drive
        self._out = send
        self._sent: list[bytes] = []
        self._transfer: str | None = None  # "upload" / "download" while a segmented transfer runs
        self._where = (0, 0)  # index, sub-index of the last initiated transfer
        self._indicated: int | None = None  # the size a segmented download's initiate request gave
        self._downloaded = 0  # bytes its segments brought so far
        self.shim = NetworkShim(self._send)
        self.local = canopen.LocalNode(node, dictionary_of(drive))
        self.local.add_read_callback(self._read)
        self.local.add_write_callback(self._write)
        # the shim has what LocalNode uses of a canopen.Network (subscribe, unsubscribe, send_message,
        # send_periodic), not the bus it would open
        self.local.associate_network(self.shim)  # type: ignore[arg-type]  # a duck-typed Network, see above
        # NMT is the simulated drive's own state machine, not LocalNode's
        self.shim.unsubscribe(0)

    def _read(self, index: int, subindex: int, od: canopen.objectdictionary.ODVariable) -> OdValue | bytes | None:
        if subindex == 0 and isinstance(od, canopen.objectdictionary.ODVariable) and od.parent is not None \
                and not isinstance(od.parent, canopen.objectdictionary.ObjectDictionary) and index != 0x1003 \
                and not 0x1400 <= index < 0x1C00:
            return od.default  # 0x1003:0 counts the stored errors, PDO records are the node's: not constants
        try:
            return self.drive.od_read(index, subindex)
        except ODError as exc:
            raise SdoAbortedError(exc.abort_code) from None
        except Exception:
            log.exception("simulated node %d: reading 0x%04X:%d failed", self.node, index, subindex)
            raise SdoAbortedError(ABORT_GENERAL) from None

    def _write(self, index: int, subindex: int, od: canopen.objectdictionary.ODVariable, data: bytes) -> None:
        try:
            # every writable object here has an integer data type, which decode_raw gives as an int
            self.drive.od_write(index, subindex, cast(int, od.decode_raw(data)))
        except ODError as exc:
            raise SdoAbortedError(exc.abort_code) from None
        except Exception:
            log.exception("simulated node %d: writing 0x%04X:%d failed", self.node, index, subindex)
            raise SdoAbortedError(ABORT_GENERAL) from None

    def _send(self, can_id: int, data: bytes) -> None:
        self._sent.append(bytes(data))
        self._out(can_id, data)

    def _abort(self, index: int, sub: int, code: int) -> None:
        self._transfer = None
        self._send(SDO_TX_BASE + self.node, struct.pack("<BHBL", 0x80, index, sub, code))

    def abort_request(self, data: bytes) -> None:
        """Answer a request the node failed on (a fault inside the simulator) with a general error."""
        if len(data) == 8 and data[0] >> 5 != CCS_ABORT:
            index, sub = struct.unpack_from("<HB", data, 1)
            self._abort(index, sub, ABORT_GENERAL)

    def receive(self, can_id: int, data: bytes, timestamp: float = 0.0) -> None:
        data = bytes(data)
        if len(data) != 8:
            return  # CiA 301: every SDO frame has 8 data bytes
        ccs = data[0] >> 5
        index, sub = struct.unpack_from("<HB", data, 1)
        if ccs == CCS_ABORT:
            self._transfer = None  # the client gave up: the next request starts afresh
            return
        if ccs in (CCS_BLOCK_UPLOAD, CCS_BLOCK_DOWNLOAD, 7):  # 7: no such command
            self._abort(index, sub, ABORT_COMMAND)
            return
        if (ccs == CCS_UPLOAD_SEGMENT and self._transfer != "upload") or \
                (ccs == CCS_DOWNLOAD_SEGMENT and self._transfer != "download"):
            self._abort(*self._where, ABORT_COMMAND)  # a segment of no transfer in progress
            return
        if ccs in (CCS_UPLOAD, CCS_DOWNLOAD):
            self._where = (index, sub)
        if ccs == CCS_DOWNLOAD:
            # bit 0 (s): bytes 4..7 give the size; bit 1 (e): expedited, no segments follow
            self._indicated = struct.unpack_from("<L", data, 4)[0] if data[0] & 0x03 == 0x01 else None
            self._downloaded = 0
        elif ccs == CCS_DOWNLOAD_SEGMENT:
            self._downloaded += 7 - (data[0] >> 1 & 0x07)  # bits 3..1 (n): bytes that carry no data
            if self._indicated is not None and self._downloaded > self._indicated:
                self._abort(*self._where, ABORT_TOO_LONG)
                return
        self._sent.clear()
        try:
            for callback in self.shim.subscribers.get(can_id, ()):
                callback(can_id, bytearray(data), timestamp)
        except Exception:
            log.exception("simulated node %d: SDO request %s failed", self.node, data.hex())
            self._abort(*self._where, ABORT_GENERAL)
            return
        last = self._sent[-1] if self._sent else None
        if last is None or last[0] == 0x80:
            self._transfer = None
        elif ccs == CCS_UPLOAD:
            self._transfer = None if last[0] & 0x02 else "upload"  # expedited: done in one frame
        elif ccs == CCS_DOWNLOAD:
            self._transfer = None if data[0] & 0x02 else "download"
        elif ccs in (CCS_UPLOAD_SEGMENT, CCS_DOWNLOAD_SEGMENT) and (last if ccs == CCS_UPLOAD_SEGMENT
                                                                    else data)[0] & 0x01:
            self._transfer = None  # the last segment
