"""Binary-interpreter frames (RPDO2 requests, TPDO2 replies), elmo-protocol.md section 1.

Bytes 2..3 of every frame are read as one little-endian u16: the 14-bit index plus two
flag bits (0x8000 float, 0x4000 query in a request / error in a reply).
"""

from __future__ import annotations

import math
import re
import struct
from dataclasses import dataclass
from typing import Literal, NamedTuple

from sherpa_cli.elmo.commands import COMMANDS, INDEX_MAX, INT32_MAX, INT32_MIN, CommandSpec, check_letters, lookup
from sherpa_cli.elmo.faults import ec_text
from sherpa_cli.errors import CodecError

HEADER = struct.Struct("<2sH")  # letters, index|flags
FRAME = struct.Struct("<2sH4s")  # header + 4 data bytes
INT32 = struct.Struct("<i")
FLOAT32 = struct.Struct("<f")

FLAG_FLOAT = 0x8000
FLAG_QUERY = 0x4000  # request meaning
FLAG_ERROR = 0x4000  # reply meaning of the same bit
INDEX_MASK = 0x3FFF

Kind = Literal["set", "query", "execute"]


@dataclass(frozen=True)
class Request:
    """A request as the drive sees it (decoded frame) or as a technician typed it."""

    kind: Kind
    letters: str
    index: int
    value: int | float | None
    is_float: bool


class Reply(NamedTuple):
    """A decoded TPDO2 reply; ``error_code`` is set when the drive refused the command.

    A NamedTuple rather than a frozen dataclass: one is built per received frame, and
    tuple construction is several times cheaper.
    """

    letters: str
    index: int  # type: ignore[assignment]  # the field shadows tuple.index, as intended
    value: int | float | None
    is_float: bool
    error_code: int | None = None

    @property
    def ok(self) -> bool:
        return self.error_code is None

    @property
    def error_text(self) -> str | None:
        if self.error_code is None:
            return None
        return ec_text(self.error_code)


# -- value checks ---------------------------------------------------------------------------------

def _what(letters: str, index: int) -> str:
    spec = COMMANDS.get(letters)
    return f"{letters}[{index}]" if index or (spec and spec.is_array) else letters


def check_int32(value: object, what: str) -> int:
    """``value`` as an int32; integral floats are accepted, anything else raises CodecError."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise CodecError(f"{what}: value must be a number, got {value!r}")
    if isinstance(value, float):
        if not math.isfinite(value):
            raise CodecError(f"{what}: value {value} is not a finite number")
        if not value.is_integer():
            raise CodecError(f"{what} is an integer parameter; {value!r} is not a whole number")
        value = int(value)
    if not INT32_MIN <= value <= INT32_MAX:
        raise CodecError(f"{what}: value {value} is outside int32 ({INT32_MIN}..{INT32_MAX})")
    return value


def check_float32(value: object, what: str) -> float:
    """``value`` as a finite float that fits float32 (it is rounded to float32 on the bus)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise CodecError(f"{what}: value must be a number, got {value!r}")
    try:
        as_float = float(value)
        FLOAT32.pack(as_float)
    except OverflowError:
        raise CodecError(f"{what}: value {value!r} is too large for float32") from None
    if not math.isfinite(as_float):
        raise CodecError(f"{what}: value {value} is not a finite number")
    return as_float


def _pack_value(value: int | float | None, is_float: bool, what: str) -> bytes:
    if value is None:
        return bytes(4)
    if is_float:
        return FLOAT32.pack(check_float32(value, what))
    return INT32.pack(check_int32(value, what))


def _header_word(index: int, *, is_float: bool = False, flag6: bool = False) -> int:
    return index | (FLAG_FLOAT if is_float else 0) | (FLAG_QUERY if flag6 else 0)


def _spec_at(letters: str, index: int) -> CommandSpec:
    return lookup(letters).at(index)


# -- host side: encode requests, decode replies ---------------------------------------------------

def encode_set(letters: str, index: int, value: int | float) -> bytes:
    """8-byte set frame; the type bit and the value's type come from the command table."""
    spec = _spec_at(letters, index)
    what = _what(letters, index)
    if spec.access == "ro":
        raise CodecError(f"{what} is read-only and cannot be set")
    if spec.access == "x":
        raise CodecError(f"{letters} is an execute command and takes no value", hint=f"send just {letters}")
    is_float = spec.value_type == "float"
    return FRAME.pack(letters.encode("ascii"), _header_word(index, is_float=is_float),
                      _pack_value(value, is_float, what))


