"""`sherpa cmd`: raw two-letter commands to one drive, like the command line of Elmo's tools.

Queries are sent; anything that changes the drive (a set, or an execute command such as
BG, ST, SV) is only shown as the frame it would send unless ``apply`` is true.

``SV`` writes the drive's flash (about 100,000 saves in its life), so it obeys the save rules
here too (:func:`check_raw_save`): only with ``apply`` and the explicit ``raw_save``, at most
one per invocation, sent through the client's save (never resent, the blackout waited out)
and counted in the save ledger under the drive's serial number.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from sherpa_cli.elmo import codec, faults
from sherpa_cli.elmo.commands import param_key
from sherpa_cli.elmo.userprog import refuse_save_while_running
from sherpa_cli.errors import DriveRefusedError, SafetyError, SherpaError, UsageError

if TYPE_CHECKING:
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.bus.targets import DriveRef
    from sherpa_cli.elmo.client import DriveClient
    from sherpa_cli.motion.settings import MotionSettings

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


@dataclass
class RawRun:
    """One `sherpa cmd` run (`Arm.command`): what each expression did, in order, up to the error that
    ended it (``error``; None: all of them ran); ``stopped``: how the guard stopped a motor a
    guarded run started; ``warnings``: the save ledger's."""

    drive: str
    apply: bool
    results: list[RawResult] = field(default_factory=list)
    stopped: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    error: SherpaError | None = None

    @property
    def ok(self) -> bool:
        return self.error is None


def parse_all(exprs: Sequence[str], query_long: bool = False) -> list[tuple[codec.Request, bytes]]:
    """Parse every expression before anything is sent: one bad word means nothing goes out."""
    parsed = []
    for text in exprs:
        request = codec.parse_expr(text)
        parsed.append((request, codec.encode_request(request, long=query_long)))
    return parsed


def save_count(exprs: Sequence[str]) -> int:
    """How many SV the expressions ask for (parsed; bad words raise as in :func:`parse_all`)."""
    return sum(1 for request, _ in parse_all(exprs) if request.kind == "execute" and request.letters == "SV")


def check_raw_save(exprs: Sequence[str], *, apply: bool, raw_save: bool) -> bool:
    """Refuse SV outside the save rules before anything is sent; True when one SV is to be sent.

    Two SV in one invocation are refused (a flash write is never repeated by accident); one SV
    needs ``apply`` and the explicit ``raw_save``. Without ``apply`` it is shown (dry run).
    """
    count = save_count(exprs)
    if count > 1:
        raise UsageError(f"{count} SV in one command: SV writes the drive's flash, at most one per invocation; "
                         "nothing was sent", hint="send one SV, after the values were read back")
    if count and apply and not raw_save:
        raise SafetyError("SV (save to flash) is refused without --raw-save; nothing was sent",
                          hint="add --raw-save to save the drive's RAM to flash (counted in the save ledger), "
                          "or use `sherpa program-limits --apply --save`")
    return bool(count and apply)


def expr_text(request: codec.Request) -> str:
    key = param_key(request.letters, request.index)
    if request.kind == "set":
        return f"{key}={request.value}"
    return key


def decode_value(letters: str, value: int | float | None, il_roles: Mapping[int, str] | None = None) -> list[str]:
    """What a register value means, for the commands that have a decoder (``il_roles``: the config's
    IL codes, joints.limits.il_roles, so IL reads as `limits show` shows it)."""
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
        return [faults.describe_il(value, il_roles)]
    return []


def starts_motion(exprs: Sequence[str]) -> bool:
    """Whether the expressions switch a motor on or begin a motion (MO=1, BG): such a run goes
    inside the motion guard, so no motor is on without an armed dead-man and none outlives it."""
    return any((request.kind == "set" and request.letters == "MO" and request.value == 1)
               or (request.kind == "execute" and request.letters == "BG") for request, _ in parse_all(exprs))


