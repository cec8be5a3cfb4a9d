"""Programming drive parameters: plan, apply, verify, save. Used by `program-limits` and `params restore`.

The engine is the same for any target set:

1. :func:`check_targets` -- every value fits its command (table type and range, writable),
   and nothing switches a protection off unless the caller allows it. Raises before any I/O.
2. :func:`read_plans` -- per drive: NMT start, MO, the present value of every target and of
   the parameters it is ordered against, the serial number (SDO 0x1018:4) when needed. The
   plan says per parameter now / target / changes, and in which order the changes go.
3. :func:`check_apply` -- refuses before any write: unreadable drives, inconsistent results,
   a motor that is on (unless the caller may switch it off).
4. :func:`apply_plans` -- per drive: MO=0 if allowed and needed, then each change written
   and read back at once; the first error or mismatch ends that drive. SV once, only if
   something changed and every write was verified, then every target is read back again.

Drives run in their own worker (bounded), so drives of one bus overlap too: the
one-outstanding-request rule is per drive (elmo-protocol.md 4.2), and the drive client
enforces it. A stop request (Ctrl-C in the caller, or a progress callback raising
KeyboardInterrupt) is honoured between two writes: the drive in hand stops there, is never
saved, and drives not yet started are not touched.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, TypeVar

from sherpa_cli.bus.machine_lock import wire_key
from sherpa_cli.bus.parallel import Outcome, run_concurrently
from sherpa_cli.bus.targets import DriveRef
from sherpa_cli.elmo import codec
from sherpa_cli.elmo.client import SetMismatchError
from sherpa_cli.elmo.commands import COMMANDS, format_value, param_key, parse_param_key
from sherpa_cli.elmo.userprog import refuse_save_while_running
from sherpa_cli.errors import CodecError, ConfigError, DriveRefusedError, Location, SafetyError, SherpaError
from sherpa_cli.motion import calibration
from sherpa_cli.motion.lock import DriveLock
from sherpa_cli.words import plural

if TYPE_CHECKING:
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.elmo.client import DriveClient
    from sherpa_cli.ops.save_ledger import SaveLedger

ParamValue = int | float

R = TypeVar("R")  # one drive's result (DriveOutcome, FlashProof)

MAX_DRIVE_WORKERS = 16  # drives programmed at once; the arm has 14

# Orderings a drive must hold after every single write (LL <= VL < VH <= HL; the speed trip
# strictly outside the speed limit; peak current >= continuous). A write may not break one of
# these that held before it; one already broken on the drive is not made a reason to refuse.
ORDER_RULES: tuple[tuple[str, str, bool], ...] = (  # (low, high, strict)
    ("LL[3]", "VL[3]", False), ("VL[3]", "VH[3]", True), ("VH[3]", "HL[3]", False), ("LL[3]", "HL[3]", True),
    ("LL[2]", "VL[2]", True), ("VL[2]", "VH[2]", True), ("VH[2]", "HL[2]", True), ("LL[2]", "HL[2]", True),
    ("CL[1]", "PL[1]", False),
)
# The mode goes first: what follows may depend on it.
FIRST = ("UM", "PM")

# Event kinds passed to the progress callback.
EV_READ, EV_MOTOR_OFF, EV_WRITTEN, EV_VERIFIED, EV_SAVED = "read", "motor-off", "written", "verified", "saved"


@dataclass(frozen=True)
class Event:
    drive: str
    kind: str  # EV_*
    key: str | None = None
    value: ParamValue | None = None


Progress = Callable[[Event], None]


@dataclass(frozen=True)
class DriveTarget:
    """What one drive should hold, in the order to prefer when writing."""

    drive: str
    bus: str
    node: int
    params: Mapping[str, ParamValue]
    # keys the caller chose not to write, with the reason (shown in the plan)
    skipped: Mapping[str, str] = field(default_factory=lambda: MappingProxyType({}))
    expected_serial: int | None = None  # restore: the serial the values were read from

    def __post_init__(self) -> None:
        object.__setattr__(self, "params", MappingProxyType(dict(self.params)))
        object.__setattr__(self, "skipped", MappingProxyType(dict(self.skipped)))


@dataclass(frozen=True)
class ParamPlan:
    key: str
    now: ParamValue | None
    target: ParamValue  # as the drive will hold it (float32 for float parameters)

    @property
    def changes(self) -> bool:
        return self.now != self.target


@dataclass(frozen=True)
class DrivePlan:
    target: DriveTarget
    params: tuple[ParamPlan, ...] = ()
    motor_on: bool = False
    serial: int | None = None
    write_order: tuple[str, ...] = ()
    problems: tuple[str, ...] = ()  # why this drive must not be written (read failed, bad result)
    error: SherpaError | None = None  # the read error behind problems, if any
    # an earlier --apply without --save wrote this drive (save ledger): --save must SV it even
    # when nothing changes now, or flash keeps the old values
    save_due: bool = False
    elapsed: float = 0.0  # s spent reading; never shown (output must not depend on timing)

    @property
    def drive(self) -> str:
        return self.target.drive

    @property
    def changes(self) -> list[ParamPlan]:
        return [p for p in self.params if p.changes]

    @property
    def ok(self) -> bool:
        return not self.problems

    @property
    def needs_save(self) -> bool:
        return bool(self.changes) or self.save_due


class OutcomeStatus(StrEnum):
    """Outcome states of one drive, in the words the report uses (a str: JSON shows the word)."""

    UNCHANGED = "unchanged"  # nothing to write
    PROGRAMMED = "programmed"  # every change written and verified, not saved
    SAVED = "saved"  # ... and saved to flash, values read back after SV
    FAILED = "failed"  # an error or mismatch stopped it
    INTERRUPTED = "interrupted"  # stopped by Ctrl-C between two writes
    NOT_STARTED = "not started"  # Ctrl-C came before its turn
    SKIPPED = "skipped"  # not written because of a problem found while planning


UNCHANGED, PROGRAMMED, SAVED = OutcomeStatus.UNCHANGED, OutcomeStatus.PROGRAMMED, OutcomeStatus.SAVED
FAILED, INTERRUPTED = OutcomeStatus.FAILED, OutcomeStatus.INTERRUPTED
NOT_STARTED, SKIPPED = OutcomeStatus.NOT_STARTED, OutcomeStatus.SKIPPED


@dataclass
class DriveOutcome:
    drive: str
    bus: str
    node: int
    status: OutcomeStatus = NOT_STARTED
    motor_switched_off: bool = False
    written: list[str] = field(default_factory=list)
    verified: list[str] = field(default_factory=list)
    mismatches: dict[str, ParamValue] = field(default_factory=dict)  # key -> value read back
    saved: bool = False
    # SV went out but the drive's answer after the blackout never came: flash state unknown
    sv_sent: bool = False
    save_count: int | None = None  # saves of this drive by this tool, this one included
    save_warning: str | None = None
    error: str | None = None
    elapsed: float = 0.0  # s; never shown

    @property
    def ok(self) -> bool:
        return self.status in (UNCHANGED, PROGRAMMED, SAVED)

    def param_result(self, key: str) -> str:
        if key in self.mismatches:
            return f"MISMATCH: reads {_fmt(self.mismatches[key])}"
        if key in self.verified:
            return "written, verified"
        if key in self.written:
            return "written, NOT verified"
        return "not written"

    def as_json(self) -> dict[str, Any]:
        return {"status": self.status, "motor_switched_off": self.motor_switched_off,
                "written": list(self.written), "verified": list(self.verified),
                "mismatches": dict(self.mismatches), "saved": self.saved, "save_count": self.save_count,
                "save_warning": self.save_warning, "error": self.error}


@dataclass
class ApplyResult:
    outcomes: list[DriveOutcome]
    interrupted: bool = False

    @property
    def ok(self) -> bool:
        return not self.interrupted and all(o.ok for o in self.outcomes)


_fmt = format_value


# --------------------------------------------------------------------------- checks (no I/O)

def drive_value(key: str, value: ParamValue) -> ParamValue:
    """``value`` as the drive will hold it; CodecError if the command cannot take it."""
    letters, index = parse_param_key(key)
    return codec.decode_request(codec.encode_set(letters, index, value)).value  # type: ignore[return-value]


def check_targets(targets: Sequence[DriveTarget], *, allow_disabled: bool = False,
                  where: Callable[[str], Location | None] | None = None) -> list[str]:
    """Every target must be a writable command with a value it can hold; returns warnings.

    A value that switches a protection off (the table's ``disables_protection``) is an
    error unless ``allow_disabled``, in which case it is a warning. ``where(drive)`` gives
    the location named in errors.
    """
    warnings: list[str] = []
    for t in targets:
        loc = (where(t.drive) if where else None) or Location()
        for key, value in t.params.items():
            try:
                letters, index = parse_param_key(key)
                spec = COMMANDS[letters]
                if spec.access != "rw":
                    raise CodecError(f"{key} is {'read-only' if spec.access == 'ro' else 'an execute command'}")
                held = drive_value(key, value)
            except CodecError as exc:
                raise ConfigError(f"drive {t.drive}: {key}={value!r}: {exc.message}", loc, hint=exc.hint) from None
            if spec.disables_protection(index, held):
                what = spec.at(index).description or key
                text = f"drive {t.drive}: {key}={_fmt(held)} switches a protection off ({what})"
                if not allow_disabled:
                    raise ConfigError(text, loc, hint="the config must not switch a protection off by accident")
                warnings.append(text)
    return warnings


def _holds(lo: ParamValue | None, hi: ParamValue | None, strict: bool) -> bool | None:
    if lo is None or hi is None:
        return None
    return lo < hi if strict else lo <= hi


def _disabled_trip(values: Mapping[str, ParamValue | None], key: str) -> bool:
    # LL/HL = 0 switch a trip off on the drive; an order against a switched-off trip means nothing.
    if key in ("LL[3]", "HL[3]"):
        return values.get("LL[3]") == 0 and values.get("HL[3]") == 0
    if key in ("LL[2]", "HL[2]"):
        return values.get(key) == 0
    return False


def _broken(values: Mapping[str, ParamValue | None],
            keys: Iterable[str] | None = None) -> Iterator[tuple[int, str, str, bool]]:
    """ORDER_RULES broken in ``values`` (position, low, high, strict); only those involving ``keys`` if given."""
    wanted = set(keys) if keys is not None else None
    for i, (lo, hi, strict) in enumerate(ORDER_RULES):
        if wanted is not None and lo not in wanted and hi not in wanted:
            continue
        if _disabled_trip(values, lo) or _disabled_trip(values, hi):
            continue
        if _holds(values.get(lo), values.get(hi), strict) is False:
            yield i, lo, hi, strict


def _broken_rules(values: Mapping[str, ParamValue | None], keys: Iterable[str] | None = None) -> list[str]:
    return [f"{lo} = {_fmt(values[lo])} must be {'<' if strict else '<='} {hi} = {_fmt(values[hi])}"
            for _, lo, hi, strict in _broken(values, keys)]


def related_keys(keys: Iterable[str]) -> list[str]:
    """Parameters the given ones are ordered against (to read them too), not already in ``keys``."""
    keys = list(keys)
    out: list[str] = []
    for lo, hi, _ in ORDER_RULES:
        for a, b in ((lo, hi), (hi, lo)):
            if a in keys and b not in keys and b not in out:
                out.append(b)
    return out


def write_order(now: Mapping[str, ParamValue | None], targets: Mapping[str, ParamValue],
                prefer: Sequence[str] | None = None) -> list[str]:
    """The changed keys in an order that never breaks an ORDER_RULES relation that holds.

    Greedy in ``prefer`` order (default: the targets' order, mode first): take the first key
    whose write keeps every relation that holds. Writing a key to its target never makes
    another key's write impossible when the targets themselves obey the rules, so this finds
    an order whenever one exists. SafetyError if none does.
    """
    state: dict[str, ParamValue | None] = dict(now)
    base = list(prefer if prefer is not None else targets)
    base = [k for k in FIRST if k in base] + [k for k in base if k not in FIRST]
    pending = [k for k in base if k in targets and state.get(k) != targets[k]]
    order: list[str] = []
    while pending:
        for key in pending:
            if set(_broken_ids({**state, key: targets[key]}, key)) <= set(_broken_ids(state, key)):
                break
        else:
            raise SafetyError("no write order keeps the limits consistent at every step: "
                              + "; ".join(_broken_rules({**state, **{k: targets[k] for k in pending}})),
                              hint="check the target values (LL <= VL < VH <= HL, PL[1] >= CL[1])")
        state[key] = targets[key]
        order.append(key)
        pending.remove(key)
    return order


def _broken_ids(values: Mapping[str, ParamValue | None], key: str) -> list[int]:
    """ORDER_RULES (by position) that involve ``key`` and are broken in ``values``."""
    return [i for i, *_ in _broken(values, (key,))]


# --------------------------------------------------------------------------- plan (reads only)

def _client(session: ArmSession, t: DriveTarget) -> DriveClient:
    from sherpa_cli.bus.session import DriveRef

    cfg_drive = session.cfg.drives.get(t.drive)
    return session.client(DriveRef(t.drive, t.bus, t.node, cfg_drive))


def read_serial(session: ArmSession, t: DriveTarget) -> int:
    """0x1018:4 over SDO (the drive's serial number); an SdoError names the drive."""
    from sherpa_cli.bus.session import DriveRef

    data = session.sdo(DriveRef(t.drive, t.bus, t.node, session.cfg.drives.get(t.drive))).upload(
        0x1018, 4, name="serial number")
    return int.from_bytes(data[:4], "little")


def _read_plan(session: ArmSession, t: DriveTarget, need_serial: bool, on_event: Progress | None) -> DrivePlan:
    start = time.perf_counter()
    targets = {k: drive_value(k, v) for k, v in t.params.items()}
    extra = related_keys(targets)
    try:
        client = _client(session, t)
        client.nmt_start()
        motor_on = bool(client.get("MO"))
        now: dict[str, ParamValue | None] = {}
        for key in [*targets, *extra]:
            letters, index = parse_param_key(key)
            try:
                now[key] = client.get(letters, index)
            except SherpaError:
                if key in extra:  # a parameter we only order against may be missing on this firmware
                    now[key] = None
                    continue
                raise
        serial = read_serial(session, t) if need_serial else None
    except SherpaError as exc:
        return DrivePlan(t, problems=(exc.message,), error=exc, elapsed=time.perf_counter() - start)
    if on_event is not None:
        on_event(Event(t.drive, EV_READ))
    params = tuple(ParamPlan(k, now[k], v) for k, v in targets.items())
    problems: list[str] = []
    final = {**now, **targets}
    changed = [p.key for p in params if p.changes]
    # the result must be consistent where we change it (a drive's other oddities are its own)
    problems += [f"result would be inconsistent: {r}" for r in _broken_rules(final, changed)]
    order: list[str] = []
    if not problems:
        try:
            order = write_order(now, targets)
        except SafetyError as exc:
            problems.append(exc.message)
    if t.expected_serial is not None and serial is not None and serial != t.expected_serial:
        problems.append(f"serial number is 0x{serial:08X} but the values are from serial "
                        f"0x{t.expected_serial:08X} (another drive: --other-serial allows it)")
    return DrivePlan(t, params, motor_on, serial, tuple(order), tuple(problems),
                     elapsed=time.perf_counter() - start)


def read_plans(session: ArmSession, targets: Sequence[DriveTarget], *, need_serial: bool = False,
               on_event: Progress | None = None, max_workers: int = MAX_DRIVE_WORKERS) -> list[DrivePlan]:
    """Read every drive's present values (concurrently; nothing is written) and plan the writes."""
    jobs = {t.drive: (lambda t=t: _read_plan(session, t, need_serial, on_event)) for t in targets}
    outcomes = run_concurrently(jobs, max_workers=max(1, max_workers))
    plans = []
    for t in targets:
        o = outcomes[t.drive]
        if o.error is not None:
            if not isinstance(o.error, SherpaError):  # Ctrl-C and bugs end the command
                raise o.error
            plans.append(DrivePlan(t, problems=(o.error.message,), error=o.error))
        else:
            plans.append(o.value)
    return plans


def mark_save_due(plans: Sequence[DrivePlan], ledger: SaveLedger) -> list[DrivePlan]:
    """Plans of drives an earlier --apply without --save left unsaved, marked ``save_due``."""
    from dataclasses import replace

    return [replace(p, save_due=True) if p.ok and p.serial is not None and ledger.unsaved(p.serial) else p
            for p in plans]


# --------------------------------------------------------------------------- apply

def plan_error(plans: Sequence[DrivePlan], *, suffix: str = "", hint: str | None = None) -> SafetyError | None:
    """The error naming the first drive that cannot be written (and how many more), or None."""
    bad = [p for p in plans if p.problems]
    if not bad:
        return None
    first = bad[0]
    more = f" (and {plural(len(bad) - 1, 'more drive')})" if len(bad) > 1 else ""
    err = SafetyError(f"{first.drive}: {first.problems[0]}{more}{suffix}", hint=hint)
    if first.error is not None:
        err.exit_code = first.error.exit_code  # e.g. 3 when a drive did not answer
    return err


def check_apply(plans: Sequence[DrivePlan], *, motor_off: bool) -> None:
    """Refuse before any write if a drive cannot be planned or its motor is on (without motor_off)."""
    err = plan_error(plans, suffix="; nothing was written", hint="fix what the plan shows, then run again")
    if err is not None:
        raise err
    on = [p.drive for p in plans if p.motor_on and p.needs_save]
    if on and not motor_off:
        raise SafetyError(f"motor is on: {', '.join(on)}; limits, UM and IL can only be written with the "
                          f"motor off; nothing was written",
                          hint="stop the motion and switch the motor off, or add --motor-off")


def _apply_drive(session: ArmSession, plan: DrivePlan, *, save: bool, ledger: SaveLedger | None, stop: threading.Event,
                 on_event: Progress | None) -> DriveOutcome:
    t = plan.target
    out = DriveOutcome(t.drive, t.bus, t.node)
    start = time.perf_counter()
    emit = on_event or (lambda event: None)
    targets = {p.key: p.target for p in plan.params}
    try:
        if not (plan.changes or (save and plan.save_due)):
            out.status = UNCHANGED
            return out
        if stop.is_set():
            return out  # NOT_STARTED
        client = _client(session, t)
        out.status = INTERRUPTED  # until it gets further
        if plan.motor_on:
            client.motor_off()
            out.motor_switched_off = True
            emit(Event(t.drive, EV_MOTOR_OFF))
        if save and plan.changes and ledger is not None and plan.serial is not None:
            # before the first write: killed between the writes and the SV, the ledger still says
            # "written, not saved", and the rerun with --save saves although RAM already holds the
            # targets (else: "nothing to change", and the next power-up loses them). SV clears it.
            out.save_warning = ledger.mark_unsaved(plan.serial, t.drive)
        for key in plan.write_order:
            if stop.is_set():
                return out
            letters, index = parse_param_key(key)
            try:
                client.set(letters, index, targets[key])
                mismatch: int | float | None = None
            except SetMismatchError as exc:  # no echo: the set's own read-back found another value
                mismatch = exc.readback
            out.written.append(key)
            emit(Event(t.drive, EV_WRITTEN, key, targets[key]))
            back = client.get(letters, index) if mismatch is None else mismatch
            if back != targets[key]:
                out.mismatches[key] = back
                out.status = FAILED
                out.error = f"{key} was written as {_fmt(targets[key])} but reads back {_fmt(back)}"
                return out
            out.verified.append(key)
            emit(Event(t.drive, EV_VERIFIED, key, back))
        if not save:
            if out.written and ledger is not None and plan.serial is not None:
                out.save_warning = ledger.mark_unsaved(plan.serial, t.drive)
            out.status = PROGRAMMED
            return out
        if stop.is_set():
            return out  # every write verified, but an interrupted run saves nothing more
        refuse_save_while_running(client)  # PS: the drive saves nothing while a user program runs
        mark = calibration.clear_for_save(session.cfg, client)  # the homed mark never goes to flash
        out.sv_sent = True
        try:
            client.save()
        except DriveRefusedError:
            out.sv_sent = False  # the drive answered SV with an error: nothing was saved
            raise
        except SherpaError as exc:
            # SV is never resent; the drive may well have written its flash: count it, say so
            out.error = f"SV was sent but {exc.message}; whether flash holds the new values is unknown"
        else:
            out.saved = True
            calibration.restore_after_save(session.cfg, client, mark)
        if ledger is not None and plan.serial is not None:
            record = ledger.record(plan.serial, t.drive)
            out.save_count, out.save_warning = record.count, record.warning
        if not out.saved:
            out.status = FAILED
            return out
        emit(Event(t.drive, EV_SAVED))
        for key, value in targets.items():
            letters, index = parse_param_key(key)
            back = client.get(letters, index)
            if back != value:
                out.mismatches[key] = back
        if out.mismatches:
            out.status = FAILED
            key = next(iter(out.mismatches))
            out.error = f"after SV {key} reads back {_fmt(out.mismatches[key])}, expected {_fmt(targets[key])}"
            return out
        out.status = SAVED
        return out
    except KeyboardInterrupt:
        stop.set()
        if out.status != FAILED:
            out.status = INTERRUPTED
        return out
    except SherpaError as exc:
        out.status = FAILED
        out.error = exc.message
        return out
    except Exception as exc:  # e.g. can.CanError from an unplugged adapter: keep every drive's report
        import logging

        logging.getLogger(__name__).debug("%s: programming failed", t.drive, exc_info=True)
        out.status = FAILED
        out.error = f"{type(exc).__name__}: {exc}"
        return out
    finally:
        out.elapsed = time.perf_counter() - start


@contextlib.contextmanager
def write_locks(plans: Sequence[DrivePlan], session: ArmSession | None = None) -> Iterator[None]:
    """The drive lock of every planned drive for the writes (motion/lock.py DriveLock): a jog,
    home or another programming command on one of them refuses (exit 5), and the writes here are
    refused while such a command runs -- before anything is sent. Released on every exit path."""
    taken: list[DriveLock] = []
    try:
        for p in plans:
            link = session.links[p.target.bus].config if session is not None and p.target.bus in session.links \
                else None
            lock = DriveLock(DriveRef(p.drive, p.target.bus, p.target.node), purpose="writing parameters to",
                             key=None if link is None else wire_key(link.interface, link.channel))
            lock.acquire()
            taken.append(lock)
        yield
    finally:
        for lock in reversed(taken):
            lock.release()


def apply_plans(session: ArmSession, plans: Sequence[DrivePlan], *, save: bool = False, ledger: SaveLedger | None = None,
                on_event: Progress | None = None, stop: threading.Event | None = None,
                max_workers: int = MAX_DRIVE_WORKERS) -> ApplyResult:
    """Write, verify and (``save``) save every planned drive; call :func:`check_apply` first.

    Never raises for one drive's trouble: each outcome says what happened. Ctrl-C while
    waiting sets ``stop``; the result is then marked interrupted.
    """
    stop = stop or threading.Event()
    jobs = {p.drive: (lambda p=p: _apply_drive(session, p, save=save, ledger=ledger, stop=stop,
                                               on_event=on_event)) for p in plans}
    with write_locks([p for p in plans if p.changes or p.needs_save], session):
        outcomes = run_concurrently(jobs, max_workers=max(1, max_workers), on_interrupt=stop.set)
    result = _in_plan_order(plans, outcomes, lambda t, message: DriveOutcome(t.drive, t.bus, t.node, status=FAILED,
                                                                            error=message))
    return ApplyResult(result, interrupted=stop.is_set())


def _in_plan_order(plans: Sequence[DrivePlan], outcomes: Mapping[str, Outcome[str]],
                   failed: Callable[[DriveTarget, str], R]) -> list[R]:
    """Each drive's result in plan order; a drive's SherpaError becomes ``failed(target, message)``
    (one drive's trouble never hides the others'), anything else is a bug and raised."""
    result: list[R] = []
    for p in plans:
        o = outcomes[p.drive]
        if o.error is not None:
            if not isinstance(o.error, SherpaError):
                raise o.error
            result.append(failed(p.target, o.error.message))
        else:
            result.append(o.value)
    return result


# --------------------------------------------------------------------------- flash proof

# The local save ledger only knows what this tool did from this state directory. Whether a
# drive's flash holds the targets is proven by the drive itself: NMT reset node makes it
# reload RAM from flash (elmo-protocol.md 3.2), so every target read back after the boot-up
# is what its flash holds. A reset is a write (it drops unsaved RAM, zeroes the position
# counter and loses any homing mark), so callers do it only with --apply and with the motor off.

HOLDS = "holds"  # every target reads back from flash
DIFFERS = "differs"  # flash holds other values (``differences``)
PROOF_FAILED = "failed"  # the reset or a read failed: flash state unknown


@dataclass
class FlashProof:
    drive: str
    bus: str
    node: int
    status: str = NOT_STARTED
    differences: dict[str, tuple[ParamValue | None, ParamValue]] = field(default_factory=dict)  # key -> (flash, target)
    checked: int = 0  # targets read back after the reset
    motor_switched_off: bool = False
    error: str | None = None
    exit_code: int | None = None  # of the error behind a failed proof (3: a drive did not answer)

    @property
    def holds(self) -> bool:
        return self.status == HOLDS

    def as_json(self) -> dict[str, Any]:
        return {"status": self.status, "checked": self.checked, "motor_switched_off": self.motor_switched_off,
                "differences": {k: {"flash": f, "target": t} for k, (f, t) in self.differences.items()},
                "error": self.error}


def check_proof(plans: Sequence[DrivePlan], *, motor_off: bool) -> None:
    """Refuse before any reset: a drive that cannot be planned, or a motor that is on (without motor_off)."""
    err = plan_error(plans, suffix="; no drive was reset, nothing was written",
                     hint="fix what the plan shows, then run again")
    if err is not None:
        raise err
    on = [p.drive for p in plans if p.motor_on]
    if on and not motor_off:
        raise SafetyError(f"motor is on: {', '.join(on)}; --verify-flash resets the drive (NMT reset node), which "
                          f"needs the motor off; no drive was reset, nothing was written",
                          hint="stop the motion and switch the motor off, or add --motor-off")


def _prove_drive(session: ArmSession, plan: DrivePlan, *, boot_timeout: float, stop: threading.Event) -> FlashProof:
    t = plan.target
    proof = FlashProof(t.drive, t.bus, t.node)
    if stop.is_set():
        return proof
    targets = {k: drive_value(k, v) for k, v in t.params.items()}
    try:
        client = _client(session, t)
        if plan.motor_on:
            client.motor_off()  # check_proof allowed it (--motor-off)
            proof.motor_switched_off = True
        client.reset_node(boot_timeout)
        for key, target in targets.items():
            letters, index = parse_param_key(key)
            held = client.get(letters, index)
            proof.checked += 1
            if held != target:
                proof.differences[key] = (held, target)
    except KeyboardInterrupt:
        stop.set()
        proof.status, proof.error = PROOF_FAILED, "interrupted"
        return proof
    except SherpaError as exc:
        proof.status, proof.error, proof.exit_code = PROOF_FAILED, exc.message, int(exc.exit_code)
        return proof
    except Exception as exc:  # noqa: BLE001 - e.g. can.CanError: in this drive's proof, every drive keeps its report
        proof.status, proof.error = PROOF_FAILED, f"{type(exc).__name__}: {exc}"
        return proof
    proof.status = DIFFERS if proof.differences else HOLDS
    return proof


def prove_flash(session: ArmSession, plans: Sequence[DrivePlan], *, boot_timeout: float,
                stop: threading.Event | None = None, max_workers: int = MAX_DRIVE_WORKERS) -> list[FlashProof]:
    """Reset every planned drive, wait for its boot-up and read every target back (call check_proof first)."""
    stop = stop or threading.Event()
    jobs = {p.drive: (lambda p=p: _prove_drive(session, p, boot_timeout=boot_timeout, stop=stop)) for p in plans}
    with write_locks(plans, session):  # an NMT reset of a drive another command moves: refused
        outcomes = run_concurrently(jobs, max_workers=max(1, max_workers), on_interrupt=stop.set)
    proofs = _in_plan_order(plans, outcomes, lambda t, message: FlashProof(t.drive, t.bus, t.node,
                                                                           status=PROOF_FAILED, error=message))
    if stop.is_set():
        raise KeyboardInterrupt
    return proofs


def proof_problem(proofs: Sequence[FlashProof], *, after_save: bool = False) -> SherpaError | None:
    """The error to end with when a proof failed or flash differs (exit 1; 3 when a drive did not answer)."""
    failed = [p for p in proofs if p.status == PROOF_FAILED]
    if failed:
        more = f" (and {plural(len(failed) - 1, 'more drive')})" if len(failed) > 1 else ""
        err = SafetyError(f"{failed[0].drive}: flash not proven: {failed[0].error}{more}")
        if failed[0].exit_code is not None:
            err.exit_code = failed[0].exit_code  # type: ignore[assignment]  # an ExitCode's value
        return err
    differs = [p for p in proofs if p.status == DIFFERS]
    if differs:
        names = ", ".join(p.drive for p in differs)
        if after_save:
            return SafetyError(f"flash of {names} still differs from the targets after SV")
        return SafetyError(f"flash of {names} differs from the targets",
                           hint="run with --apply --save --verify-flash to write and save them")
    return None


def exit_problem(result: ApplyResult) -> SherpaError | None:
    """The error the command ends with (exit 1), or None when every drive is fine."""
    bad = [o for o in result.outcomes if o.status == FAILED]
    if bad:
        first = bad[0]
        more = f" ({len(bad)} drives failed)" if len(bad) > 1 else ""
        saved = "SV sent, save not confirmed" if first.sv_sent else "not saved"
        return SafetyError(f"{first.drive}: {first.error}; programming of {first.drive} stopped there, "
                           f"{saved}{more}")
    return None


__all__ = [
    "ApplyResult",
    "DriveOutcome",
    "DrivePlan",
    "DriveTarget",
    "Event",
    "FlashProof",
    "ParamPlan",
    "apply_plans",
    "check_apply",
    "check_proof",
    "check_targets",
    "drive_value",
    "exit_problem",
    "param_key",
    "plan_error",
    "proof_problem",
    "prove_flash",
    "read_plans",
    "related_keys",
    "write_order",
]
