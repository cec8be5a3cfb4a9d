"""What a CAN frame on the arm's buses means: NMT, SYNC, EMCY, heartbeat, SDO, interpreter, PDO.

Pure: frames in (as :class:`Frame`), :class:`Decoded` out. The decoder keeps the state a
passive listener needs: segmented SDO transfers are joined per (bus, node), and PDO
mappings written through SDO in the capture (0x1600/0x1A00 range, COB-IDs in 0x1400/0x1800
sub 1) are remembered so later PDO frames decode by their mapping. Never raises on a frame:
what cannot be decoded is shown as such.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from typing import Any

from sherpa_cli.bus.canopen_names import abort_text, nmt_text
from sherpa_cli.elmo.codec import decode_reply, decode_request
from sherpa_cli.elmo.commands import format_value, lookup
from sherpa_cli.elmo.faults import decode_emcy
from sherpa_cli.errors import CodecError

KINDS = ("nmt", "sync", "emcy", "heartbeat", "sdo", "interp", "pdo", "remote", "malformed", "other")

NMT_COMMANDS = {0x01: "start", 0x02: "stop", 0x80: "enter pre-operational", 0x81: "reset node",
                0x82: "reset communication"}

# CANopen objects by name (CiA 301 / DS402 and the Elmo objects this tool touches)
OBJECT_NAMES = {
    0x1000: "device type", 0x1001: "error register", 0x1003: "pre-defined error field",
    0x1005: "SYNC COB-ID", 0x1006: "communication cycle period", 0x1008: "device name",
    0x1009: "hardware version", 0x100A: "software version", 0x1010: "store parameters",
    0x1014: "EMCY COB-ID", 0x1016: "consumer heartbeat time", 0x1017: "producer heartbeat time",
    0x1018: "identity", 0x1029: "error behaviour",
    0x2012: "binary interpreter input", 0x2013: "binary interpreter output", 0x2030: "recorder data",
    0x2F20: "TPDO asynchronous events", 0x2F21: "emergency events",
    0x6007: "abort connection option code", 0x6041: "statusword", 0x6060: "modes of operation",
    0x6064: "position actual value", 0x606C: "velocity actual value", 0x6069: "velocity sensor actual value",
    0x6077: "torque actual value", 0x6078: "current actual value",
}
IDENTITY_SUBS = {1: "vendor id", 2: "product code", 3: "revision", 4: "serial number"}
PDO_COMM_SUBS = {1: "COB-ID", 2: "transmission type", 3: "inhibit time", 5: "event timer"}


def object_name(index: int, sub: int) -> str:
    for base, what in ((0x1400, "RPDO{} communication"), (0x1600, "RPDO{} mapping"),
                       (0x1800, "TPDO{} communication"), (0x1A00, "TPDO{} mapping")):
        if base <= index < base + 0x200:
            name = what.format(index - base + 1)
            if what.endswith("communication") and sub in PDO_COMM_SUBS:
                return f"{name} {PDO_COMM_SUBS[sub]}"
            if what.endswith("mapping"):
                return f"{name} {'count' if sub == 0 else f'entry {sub}'}"
            return name
    name = OBJECT_NAMES.get(index, "")
    if index == 0x1018 and sub in IDENTITY_SUBS:
        name = f"identity {IDENTITY_SUBS[sub]}"
    return name


@dataclass(frozen=True)
class Frame:
    """One frame of a capture; ``bus`` is the configured bus name (or the capture's channel)."""

    timestamp: float
    bus: str
    can_id: int
    data: bytes
    is_extended: bool = False
    is_remote: bool = False
    is_error: bool = False

    def raw(self) -> str:
        ident = f"{self.can_id:08X}" if self.is_extended else f"{self.can_id:03X}"
        return f"{ident}#{'R' if self.is_remote else self.data.hex().upper()}"


@dataclass(frozen=True)
class Decoded:
    frame: Frame
    kind: str
    node: int | None
    text: str
    fields: dict[str, Any] = field(default_factory=dict)

    def as_json(self, t0: float) -> dict[str, Any]:
        return {"time": round(self.frame.timestamp - t0, 6), "bus": self.frame.bus,
                "id": self.frame.can_id, "remote": self.frame.is_remote, "data": self.frame.data.hex(),
                "kind": self.kind, "node": self.node, "text": self.text,
                **({"fields": self.fields} if self.fields else {})}


@dataclass
class _Transfer:
    index: int
    sub: int
    upload: bool
    data: bytearray = field(default_factory=bytearray)
    size: int | None = None


@dataclass(frozen=True)
class PdoEntry:
    index: int
    sub: int
    bits: int


def _u(data: bytes) -> int:
    return int.from_bytes(data, "little")


def _value_text(index: int, sub: int, data: bytes) -> tuple[str, Any]:
    if not data:
        return "(no data)", None
    if index in (0x1008, 0x1009, 0x100A) or (len(data) > 4 and all(32 <= b < 127 or b == 0 for b in data)):
        text = data.split(b"\0", 1)[0].decode("latin-1")
        return repr(text), text
    if len(data) <= 4:
        value = _u(data)
        if ((0x1400 <= index < 0x1600 or 0x1800 <= index < 0x1A00) and sub == 1) or \
                ((0x1600 <= index < 0x1800 or 0x1A00 <= index < 0x1C00) and sub > 0):
            return f"0x{value:08X}", value
        if index in (0x6064, 0x606C, 0x6069, 0x6077, 0x6078) and len(data) in (2, 4):
            signed = int.from_bytes(data, "little", signed=True)
            return str(signed), signed
        return f"{value} (0x{value:0{2 * len(data)}X})", value
    return data.hex(" "), data.hex()


class FrameDecoder:
    """Decode frames in capture order; ``nodes`` names a (bus, node) as its drive (optional)."""

    def __init__(self, nodes: dict[tuple[str, int], str] | None = None) -> None:
        self.nodes = dict(nodes or {})
        # for captures without a bus per frame (.csv): a node id that only one drive has
        by_id: dict[int, list[str]] = {}
        for (_, node), name in self.nodes.items():
            by_id.setdefault(node, []).append(name)
        self._unique = {node: names[0] for node, names in by_id.items() if len(names) == 1}
        self._buses = {bus for bus, _ in self.nodes}
        self._sdo: dict[tuple[str, int], _Transfer] = {}
        self._pending_write: dict[tuple[str, int], tuple[int, int, int]] = {}
        # per bus: TPDO/RPDO number -> (cob id, mapping) as written in the capture
        self._maps: dict[tuple[str, int, str, int], list[PdoEntry]] = {}
        self._cobs: dict[tuple[str, int, str, int], int] = {}

    # -- the public entry ---------------------------------------------------------------------
    def decode(self, frame: Frame) -> Decoded:
        try:
            return self._decode(frame)
        except (CodecError, struct.error, ValueError, IndexError) as exc:
            return Decoded(frame, "other", None, f"undecodable: {exc}")

    def decode_all(self, frames: Iterable[Frame]) -> Iterator[Decoded]:
        for frame in frames:
            yield self.decode(frame)

    def _who(self, bus: str, node: int) -> str:
        name = self.nodes.get((bus, node)) if bus in self._buses else self._unique.get(node)
        return f"node {node}" + (f" ({name})" if name else "")

    def _decode(self, frame: Frame) -> Decoded:
        cid, data = frame.can_id, frame.data
        if frame.is_error:
            return Decoded(frame, "other", None, "error frame")
        if frame.is_extended:
            return Decoded(frame, "other", None, "extended id (not CANopen)")
        if frame.is_remote:
            return self._remote(frame)
        wrong = _malformed(cid, data)
        if wrong is not None:
            node = cid & 0x7F if cid > 0x80 else None
            who = f"{self._who(frame.bus, node)} " if node else ""
            return Decoded(frame, "malformed", node, f"{who}malformed: {wrong}", {"malformed": wrong})
        if cid == 0x000:
            cmd = NMT_COMMANDS.get(data[0], f"command 0x{data[0]:02X}") if data else "(empty)"
            target = data[1] if len(data) > 1 else 0
            who = "all nodes" if target == 0 else self._who(frame.bus, target)
            return Decoded(frame, "nmt", target or None, f"NMT {cmd} {who}", {"command": cmd})
        if cid == 0x080:
            text = "SYNC" + (f" counter {data[0]}" if data else "")
            return Decoded(frame, "sync", None, text)
        pdo = self._mapped_pdo(frame)
        if pdo is not None:
            return pdo
        func, node = cid & 0x780, cid & 0x7F
        if 0x081 <= cid <= 0x0FF:
            emcy = decode_emcy(data)
            return Decoded(frame, "emcy", node, f"{self._who(frame.bus, node)} {emcy.text}",
                           {"code": emcy.code, "elmo_code": emcy.elmo_code})
        if func == 0x700 and node:
            if len(data) < 1:
                return Decoded(frame, "heartbeat", node, f"{self._who(frame.bus, node)} heartbeat (empty)")
            state = data[0] & 0x7F
            what = "boot-up" if state == 0 else f"heartbeat {nmt_text(state)}"
            return Decoded(frame, "heartbeat", node, f"{self._who(frame.bus, node)} {what}", {"state": state})
        if func == 0x600 and node:
            return self._sdo_request(frame, node)
        if func == 0x580 and node:
            return self._sdo_response(frame, node)
        if func == 0x300 and node:
            req = decode_request(data)
            name = _command_name(req.letters)
            where = f"{req.letters}[{req.index}]" if req.index else req.letters
            if req.kind == "query":
                text = f"{where}?"
            elif req.kind == "execute":
                text = f"{where} (execute)"
            else:
                text = f"{where}={format_value(req.value)}"
            return Decoded(frame, "interp", node, f"{self._who(frame.bus, node)} -> {text}{name}",
                           {"request": req.kind, "letters": req.letters, "index": req.index, "value": req.value})
        if func == 0x280 and node:
            rep = decode_reply(data)
            where = f"{rep.letters}[{rep.index}]" if rep.index else rep.letters
            name = _command_name(rep.letters)
            if rep.ok:
                text = f"{where}={format_value(rep.value)}"
            else:
                text = f"{where} error {rep.error_code}: {rep.error_text}"
            return Decoded(frame, "interp", node, f"{self._who(frame.bus, node)} <- {text}{name}",
                           {"reply": rep.letters, "index": rep.index, "value": rep.value,
                            "error_code": rep.error_code})
        if func in (0x180, 0x200, 0x380, 0x400, 0x480, 0x500) and node:
            pdo_name = PDO_NAMES[func]
            return Decoded(frame, "pdo", node, f"{self._who(frame.bus, node)} {pdo_name} {data.hex(' ')}"
                           " (mapping not in the capture)")
        return Decoded(frame, "other", None, f"{len(data)} bytes")

    def _remote(self, frame: Frame) -> Decoded:
        """A remote (RTR) frame asks a producer for the frame of that id; it is no SYNC, heartbeat or
        PDO itself (CiA 301: the Whistle's PDOs are not RTR-requestable)."""
        cid, node = frame.can_id, frame.can_id & 0x7F
        func = cid & 0x780
        if cid == 0x000:
            asked = "the NMT id"
        elif cid == 0x080:
            asked = "the SYNC id"
        elif func == 0x700 and node:
            asked = f"{self._who(frame.bus, node)}'s heartbeat (node guarding)"
        elif func in PDO_NAMES and node:
            asked = f"{self._who(frame.bus, node)}'s {PDO_NAMES[func]}"
        else:
            asked = f"id 0x{cid:03X}"
        return Decoded(frame, "remote", node if cid > 0x80 else None, f"remote request (RTR) for {asked}",
                       {"remote": True})

    # -- SDO ----------------------------------------------------------------------------------
    def _sdo_request(self, frame: Frame, node: int) -> Decoded:
        data, key, who = frame.data, (frame.bus, node), self._who(frame.bus, node)
        ccs = data[0] >> 5
        if ccs in (1, 2):  # initiate download / upload
            index, sub = struct.unpack_from("<HB", data, 1)
            name = _named(index, sub)
            if ccs == 2:
                self._sdo[key] = _Transfer(index, sub, upload=True)
                return Decoded(frame, "sdo", node, f"{who} SDO read 0x{index:04X}:{sub}{name}",
                               {"sdo": "read", "index": index, "sub": sub})
            expedited, sized = data[0] & 0x02, data[0] & 0x01
            if expedited:
                n = 4 - ((data[0] >> 2) & 0x03) if sized else 4
                payload = bytes(data[4:4 + n])
                self._sdo.pop(key, None)
                self._pending_write[key] = (index, sub, _u(payload))
                text, value = _value_text(index, sub, payload)
                return Decoded(frame, "sdo", node, f"{who} SDO write 0x{index:04X}:{sub}{name} = {text}",
                               {"sdo": "write", "index": index, "sub": sub, "value": value})
            transfer = _Transfer(index, sub, upload=False, size=_u(data[4:8]) if sized else None)
            self._sdo[key] = transfer
            return Decoded(frame, "sdo", node, f"{who} SDO write 0x{index:04X}:{sub}{name} (segmented, "
                           f"{transfer.size if transfer.size is not None else '?'} bytes)",
                           {"sdo": "write", "index": index, "sub": sub})
        if ccs == 0:  # download segment
            download = self._sdo.get(key)
            n = 7 - ((data[0] >> 1) & 0x07)
            last = data[0] & 0x01
            if download is None or download.upload:
                return Decoded(frame, "sdo", node, f"{who} SDO download segment outside a download")
            download.data += data[1:1 + n]
            if not last:
                return Decoded(frame, "sdo", node, f"{who} SDO write segment ({len(download.data)} bytes so far)")
            text, value = _value_text(download.index, download.sub, bytes(download.data))
            self._sdo.pop(key, None)
            return Decoded(frame, "sdo", node, f"{who} SDO write 0x{download.index:04X}:{download.sub}"
                           f"{_named(download.index, download.sub)} = {text} (last segment)",
                           {"sdo": "write", "index": download.index, "sub": download.sub, "value": value})
        if ccs == 3:
            return Decoded(frame, "sdo", node, f"{who} SDO read segment request")
        if ccs == 4:
            return self._abort(frame, node, "host")
        return Decoded(frame, "sdo", node, f"{who} SDO request 0x{data[0]:02X} (block transfer, not decoded)")

    def _sdo_response(self, frame: Frame, node: int) -> Decoded:
        data, key, who = frame.data, (frame.bus, node), self._who(frame.bus, node)
        scs = data[0] >> 5
        if scs == 2:  # initiate upload response
            index, sub = struct.unpack_from("<HB", data, 1)
            name = _named(index, sub)
            if data[0] & 0x02:
                n = 4 - ((data[0] >> 2) & 0x03) if data[0] & 0x01 else 4
                self._sdo.pop(key, None)
                text, value = _value_text(index, sub, bytes(data[4:4 + n]))
                return Decoded(frame, "sdo", node, f"{who} SDO 0x{index:04X}:{sub}{name} = {text}",
                               {"sdo": "value", "index": index, "sub": sub, "value": value})
            size = _u(data[4:8]) if data[0] & 0x01 else None
            self._sdo[key] = _Transfer(index, sub, upload=True, size=size)
            return Decoded(frame, "sdo", node, f"{who} SDO 0x{index:04X}:{sub}{name} (segmented, "
                           f"{size if size is not None else '?'} bytes)", {"sdo": "value", "index": index, "sub": sub})
        if scs == 3:  # download confirmed
            index, sub = struct.unpack_from("<HB", data, 1)
            written = self._pending_write.pop(key, None)
            if written is not None and written[:2] == (index, sub):
                self._remember_pdo(frame.bus, node, index, sub, written[2])
            return Decoded(frame, "sdo", node, f"{who} SDO write 0x{index:04X}:{sub}{_named(index, sub)} done",
                           {"sdo": "written", "index": index, "sub": sub})
        if scs == 0:  # upload segment
            upload = self._sdo.get(key)
            if upload is None or not upload.upload:
                return Decoded(frame, "sdo", node, f"{who} SDO upload segment outside a upload")
            n = 7 - ((data[0] >> 1) & 0x07)
            upload.data += data[1:1 + n]
            if not data[0] & 0x01:
                return Decoded(frame, "sdo", node, f"{who} SDO segment ({len(upload.data)} bytes so far)")
            self._sdo.pop(key, None)
            text, value = _value_text(upload.index, upload.sub, bytes(upload.data))
            return Decoded(frame, "sdo", node, f"{who} SDO 0x{upload.index:04X}:{upload.sub}"
                           f"{_named(upload.index, upload.sub)} = {text} (last segment)",
                           {"sdo": "value", "index": upload.index, "sub": upload.sub, "value": value})
        if scs == 1:
            return Decoded(frame, "sdo", node, f"{who} SDO write segment confirmed")
        if scs == 4:
            return self._abort(frame, node, "drive")
        return Decoded(frame, "sdo", node, f"{who} SDO response 0x{data[0]:02X} (block transfer, not decoded)")

    def _abort(self, frame: Frame, node: int, by: str) -> Decoded:
        index, sub, code = struct.unpack_from("<HBI", frame.data, 1)
        self._sdo.pop((frame.bus, node), None)
        self._pending_write.pop((frame.bus, node), None)
        return Decoded(frame, "sdo", node, f"{self._who(frame.bus, node)} SDO abort by the {by} "
                       f"0x{index:04X}:{sub}{_named(index, sub)}: 0x{code:08X} {abort_text(code)}",
                       {"sdo": "abort", "index": index, "sub": sub, "abort_code": code})

    # -- PDO mapping seen in the capture ------------------------------------------------------
    def _remember_pdo(self, bus: str, node: int, index: int, sub: int, value: int) -> None:
        for base, kind, comm in ((0x1600, "R", False), (0x1A00, "T", False), (0x1400, "R", True),
                                 (0x1800, "T", True)):
            if base <= index < base + 0x200:
                number = index - base
                key = (bus, node, kind, number)
                if comm:
                    if sub == 1:
                        self._cobs[key] = value
                elif sub == 0:
                    self._maps[key] = self._maps.get(key, [])[:value]
                else:
                    entries = self._maps.setdefault(key, [])
                    entry = PdoEntry(value >> 16, (value >> 8) & 0xFF, value & 0xFF)
                    while len(entries) < sub:
                        entries.append(PdoEntry(0, 0, 0))
                    entries[sub - 1] = entry
                return

    def _mapped_pdo(self, frame: Frame) -> Decoded | None:
        for (bus, node, kind, number), entries in self._maps.items():
            if bus != frame.bus or not entries:
                continue
            default = (0x180 if kind == "T" else 0x200) + 0x100 * number + node
            cob = self._cobs.get((bus, node, kind, number), default) & 0x7FF
            if cob != frame.can_id or self._cobs.get((bus, node, kind, number), 0) & 0x80000000:
                continue
            parts, values, bit = [], {}, 0
            payload = _u(frame.data)
            for e in entries:
                if not e.bits:
                    continue
                raw = (payload >> bit) & ((1 << e.bits) - 1)
                if raw >> (e.bits - 1):
                    raw -= 1 << e.bits
                bit += e.bits
                name = OBJECT_NAMES.get(e.index, f"0x{e.index:04X}:{e.sub}")
                parts.append(f"{name}={raw}")
                values[f"0x{e.index:04X}:{e.sub}"] = raw
            return Decoded(frame, "pdo", node, f"{self._who(bus, node)} {kind}PDO{number + 1} "
                           + ", ".join(parts), {"values": values})
        return None


PDO_NAMES = {0x180: "TPDO1", 0x200: "RPDO1", 0x280: "TPDO2", 0x300: "RPDO2", 0x380: "TPDO3", 0x400: "RPDO3",
             0x480: "TPDO4", 0x500: "RPDO4"}


def _malformed(cid: int, data: bytes) -> str | None:
    """What is wrong with a CANopen frame's length for its id (CiA 301), None when it can be one:
    NMT 2 bytes, SYNC 0 or 1, EMCY and SDO 8, heartbeat 1."""
    n = len(data)
    func, node = cid & 0x780, cid & 0x7F
    if cid == 0x000 and n != 2:
        return f"NMT command with {n} byte(s) (an NMT command has 2)"
    if cid == 0x080 and n > 1:
        return f"SYNC with {n} bytes (a SYNC has none, or a 1-byte counter)"
    if 0x081 <= cid <= 0x0FF and n != 8:
        return f"EMCY with {n} byte(s) (an EMCY has 8)"
    if func in (0x580, 0x600) and node and n != 8:
        what = "request" if func == 0x600 else "response"
        return f"SDO {what} with {n} byte(s) (an SDO frame has 8)"
    if func == 0x700 and node and n != 1:
        return f"heartbeat with {n} byte(s) (a heartbeat has 1)"
    return None


def _named(index: int, sub: int) -> str:
    name = object_name(index, sub)
    return f" ({name})" if name else ""


def _command_name(letters: str) -> str:
    try:
        return f" ({lookup(letters).description})"
    except CodecError:
        return ""


# -- can-utils `candump -L` text -----------------------------------------------------------------

def parse_candump_line(line: str, where: str) -> Frame | None:
    """``(1600000000.000000) can0 123#DEADBEEF`` (optionally a trailing R/T direction); blank and
    ``#`` comment lines give None. Raises ValueError naming ``where`` for anything else."""
    text = line.strip()
    if not text or text.startswith("#"):
        return None
    parts = text.split()
    try:
        if len(parts) < 3 or not (parts[0].startswith("(") and parts[0].endswith(")")):
            raise ValueError("expected '(TIMESTAMP) CHANNEL ID#DATA'")
        if not (parts[0].isascii() and parts[2].isascii()):  # float()/int() read other scripts' digits
            raise ValueError("the timestamp and ID#DATA must be ASCII")
        timestamp = float(parts[0][1:-1])
        ident, sep, payload = parts[2].partition("#")
        if not sep or not ident:
            raise ValueError(f"{parts[2]!r} is not ID#DATA")
        can_id = int(ident, 16)
        extended = len(ident) > 3
        remote = payload.upper().startswith("R")
        if payload.startswith("#"):  # CAN FD: ID##<flags><data>
            payload = payload[2:]
        data = b"" if remote else bytes.fromhex(payload.replace(".", ""))
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from None
    if extended and can_id & 0x20000000:
        return Frame(timestamp, parts[1], can_id & 0x1FFFFFFF, data, True, remote, is_error=True)
    return Frame(timestamp, parts[1], can_id, data, extended, remote)