def begins_motion(exprs: Sequence[str]) -> bool:
    """BG among the expressions (a motion, not only a motor switched on to clear a fault)."""
    return any(request.kind == "execute" and request.letters == "BG" for request, _ in parse_all(exprs))


def run_raw(client: DriveClient, node: int, exprs: Sequence[str], *, apply: bool, query_long: bool = False,
            results: list[RawResult] | None = None,
            on_save: Callable[[RawResult], None] | None = None,
            il_roles: Mapping[int, str] | None = None,
            motor_on: Callable[[], None] | None = None) -> list[RawResult]:
    """Run the expressions in order on one drive; stop at the first error (it propagates).

    ``results`` collects what was done before an error, so the caller can still show it.
    SV goes through ``client.save()`` (sent once, blackout waited out); ``on_save(result)`` is
    called once the drive accepted it (the caller counts it in the save ledger). Callers
    check :func:`check_raw_save` first. ``motor_on``: how MO=1 is sent (the motion guard's enable,
    which records the motor as on so that its exit switches it off); default the client's.
    """
    done = results if results is not None else []
    for request, frame in parse_all(exprs, query_long):
        text = expr_text(request)
        result = RawResult(text, request.kind, RPDO2_BASE + node, frame, sent=False)
        if request.kind == "query":
            result.value = client.get(request.letters, request.index)
            result.sent = True
            result.decoded = decode_value(request.letters, result.value, il_roles)
        elif apply:
            if request.kind == "set" and request.letters == "MO" and request.value in (0, 1):
                # the confirmed motor switch: MO=1/0, then MO polled until it reads back (the drive is
                # deaf while it settles, so a PA or BG right after a bare MO=1 would go unanswered)
                (motor_on or client.motor_on)() if request.value == 1 else client.motor_off()
            elif request.kind == "set":
                assert request.value is not None  # a set request carries its value
                client.set(request.letters, request.index, request.value)
            elif request.letters == "SV":
                refuse_save_while_running(client)  # PS: no save while a user program runs
                try:
                    client.save()
                except DriveRefusedError:
                    raise  # the drive answered SV with an error: nothing was saved, nothing to count
                except SherpaError:
                    # no answer after the blackout: the flash may well have been written -- count it
                    if on_save is not None:
                        on_save(result)
                    raise
                if on_save is not None:
                    on_save(result)
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


def run_raw_guarded(session: ArmSession, ref: DriveRef, exprs: Sequence[str], settings: MotionSettings, *,
                    query_long: bool = False, results: list[RawResult] | None = None,
                    on_save: Callable[[RawResult], None] | None = None,
                    il_roles: Mapping[int, str] | None = None, on_exit: list[str] | None = None) -> list[RawResult]:
    """:func:`run_raw` with ``apply`` inside the motion guard, for expressions that switch a motor on or
    begin a motion (:func:`starts_motion`): the dead-man is armed before anything is sent, MO=1 goes
    through the guard's enable (in the drive's present UM) so that the guard's exit stops the motor
    from standstill and switches it off. MO=1 clears a latched MF (Elmo), so a drive in fault is
    refused only when the run also begins a motion (BG). ``on_exit`` collects the guard's line for
    each motor it switched off."""
    from sherpa_cli.motion.guard import MotionGuard

    done = results if results is not None else []
    guard = MotionGuard(session, [ref], settings=settings, clears_fault=not begins_motion(exprs))
    try:
        with guard as g:
            run_raw(g.client(ref), ref.node, exprs, apply=True, query_long=query_long, results=done,
                    on_save=on_save, il_roles=il_roles, motor_on=lambda: g.enable(ref, g.unit_mode(ref)))
            g.check()
    finally:
        if on_exit is not None:
            on_exit.extend(f"{d.line()}: `cmd` keeps no motor on after it ends (its dead-man ends with it); "
                           "`sherpa jog JOINT --hold` holds a joint" for d in guard.report.drives if d.motor_off)
    return done
