"""`sherpa stop`: stop every (or the named) drive now -- ST (JV=0 + BG where ST is refused), wait for
standstill (bounded), MO=0 -- with no confirmation, buses at the same time (docs/motion.md).

It is meant for a second terminal while another command moves the arm: it NMT-starts each drive
first (a drive whose heartbeat consumer tripped sits in NMT Stopped and ignores the interpreter),
and it switches the motor off whoever switched it on. A drive whose motor is already off gets no
write at all.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

from sherpa_cli.bus.parallel import run_concurrently
from sherpa_cli.errors import SherpaError
from sherpa_cli.ops.motion import MotionSettings, stop_drive
from sherpa_cli.ops.session import DriveRef


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

    def as_json(self) -> dict[str, Any]:
        return {"drive": self.drive, "address": self.address, "stopped_by": self.stopped_by,
                "standstill": self.standstill, "motor_off": self.motor_off, "problems": list(self.problems)}


def stop_one(client: Any, ref: DriveRef, settings: MotionSettings, *, clock: Callable[[], float] = time.monotonic,
             sleep: Callable[[float], None] = time.sleep) -> StopResult:
    r = StopResult(ref.name, ref.address)
    try:
        client.nmt_start()
        um = int(client.get("UM"))
        r.stopped_by, r.standstill, problems = stop_drive(
            client, unit_mode=um, method=settings.stop_method, standstill_timeout=settings.standstill_timeout,
            poll_interval=settings.poll_interval, clock=clock, sleep=sleep)
        r.problems.extend(problems)
        if r.stopped_by != "motor was off":
            client.motor_off()
            r.motor_off = True
    except SherpaError as exc:
        r.problems.append(str(exc))
    return r


def stop_drives(session: Any, refs: Sequence[DriveRef], settings: MotionSettings, *,
                clock: Callable[[], float] = time.monotonic,
                sleep: Callable[[float], None] = time.sleep) -> list[StopResult]:
    """Stop the drives, one bus per thread (drives of one bus one after the other); in ``refs`` order."""
    by_bus: dict[str, list[DriveRef]] = {}
    for ref in refs:
        by_bus.setdefault(ref.bus, []).append(ref)

    def job(bus_refs: list[DriveRef]) -> Callable[[], list[StopResult]]:
        return lambda: [stop_one(session.client(ref), ref, settings, clock=clock, sleep=sleep) for ref in bus_refs]

    outcomes = run_concurrently({bus: job(rs) for bus, rs in by_bus.items()})
    done: dict[tuple[str, int], StopResult] = {}
    for bus, outcome in outcomes.items():
        if outcome.ok:
            for ref, result in zip(by_bus[bus], outcome.value):
                done[(ref.bus, ref.node)] = result
        else:
            for ref in by_bus[bus]:
                done[(ref.bus, ref.node)] = StopResult(ref.name, ref.address, problems=[str(outcome.error)])
    return [done[(ref.bus, ref.node)] for ref in refs]
