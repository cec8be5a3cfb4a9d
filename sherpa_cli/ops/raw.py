"""`sherpa cmd`: raw two-letter commands to one drive, like the command line of Elmo's tools.

Queries are sent; anything that changes the drive (a set, or an execute command such as
BG, ST, SV) is only shown as the frame it would send unless ``apply`` is true.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Sequence

from sherpa_cli.elmo import codec, faults
from sherpa_cli.elmo.commands import param_key
from sherpa_cli.errors import SherpaError

RPDO2_BASE = 0x300


@dataclass
class RawResult:
    text: str  # the expression as normalised, e.g. "LL[3]=-240"
    kind: str  # query / set / execute
    cob_id: int
    frame: bytes
    sent: bool
    value: int | float | None = None
    decoded: list[str] = field(default_factory=list)

    def as_json(self) -> dict[str, Any]:
        return {"command": self.text, "kind": self.kind, "cob_id": f"0x{self.cob_id:03X}",
                "frame": self.frame.hex(" ").upper(), "sent": self.sent, "value": self.value,
                "decoded": self.decoded}


def parse_all(exprs: Sequence[str], query_long: bool = False) -> list[tuple[codec.Request, bytes]]:
    """Parse every expression before anything is sent: one bad word means nothing goes out."""
    parsed = []
    for text in exprs:
        request = codec.parse_expr(text)
        parsed.append((request, codec.encode_request(request, long=query_long)))
    return parsed


def expr_text(request: codec.Request) -> str:
    key = param_key(request.letters, request.index)
    if request.kind == "set":
        return f"{key}={request.value}"
    return key


def decode_value(letters: str, value: int | float | None) -> list[str]:
    """What a register value means, for the commands that have a decoder."""
    if not isinstance(value, int):
        return []
    if letters == "SR":
        return faults.describe_sr(value)
    if letters == "MF":
        return faults.describe_mf(value) or ["no motor failure"]
    if letters == "EC":
        return [faults.ec_text(value)] if value else ["no error"]
    if letters == "IP":
        return faults.describe_ip(value)
    if letters == "IL":
        return [faults.describe_il(value)]
    return []


def run_raw(client: Any, node: int, exprs: Sequence[str], *, apply: bool, query_long: bool = False,
            results: list[RawResult] | None = None) -> list[RawResult]:
    """Run the expressions in order on one drive; stop at the first error (it propagates).

    ``results`` collects what was done before an error, so the caller can still show it.
    """
    done = results if results is not None else []
    for request, frame in parse_all(exprs, query_long):
        text = expr_text(request)
        result = RawResult(text, request.kind, RPDO2_BASE + node, frame, sent=False)
        if request.kind == "query":
            result.value = client.get(request.letters, request.index)
            result.sent = True
            result.decoded = decode_value(request.letters, result.value)
        elif apply:
            if request.kind == "set" and request.letters == "MO" and request.value in (0, 1):
                # the confirmed motor switch: MO=1/0, then MO polled until it reads back (the drive is
                # deaf while it settles, so a PA or BG right after a bare MO=1 would go unanswered)
                client.motor_on() if request.value == 1 else client.motor_off()
            elif request.kind == "set":
                client.set(request.letters, request.index, request.value)
            else:
                client.execute(request.letters, request.index)
            result.sent = True
        done.append(result)
    return done


class RawCommandError(SherpaError):
    """Carries the results done before the failure, so the CLI can show them with the error."""

    def __init__(self, cause: SherpaError, done: list[RawResult]) -> None:
        super().__init__(cause.message, hint=cause.hint)
        self.exit_code = cause.exit_code
        self.cause = cause
        self.done = done
