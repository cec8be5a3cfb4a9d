"""Reply rules of the binary interpreter (elmo-protocol.md 1.2-1.4, 2.5): which request gets
which answer and which Elmo error code. The drive supplies state; this module decides.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

from sherpa_cli.elmo.codec import (
    FLAG_ERROR,
    FRAME,
    HEADER,
    INDEX_MASK,
    decode_request,
    encode_error_reply,
    encode_reply,
)
from sherpa_cli.elmo.commands import COMMANDS, CommandSpec
from sherpa_cli.errors import CodecError
from sherpa_cli.sim.params import coerce, in_range, is_float

if TYPE_CHECKING:
    from sherpa_cli.sim.settings import SimSettings


class InterpretedDrive(Protocol):
    """What the interpreter needs of a drive (sim/drive.py's SimDrive is one); a Protocol, so the
    interpreter does not import the drive that imports it."""

    settings: SimSettings
    last_error: int

    @property
    def motor_on(self) -> bool: ...

    def read_param(self, key: str) -> int | float: ...

    def write_param(self, key: str, value: int | float) -> None: ...

    def execute(self, letters: str) -> None: ...

EC_BAD_COMMAND = 2
EC_BAD_INDEX = 3
EC_NOT_IN_THIS_UM = 12  # "command not available in this unit mode" ([BLISS])
EC_SYNTAX = 19  # a query of an execute command (BG with the query bit): nothing to read
EC_OUT_OF_RANGE = 21
EC_CANNOT_ASSIGN = 23  # a set of a read-only command
EC_MOTOR_MUST_BE_OFF = 57
EC_MOTOR_MUST_BE_ON = 58


class Refused(Exception):
    def __init__(self, code: int) -> None:
        super().__init__(code)
        self.code = code


def handle(drive: InterpretedDrive, data: bytes) -> bytes | None:
    """The TPDO2 reply to one RPDO2 frame, or None when the drive stays silent.

    A frame that cannot be decoded (lower-case or non-ASCII letters, a length other than 4 or 8, a
    float that is no number) gets the error reply with ``settings.malformed_command_error``.
    """
    try:
        request = decode_request(data)
    except CodecError:
        return _malformed(drive, data)
    letters, index = request.letters, request.index
    try:
        key, spec = _resolve(drive, letters, index)
        if request.kind == "query":
            if spec.access == "x":
                raise Refused(EC_SYNTAX)
            return encode_reply(letters, index, drive.read_param(key), is_float(spec))
        if request.kind == "execute":
            drive.execute(letters)
            return encode_reply(letters, index, None, False)
        if spec.access == "ro":
            raise Refused(EC_CANNOT_ASSIGN)
        if spec.motor_off and drive.motor_on:
            raise Refused(EC_MOTOR_MUST_BE_OFF)
        assert request.value is not None, "decode_request gives every set frame its value"
        value = coerce(spec, request.value)
        if value is None or not in_range(key, value, drive.settings.max_current):
            raise Refused(EC_OUT_OF_RANGE)
        drive.write_param(key, value)
        if not drive.settings.echo_sets:
            return None
        return encode_reply(letters, index, value, is_float(spec))
    except Refused as refused:
        drive.last_error = refused.code
        return encode_error_reply(letters, index, refused.code)


def _malformed(drive: InterpretedDrive, data: bytes) -> bytes | None:
    """The error reply to a frame the interpreter cannot parse: it repeats the frame's two command bytes
    and index as they came (the host matches replies on them, even lower-case ones), error bit set."""
    if len(data) < HEADER.size:
        return None  # no letters and index to repeat: whatever a real drive does, no reply can match
    code = drive.settings.malformed_command_error
    drive.last_error = code
    letters, word = HEADER.unpack_from(data)
    return FRAME.pack(letters, (word & INDEX_MASK) | FLAG_ERROR, bytes([code, 0, 0, 0]))


_RESOLVED: dict[tuple[str, int], tuple[str, CommandSpec]] = {}  # every frame asks; the table never changes


def _resolve(drive: InterpretedDrive, letters: str, index: int) -> tuple[str, CommandSpec]:
    """The parameter key (``"LL[3]"``) and the spec at that index; raises Refused like the drive."""
    resolved = _RESOLVED.get((letters, index))
    if resolved is None:
        spec = _spec(drive, letters, index)
        resolved = (f"{letters}[{index}]" if spec.is_array else letters, spec.at(index))
        _RESOLVED[(letters, index)] = resolved  # bounded: only table commands at valid indexes get here
    elif letters == "IL" and index > drive.settings.inputs:
        raise Refused(EC_BAD_INDEX)  # the one check that depends on the drive
    return resolved


def _spec(drive: InterpretedDrive, letters: str, index: int) -> CommandSpec:
    spec = COMMANDS.get(letters)
    if spec is None:
        raise Refused(EC_BAD_COMMAND)
    try:
        spec.check_index(index)
    except CodecError:
        raise Refused(EC_BAD_INDEX) from None
    if letters == "IL" and index > drive.settings.inputs:
        raise Refused(EC_BAD_INDEX)
    return spec
