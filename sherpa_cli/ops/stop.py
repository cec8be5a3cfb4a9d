"""`sherpa stop`: stop every (or the named) drive now -- ST (JV=0 + BG where ST is refused), wait for
standstill (bounded), MO=0 -- with no confirmation, buses at the same time (docs/motion.md).

It is meant for a second terminal while another command moves the arm: it NMT-starts each drive
first (a drive whose heartbeat consumer tripped sits in NMT Stopped and ignores the interpreter),
and it switches the motor off whoever switched it on. A drive whose motor is already off gets no
write at all.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from sherpa_cli.bus.parallel import run_concurrently
from sherpa_cli.bus.targets import DriveRef
from sherpa_cli.devices.drives import is_elmo, open_drive
from sherpa_cli.elmo.protocol import UM_TORQUE
from sherpa_cli.errors import SafetyError
from sherpa_cli.motion.settings import MotionSettings
from sherpa_cli.motion.stopping import ask_patiently, stop_drive, stop_other, why
from sherpa_cli.words import plural

if TYPE_CHECKING:
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.elmo.client import DriveClient

log = logging.getLogger(__name__)


@dataclass
class StopResult:
    drive: str
    address: str
    stopped_by: str = "-"
    standstill: bool | None = None
    motor_off: bool = False  # MO=0 was sent and confirmed
    problems: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.problems

    @property
    def reached(self) -> bool:
        return self.stopped_by != "not reached"

    def as_json(self) -> dict[str, Any]:
        return {"drive": self.drive, "address": self.address, "stopped_by": self.stopped_by,
                "standstill": self.standstill, "motor_off": self.motor_off, "problems": list(self.problems)}


def stop_one(client: DriveClient, ref: DriveRef, settings: MotionSettings, *, clock: Callable[[], float] = time.monotonic,
             sleep: Callable[[float], None] = time.sleep) -> StopResult:
    """Each step on its own: a failed NMT start, UM read or ST never skips the MO=0 -- only a motor read
    as off gets no MO=0. UM is read patiently (a drive in its MO settle window is deaf); unreadable,
    the drive is treated as in torque mode (TC=0, then ST)."""
    r = StopResult(ref.name, ref.address)
    try:
        client.nmt_start()
    except Exception as exc:  # noqa: BLE001 - reported; a failed NMT start never skips the stop
        r.problems.append(f"NMT start: {why(exc)}")
    try:
        um = int(ask_patiently(client, "UM", clock, sleep, client.settings.mo_confirm_timeout,
                                settings.poll_interval))
    except Exception as exc:  # noqa: BLE001 - logged; an unreadable UM is stopped as in torque mode
        log.warning("%s: UM unreadable (%s); stopping as in torque mode (TC=0, then ST)", ref.name, why(exc))
        um = UM_TORQUE
    motor_read_off = False
    try:
        r.stopped_by, r.standstill, problems = stop_drive(
            client, unit_mode=um, method=settings.stop_method, standstill_timeout=settings.standstill_timeout,
            poll_interval=settings.poll_interval, clock=clock, sleep=sleep,
            standstill_velocity=settings.standstill_velocity)
        r.problems.extend(problems)
        motor_read_off = r.stopped_by == "motor was off"
    except Exception as exc:  # noqa: BLE001 - reported; a failed stop never skips the MO=0
        r.stopped_by = "not stopped"
        r.problems.append(f"stop: {why(exc)}")
    if not motor_read_off:
        try:
            client.motor_off()
            r.motor_off = True
        except Exception as exc:  # noqa: BLE001 - reported in the drive's result
            r.problems.append(f"MO=0: {why(exc)}")
    return r


def stop_other_one(session: ArmSession, ref: DriveRef, settings: MotionSettings, *,
                   clock: Callable[[], float] = time.monotonic,
                   sleep: Callable[[float], None] = time.sleep) -> StopResult:
    """:func:`stop_one` for a drive of another type, through the seam: NMT start, its own stop and
    the standstill rule, then its power stage off; a failed step never skips the switch-off."""
    r = StopResult(ref.name, ref.address)
    try:
        session.client(ref).nmt_start()
    except Exception as exc:  # noqa: BLE001 - reported; a failed NMT start never skips the stop
        r.problems.append(f"NMT start: {why(exc)}")
    motor_read_off = False
    try:
        drive = open_drive(session, ref)
        r.stopped_by, r.standstill, problems = stop_other(
            drive, standstill_timeout=settings.standstill_timeout, poll_interval=settings.poll_interval,
            clock=clock, sleep=sleep, standstill_velocity=settings.standstill_velocity)
        r.problems.extend(problems)
        motor_read_off = r.stopped_by == "motor was off"
    except Exception as exc:  # noqa: BLE001 - reported; a failed stop never skips the switch-off
        r.stopped_by = "not stopped"
        r.problems.append(f"stop: {why(exc)}")
    if not motor_read_off:
        try:
            open_drive(session, ref).disable()
            r.motor_off = True
        except Exception as exc:  # noqa: BLE001 - reported in the drive's result
            r.problems.append(f"switch-off: {why(exc)}")
    return r


def stop_drives(session: ArmSession, refs: Sequence[DriveRef], settings: MotionSettings, *,
                clock: Callable[[], float] = time.monotonic,
                sleep: Callable[[float], None] = time.sleep) -> list[StopResult]:
    """Stop the drives, one bus per thread (drives of one bus one after the other); in ``refs`` order."""
    by_bus: dict[str, list[DriveRef]] = {}
    done: dict[tuple[str, int], StopResult] = {}
    unreachable = getattr(session, "unreachable", {})
    for ref in refs:
        if ref.bus in unreachable:  # best effort: named, never in the way of the other buses
            done[(ref.bus, ref.node)] = StopResult(ref.name, ref.address, stopped_by="not reached",
                                                   problems=[f"not reached: {unreachable[ref.bus]}"])
            continue
        by_bus.setdefault(ref.bus, []).append(ref)

    def one(ref: DriveRef) -> StopResult:
        if is_elmo(session, ref):
            return stop_one(session.client(ref), ref, settings, clock=clock, sleep=sleep)
        return stop_other_one(session, ref, settings, clock=clock, sleep=sleep)

    def job(bus_refs: list[DriveRef]) -> Callable[[], list[StopResult]]:
        return lambda: [one(ref) for ref in bus_refs]

    outcomes = run_concurrently({bus: job(rs) for bus, rs in by_bus.items()})
    for bus, outcome in outcomes.items():
        if outcome.ok:
            for ref, result in zip(by_bus[bus], outcome.value, strict=True):
                done[(ref.bus, ref.node)] = result
        else:
            for ref in by_bus[bus]:
                done[(ref.bus, ref.node)] = StopResult(ref.name, ref.address, problems=[str(outcome.error)])
    return [done[(ref.bus, ref.node)] for ref in refs]


@dataclass
class StopReport:
    """What `sherpa stop` did to each drive, in the order asked; ``problem()`` is "partly stopped"."""

    drives: list[StopResult]

    @property
    def ok(self) -> bool:
        return all(r.ok for r in self.drives)

    @property
    def not_reached(self) -> list[str]:
        return [r.drive for r in self.drives if not r.ok and not r.reached]

    @property
    def unconfirmed(self) -> list[str]:
        return [r.drive for r in self.drives if not r.ok and r.reached]

    def problem(self) -> SafetyError | None:
        """Exit 1 "partly stopped" naming each drive not reached or not confirmed stopped."""
        if self.ok:
            return None
        parts = []
        if self.unconfirmed:
            parts.append(f"{plural(len(self.unconfirmed), 'drive')} not confirmed stopped: {', '.join(self.unconfirmed)}")
        if self.not_reached:
            parts.append(f"{plural(len(self.not_reached), 'drive')} not reached (bus could not be opened): "
                         f"{', '.join(self.not_reached)}")
        stopped = sum(1 for r in self.drives if r.ok)
        return SafetyError(f"partly stopped ({stopped} of {plural(len(self.drives), 'drive')} stopped): " + "; ".join(parts),
                           hint="check them with `sherpa monitor --once`; cut the motor power if they still move")
