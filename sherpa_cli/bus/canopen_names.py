"""CANopen names and texts (CiA 301): NMT states, vendor ids, SDO abort codes, VISIBLE_STRING.

Pure tables for scan, identify, monitor and the SDO client (bus/sdo.py); no I/O here.
"""

from __future__ import annotations

ELMO_VENDOR_ID = 0x9A
VENDORS = {ELMO_VENDOR_ID: "Elmo"}

# the state byte of a boot-up (0x00) or heartbeat frame
NMT_STATES = {0x00: "boot-up", 0x04: "stopped", 0x05: "operational", 0x7F: "pre-op"}

# SDO abort codes (CiA 301, 7.2.4.3.17), worded for a technician
SDO_ABORT_CODES = {
    0x05030000: "toggle bit not alternated",
    0x05040000: "SDO protocol timed out",
    0x05040001: "command specifier not valid or unknown",
    0x05040002: "invalid block size",
    0x05040003: "invalid sequence number",
    0x05040004: "CRC error",
    0x05040005: "out of memory",
    0x06010000: "unsupported access to an object",
    0x06010001: "attempt to read a write-only object",
    0x06010002: "attempt to write a read-only object",
    0x06020000: "object does not exist in the object dictionary",
    0x06040041: "object cannot be mapped to the PDO",
    0x06040042: "the number and length of the objects to be mapped would exceed the PDO length",
    0x06040043: "general parameter incompatibility",
    0x06040047: "general internal incompatibility in the device",
    0x06060000: "access failed due to a hardware error",
    0x06070010: "data type does not match, length of service parameter does not match",
    0x06070012: "data type does not match, length of service parameter too high",
    0x06070013: "data type does not match, length of service parameter too low",
    0x06090011: "sub-index does not exist",
    0x06090030: "value range of parameter exceeded",
    0x06090031: "value of parameter written too high",
    0x06090032: "value of parameter written too low",
    0x06090036: "maximum value is less than minimum value",
    0x060A0023: "resource not available: SDO connection",
    0x08000000: "general error",
    0x08000020: "data cannot be transferred or stored to the application",
    0x08000021: "data cannot be transferred or stored to the application because of local control",
    0x08000022: "data cannot be transferred or stored to the application because of the present device state",
    0x08000023: "object dictionary dynamic generation failed or no object dictionary is present",
    0x08000024: "no data available",
}


def nmt_text(state: int) -> str:
    """An NMT state byte of a boot-up or heartbeat frame, as text."""
    # a boot-up leaves the node pre-operational (elmo-protocol.md 3.2)
    return NMT_STATES[0x7F] if state == 0x00 else NMT_STATES.get(state, f"0x{state:02X}")


def abort_text(code: int) -> str:
    """An SDO abort code as text; an unknown code as "unknown abort code"."""
    return SDO_ABORT_CODES.get(code, "unknown abort code")


def decode_text(data: bytes) -> str:
    """A VISIBLE_STRING; some firmware pads with NULs."""
    return data.split(b"\0", 1)[0].decode("latin-1").strip()