def encode_query(letters: str, index: int = 0, long: bool = False) -> bytes:
    """Query frame: 4 bytes, or 8 bytes with the query bit (and, for a float parameter, the
    float bit: [IG] 9-3 wants the type in every frame) when ``long``."""
    spec = _spec_at(letters, index)
    if spec.access == "x":
        raise CodecError(f"{letters} is an execute command and cannot be queried")
    if long:
        # [IG] 9-3: the type bit is always set to the parameter's type, in queries too
        return FRAME.pack(letters.encode("ascii"),
                          _header_word(index, is_float=spec.value_type == "float", flag6=True), bytes(4))
    return HEADER.pack(letters.encode("ascii"), index)


def encode_execute(letters: str, index: int = 0) -> bytes:
    """4-byte execute frame (BG, ST, SV, ...)."""
    spec = _spec_at(letters, index)
    if spec.access != "x":
        raise CodecError(f"{letters} is not an execute command", hint=f"query it as {letters} or set {letters}=...")
    return HEADER.pack(letters.encode("ascii"), index)


def encode_request(request: Request, long: bool = False) -> bytes:
    """Frame for a :class:`Request` (e.g. from :func:`parse_expr`)."""
    if request.kind == "set":
        return encode_set(request.letters, request.index, request.value)  # type: ignore[arg-type]
    if request.kind == "query":
        return encode_query(request.letters, request.index, long=long)
    return encode_execute(request.letters, request.index)


def _split(data: object, lengths: tuple[int, ...], what: str) -> tuple[str, int, bytes]:
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise CodecError(f"{what} must be bytes, got {type(data).__name__}")
    if type(data) is not bytes:
        data = bytes(data)
    if len(data) not in lengths:
        allowed = " or ".join(str(n) for n in lengths)
        raise CodecError(f"{what} must be {allowed} bytes, got {len(data)}: {data.hex(' ')}")
    raw_letters, word = HEADER.unpack_from(data)
    try:
        letters = raw_letters.decode("ascii")
    except UnicodeDecodeError:
        raise CodecError(f"{what} {data.hex(' ')}: command bytes {raw_letters.hex(' ')} are not ASCII") from None
    try:
        check_letters(letters)
    except CodecError as exc:
        raise CodecError(f"{what} {data.hex(' ')}: {exc.message}") from None
    return letters, word, data[4:]


def _unpack_value(payload: bytes, is_float: bool, letters: str, index: int) -> int | float:
    if not is_float:
        return INT32.unpack(payload)[0]
    value = FLOAT32.unpack(payload)[0]
    if not math.isfinite(value):
        raise CodecError(f"{_what(letters, index)}: float value bytes {payload.hex(' ')} are not a finite number")
    return value


def decode_reply(data: bytes) -> Reply:
    """Decode an 8-byte TPDO2 reply. Letters need not be in the table."""
    letters, word, payload = _split(data, (8,), "reply frame")
    index, is_float = word & INDEX_MASK, bool(word & FLAG_FLOAT)
    if word & FLAG_ERROR:
        # The guide: "byte 4 contains the Elmo error code".
        return Reply(letters, index, None, is_float, error_code=payload[0])
    return Reply(letters, index, _unpack_value(payload, is_float, letters, index), is_float)


# -- drive (simulator) side ----------------------------------------------------------------------

def decode_request(data: bytes) -> Request:
    """Decode a 4- or 8-byte RPDO2 frame.

    Letters must be upper-case ASCII but need not be in the table, so a simulator can answer
    unknown commands and bad indexes with an error reply (EC 2 / EC 3) instead of failing.
    """
    letters, word, payload = _split(data, (4, 8), "request frame")
    index, is_float = word & INDEX_MASK, bool(word & FLAG_FLOAT)
    spec = _known(letters)
    is_execute = spec is not None and spec.access == "x"
    if len(data) == 4 or word & FLAG_QUERY:
        kind: Kind = "execute" if is_execute and not word & FLAG_QUERY else "query"
        return Request(kind, letters, index, None, is_float)
    value = _unpack_value(payload, is_float, letters, index)
    return Request("execute" if is_execute else "set", letters, index, value, is_float)


def _known(letters: str) -> CommandSpec | None:
    try:
        return lookup(letters)
    except CodecError:
        return None


def encode_reply(letters: str, index: int, value: int | float | None, is_float: bool) -> bytes:
    """8-byte success reply; ``value=None`` gives the all-zero data of an execute reply."""
    check_letters(letters)
    _check_raw_index(letters, index)
    return FRAME.pack(letters.encode("ascii"), _header_word(index, is_float=is_float),
                      _pack_value(value, is_float, _what(letters, index)))


