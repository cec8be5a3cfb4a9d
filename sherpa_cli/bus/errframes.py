"""Decode Linux SocketCAN error frames (``CAN_ERR_*``, include/uapi/linux/can/error.h) into what
happened on the bus and what to check. Pure code: no I/O, no python-can.

python-can hands an error frame over as a ``can.Message`` with ``is_error_frame`` set, the error
class bits in ``arbitration_id`` (the CAN_ERR_FLAG itself already stripped) and eight data bytes:

- byte 0: the bit position where arbitration was lost (CAN_ERR_LOSTARB)
- byte 1: controller status (CAN_ERR_CRTL): overflow, warning, passive, back to active
- bytes 2-3: protocol violation type and location (CAN_ERR_PROT)
- byte 4: transceiver status (CAN_ERR_TRX)
- bytes 6-7: the TX and RX error counters, valid when CAN_ERR_CNT is set

The hints are what a technician checks first (../shared/docs/real-arm.md section 1).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

CAN_ERR_FLAG = 0x20000000  # in a raw can_id: this is an error frame
CAN_ERR_MASK = 0x1FFFFFFF

# error classes (can_id bits)
CAN_ERR_TX_TIMEOUT = 0x001
CAN_ERR_LOSTARB = 0x002
CAN_ERR_CRTL = 0x004
CAN_ERR_PROT = 0x008
CAN_ERR_TRX = 0x010
CAN_ERR_ACK = 0x020
CAN_ERR_BUSOFF = 0x040
CAN_ERR_BUSERROR = 0x080
CAN_ERR_RESTARTED = 0x100
CAN_ERR_CNT = 0x200

# data[1]: controller
CAN_ERR_CRTL_RX_OVERFLOW = 0x01
CAN_ERR_CRTL_TX_OVERFLOW = 0x02
CAN_ERR_CRTL_RX_WARNING = 0x04
CAN_ERR_CRTL_TX_WARNING = 0x08
CAN_ERR_CRTL_RX_PASSIVE = 0x10
CAN_ERR_CRTL_TX_PASSIVE = 0x20
CAN_ERR_CRTL_ACTIVE = 0x40

# data[2]: protocol violation type
CAN_ERR_PROT_BIT = 0x01
CAN_ERR_PROT_FORM = 0x02
CAN_ERR_PROT_STUFF = 0x04
CAN_ERR_PROT_BIT0 = 0x08
CAN_ERR_PROT_BIT1 = 0x10
CAN_ERR_PROT_OVERLOAD = 0x20
CAN_ERR_PROT_ACTIVE = 0x40
CAN_ERR_PROT_TX = 0x80

# data[3]: protocol violation location
PROT_LOCATIONS: dict[int, str] = {
    0x03: "start of frame", 0x02: "ID bits 28-21 (SFF 10-3)", 0x06: "ID bits 20-18 (SFF 2-0)",
    0x04: "substitute RTR (SFF RTR)", 0x05: "identifier extension", 0x07: "ID bits 17-13",
    0x0F: "ID bits 12-5", 0x0E: "ID bits 4-0", 0x0C: "RTR", 0x0D: "reserved bit 1", 0x09: "reserved bit 0",
    0x0B: "data length code", 0x0A: "data field", 0x08: "CRC sequence", 0x18: "CRC delimiter",
    0x19: "ACK slot", 0x1B: "ACK delimiter", 0x1A: "end of frame", 0x12: "intermission",
}
CRC_LOCATIONS = frozenset({0x08, 0x18})

# data[4]: transceiver
TRX_STATUS: dict[int, str] = {
    0x04: "CANH no wire", 0x05: "CANH short to battery", 0x06: "CANH short to VCC", 0x07: "CANH short to GND",
    0x40: "CANL no wire", 0x50: "CANL short to battery", 0x60: "CANL short to VCC", 0x70: "CANL short to GND",
    0x80: "CANL short to CANH",
}

# the short names of error kinds (what `bus watch` counts, what the simulator injects)
KINDS = ("tx-timeout", "lost-arbitration", "rx-overflow", "tx-overflow", "warning", "passive", "active",
         "bit", "form", "stuff", "crc", "overload", "protocol", "transceiver", "no-ack", "bus-off",
         "bus-error", "restarted")

HINTS: dict[str, str] = {
    "no-ack": "no ACK: is another node powered, is the bus terminated?",
    "stuff": "stuff/form errors: bit rate mismatch or wiring",
    "form": "stuff/form errors: bit rate mismatch or wiring",
    "bit": "bit errors: wiring, termination, or two nodes sending the same id",
    "crc": "CRC errors: noise or a poor cable; check termination (120 ohm at each end) and the bit rate",
    "protocol": "protocol errors: check the bit rate, sample point and wiring",
    "overload": "overload frames: a node cannot keep up",
    "warning": "error counters passed 96: the bus is having errors; see which class above",
    "passive": "error-passive (a counter passed 127): this node keeps failing; check bit rate, "
               "termination, wiring",
    "active": "back to error-active: the errors stopped",
    "bus-off": "bus-off: the controller stopped sending; fix the cause, it restarts after restart-ms "
               "(or `sherpa bus down` and `sherpa bus up`)",
    "restarted": "the controller restarted after bus-off",
    "rx-overflow": "receive overflow: frames were lost; the host reads too slowly or the bus is overloaded",
    "tx-overflow": "transmit overflow: the adapter's queue is full; the bus is blocked or too slow",
    "lost-arbitration": "lost arbitration: normal under load; all the time means a babbling node",
    "tx-timeout": "TX timeout: the adapter could not send (bus-off, no other node, or a driver problem)",
    "transceiver": "transceiver fault: check CANH/CANL wiring and the cable",
    "bus-error": "bus error: enable berr-reporting to see which kind",
}


@dataclass(frozen=True)
class ErrorFrame:
    """One decoded error frame: its error kinds (short names, :data:`KINDS` order), a description
    per kind, the counters when the frame carries them, and one hint per kind."""

    kinds: tuple[str, ...]
    details: tuple[str, ...]
    tec: int | None = None
    rec: int | None = None
    raw_id: int = 0
    data: bytes = b""

    @property
    def hints(self) -> tuple[str, ...]:
        seen: list[str] = []
        for kind in self.kinds:
            hint = HINTS.get(kind)
            if hint is not None and hint not in seen:
                seen.append(hint)
        return tuple(seen)

    @property
    def summary(self) -> str:
        text = "; ".join(self.details) if self.details else "error frame without a class"
        if self.tec is not None:
            text += f" (TEC {self.tec}, REC {self.rec})"
        return text

    def as_json(self) -> dict[str, Any]:
        return {"kinds": list(self.kinds), "details": list(self.details), "tec": self.tec, "rec": self.rec,
                "hints": list(self.hints), "id": f"0x{self.raw_id:08X}", "data": self.data.hex()}


def _location(loc: int) -> str:
    return PROT_LOCATIONS.get(loc, f"location 0x{loc:02X}")


def decode_error_frame(can_id: int, data: bytes | bytearray) -> ErrorFrame:
    """Decode one error frame: ``can_id`` with or without CAN_ERR_FLAG, ``data`` up to 8 bytes
    (missing bytes read 0, as the kernel always sends 8)."""
    cls = can_id & CAN_ERR_MASK
    raw = bytes(data[:8])
    d = raw.ljust(8, b"\x00")
    found: dict[str, str] = {}

    def add(kind: str, text: str) -> None:
        found.setdefault(kind, text)

    if cls & CAN_ERR_TX_TIMEOUT:
        add("tx-timeout", "TX timeout")
    if cls & CAN_ERR_LOSTARB:
        add("lost-arbitration", f"lost arbitration at bit {d[0]}" if d[0] else "lost arbitration")
    if cls & CAN_ERR_CRTL:
        c = d[1]
        if c & CAN_ERR_CRTL_RX_OVERFLOW:
            add("rx-overflow", "controller: RX buffer overflow")
        if c & CAN_ERR_CRTL_TX_OVERFLOW:
            add("tx-overflow", "controller: TX buffer overflow")
        sides = [side for bit, side in ((CAN_ERR_CRTL_TX_WARNING, "TX"), (CAN_ERR_CRTL_RX_WARNING, "RX")) if c & bit]
        if sides:
            add("warning", f"controller: error-warning ({'/'.join(sides)})")
        sides = [side for bit, side in ((CAN_ERR_CRTL_TX_PASSIVE, "TX"), (CAN_ERR_CRTL_RX_PASSIVE, "RX")) if c & bit]
        if sides:
            add("passive", f"controller: error-passive ({'/'.join(sides)})")
        if c & CAN_ERR_CRTL_ACTIVE:
            add("active", "controller: back to error-active")
        if not c:
            add("protocol", "controller problem (unspecified)")
    if cls & CAN_ERR_PROT:
        kind, loc = d[2], d[3]
        where = f" at {_location(loc)}" if loc else ""
        side = " on transmit" if kind & CAN_ERR_PROT_TX else ""
        if kind & (CAN_ERR_PROT_BIT | CAN_ERR_PROT_BIT0 | CAN_ERR_PROT_BIT1):
            which = ("dominant bit not sent" if kind & CAN_ERR_PROT_BIT0 else
                     "recessive bit not sent" if kind & CAN_ERR_PROT_BIT1 else "bit error")
            add("bit", f"{which}{where}{side}")
        if kind & CAN_ERR_PROT_FORM:
            add("form", f"form error{where}{side}")
        if kind & CAN_ERR_PROT_STUFF:
            add("stuff", f"stuff error{where}{side}")
        if kind & CAN_ERR_PROT_OVERLOAD:
            add("overload", f"overload{where}")
        if loc in CRC_LOCATIONS and not kind & (CAN_ERR_PROT_BIT | CAN_ERR_PROT_BIT0 | CAN_ERR_PROT_BIT1
                                                 | CAN_ERR_PROT_FORM | CAN_ERR_PROT_STUFF):
            add("crc", f"CRC error at {_location(loc)}{side}")
        if not any(k in found for k in ("bit", "form", "stuff", "overload", "crc")):
            add("protocol", f"protocol violation{where}{side}" if where or side else "protocol violation (unspecified)")
    if cls & CAN_ERR_TRX:
        add("transceiver", f"transceiver: {TRX_STATUS.get(d[4], f'status 0x{d[4]:02X}')}")
    if cls & CAN_ERR_ACK:
        add("no-ack", "no ACK on transmission")
    if cls & CAN_ERR_BUSOFF:
        add("bus-off", "bus-off")
    if cls & CAN_ERR_BUSERROR and not any(k in found for k in ("bit", "form", "stuff", "crc", "protocol",
                                                                "overload", "no-ack")):
        add("bus-error", "bus error")  # drivers set it beside the class that says which; alone it says little
    if cls & CAN_ERR_RESTARTED:
        add("restarted", "controller restarted")
    tec = rec = None
    if cls & CAN_ERR_CNT:
        tec, rec = d[6], d[7]
    kinds = tuple(k for k in KINDS if k in found)
    return ErrorFrame(kinds, tuple(found[k] for k in kinds), tec, rec, cls, raw)


def encode_error_frame(kinds: tuple[str, ...] | list[str], *, tec: int | None = None, rec: int | None = None,
                       location: int = 0, transmit: bool = False) -> tuple[int, bytes]:
    """The (class bits, 8 data bytes) of an error frame with these kinds: what tests and ``cansend``
    in the vcan guest send. The inverse of :func:`decode_error_frame` for the kinds it names."""
    cls = 0
    d = bytearray(8)
    for kind in kinds:
        if kind == "tx-timeout":
            cls |= CAN_ERR_TX_TIMEOUT
        elif kind == "lost-arbitration":
            cls |= CAN_ERR_LOSTARB
            d[0] = location
        elif kind in ("rx-overflow", "tx-overflow", "warning", "passive", "active"):
            cls |= CAN_ERR_CRTL
            d[1] |= {"rx-overflow": CAN_ERR_CRTL_RX_OVERFLOW, "tx-overflow": CAN_ERR_CRTL_TX_OVERFLOW,
                     "warning": CAN_ERR_CRTL_TX_WARNING if transmit else CAN_ERR_CRTL_RX_WARNING,
                     "passive": CAN_ERR_CRTL_TX_PASSIVE if transmit else CAN_ERR_CRTL_RX_PASSIVE,
                     "active": CAN_ERR_CRTL_ACTIVE}[kind]
        elif kind in ("bit", "form", "stuff", "overload", "crc", "protocol"):
            cls |= CAN_ERR_PROT
            d[2] |= {"bit": CAN_ERR_PROT_BIT, "form": CAN_ERR_PROT_FORM, "stuff": CAN_ERR_PROT_STUFF,
                     "overload": CAN_ERR_PROT_OVERLOAD, "crc": 0, "protocol": 0}[kind]
            if transmit:
                d[2] |= CAN_ERR_PROT_TX
            d[3] = 0x08 if kind == "crc" and not location else location
        elif kind == "transceiver":
            cls |= CAN_ERR_TRX
            d[4] = location or 0x04
        elif kind == "no-ack":
            cls |= CAN_ERR_ACK
        elif kind == "bus-off":
            cls |= CAN_ERR_BUSOFF
        elif kind == "bus-error":
            cls |= CAN_ERR_BUSERROR
        elif kind == "restarted":
            cls |= CAN_ERR_RESTARTED
        else:
            raise ValueError(f"unknown error kind {kind!r}; known: {', '.join(KINDS)}")
    if tec is not None or rec is not None:
        cls |= CAN_ERR_CNT
        d[6], d[7] = min(tec or 0, 255), min(rec or 0, 255)
    return cls, bytes(d)