def encode_error_reply(letters: str, index: int, code: int) -> bytes:
    """8-byte error reply carrying Elmo error ``code`` (EC numbering, one byte)."""
    check_letters(letters)
    _check_raw_index(letters, index)
    if isinstance(code, bool) or not isinstance(code, int) or not 0 <= code <= 0xFF:
        raise CodecError(f"{_what(letters, index)}: error code must be 0..255, got {code!r}")
    return FRAME.pack(letters.encode("ascii"), _header_word(index, flag6=True), bytes([code, 0, 0, 0]))


def _check_raw_index(letters: str, index: int) -> None:
    if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index <= INDEX_MAX:
        raise CodecError(f"{letters}: index must be 0..{INDEX_MAX} (14 bits), got {index!r}")


# -- technician text ------------------------------------------------------------------------------

_EXPR = re.compile(r"^\s*(?P<letters>[^\[\]=\s]*)\s*(?:\[(?P<index>[^\]]*)\])?\s*(?:=(?P<value>.*))?$",
                   re.DOTALL)
_INT_TEXT = re.compile(r"[+-]?(?:0[xX][0-9a-fA-F]+|[0-9]+)")


def parse_expr(text: str) -> Request:
    """Parse raw command text: ``PX``, ``LL[3]``, ``AC=150000``, ``CL[1]=1.5``, ``BG``."""
    if not isinstance(text, str):
        raise CodecError(f"command text must be a string, got {text!r}")
    m = _EXPR.match(text)
    if m is None or not m.group("letters"):
        raise CodecError(f"cannot parse {text.strip()!r}", hint="write e.g. PX, LL[3], AC=150000 or BG")
    letters, raw_index, raw_value = m.group("letters"), m.group("index"), m.group("value")
    spec = lookup(letters)
    index = _parse_index(spec, raw_index, text)
    spec = spec.at(index)
    what = _what(letters, index)
    if raw_value is None:
        if spec.access == "x":
            return Request("execute", letters, index, None, False)
        return Request("query", letters, index, None, False)
    if spec.access == "x":
        raise CodecError(f"{letters} is an execute command and takes no value", hint=f"write just {letters}")
    if spec.access == "ro":
        raise CodecError(f"{what} is read-only and cannot be set")
    raw_value = raw_value.strip()
    if not raw_value:
        raise CodecError(f"{what}=: value is missing")
    if spec.value_type == "float":
        return Request("set", letters, index, check_float32(_parse_float(raw_value, what), what), True)
    return Request("set", letters, index, check_int32(_parse_int(raw_value, what), what), False)


def _parse_index(spec: CommandSpec, raw_index: str | None, text: str) -> int:
    if raw_index is None:
        if spec.is_array:
            raise CodecError(f"{spec.letters} is an array command and needs an index",
                             hint=f"write e.g. {spec.letters}[{spec.index_min}]")
        return 0
    raw_index = raw_index.strip()
    if not (raw_index.isascii() and raw_index.isdigit()):
        raise CodecError(f"bad index {raw_index!r} in {text.strip()!r}: must be a decimal number")
    if len(raw_index) > 6:  # 14 bits need at most 5 digits; int() refuses thousands of them
        raise CodecError(f"{spec.letters}: bad index {raw_index[:10]}... ({len(raw_index)} digits): "
                         f"out of range 0..{INDEX_MAX}")
    return spec.check_index(int(raw_index))


def _parse_int(raw: str, what: str) -> int | float:
    if len(raw) > 40:  # int32 needs 11 characters; Python refuses int('9' * 5000) with ValueError
        raise CodecError(f"{what}: {raw[:20]}... ({len(raw)} characters) is not an int32 value")
    if _INT_TEXT.fullmatch(raw):
        sign = -1 if raw.startswith("-") else 1
        body = raw.lstrip("+-")
        # Base 10 unless 0x: int(raw, 0) would reject a technician's leading zeros ("007").
        return sign * (int(body, 16) if body[:2].lower() == "0x" else int(body, 10))
    value = _parse_float(raw, what)
    if not value.is_integer():
        raise CodecError(f"{what} is an integer parameter; {raw!r} is not a whole number")
    return value


def _parse_float(raw: str, what: str) -> float:
    if len(raw) > 64:
        raise CodecError(f"{what}: {raw[:20]}... ({len(raw)} characters) is not a float32 value")
    if not raw.isascii():  # float() reads other scripts' digits (U+FF13 -> 3.0)
        raise CodecError(f"{what}: {raw!r} is not a number; write it with the ASCII digits 0-9")
    try:
        value = float(raw)
    except ValueError:
        raise CodecError(f"{what}: {raw!r} is not a number") from None
    if not math.isfinite(value):
        raise CodecError(f"{what}: value {raw!r} is not a finite number")
    return value
