"""`--hold`: after a move the motors stay on, holding, until Ctrl-C or `sherpa stop`.

One hold for every command that offers it (`jog` of a plain joint, a drive, a Σ/Δ joint or a pair
motor; `diffdrive move`), for any number of drives at once:

1. :func:`hold_in_place`: a motion that may still run (velocity, torque) is stopped, every motor
   waits for the one standstill rule (motion/recovery.wait_standstill: a hold never starts from
   motion), then each motor holds where it stands in position mode (PA = PX, BG);
2. :func:`hold_until_released`: the guard's sign of life (the dead-man stays armed), the caller's
   watch (live position, the limit watch) and the motors' state, every poll interval, until Ctrl-C
   (raised: the caller ends normally, :func:`ctrl_c_ends_hold`), every motor switched off from
   elsewhere (`sherpa stop`: a normal end), or a drive fault (an error naming the drive).

The guard's exit then stops, switches off and restores as on every other way out.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Protocol

from sherpa_cli.elmo.faults import decode_sr, describe_mf
from sherpa_cli.elmo.protocol import UM_POSITION
from sherpa_cli.errors import SafetyError
from sherpa_cli.motion import recovery
from sherpa_cli.motion.stopping import send_stop

if TYPE_CHECKING:
    from sherpa_cli.bus.targets import DriveRef
    from sherpa_cli.motion.guard import MotionGuard
    from sherpa_cli.motion.limit_watch import Breach
    from sherpa_cli.motion.report import GuardReport
    from sherpa_cli.motion.settings import MotionSettings

HELD_UNTIL_CTRL_C = "held until Ctrl-C"
HELD_UNTIL_STOPPED = "held until the motor was switched off (sherpa stop)"


def hold_in_place(guard: MotionGuard, refs: Sequence[DriveRef], *, settings: MotionSettings,
                  clock: Callable[[], float], sleep: Callable[[float], None], stop: bool = True) -> dict[str, int]:
    """Stop (``stop``: the stop frames of each motor; False when the caller's stop was sent already),
    wait for standstill, then hold every motor in position mode at PA = PX (BG). Returns the PA of
    each drive."""
    clients = {r.name: guard.client(r) for r in refs}
    if stop:
        problems: list[str] = []
        for r in refs:
            _, found = send_stop(clients[r.name], unit_mode=guard.unit_mode(r), method=settings.stop_method,
                                 pulse=guard.check)
            problems += [f"{clients[r.name].label}: {p}" for p in found]
        if problems:  # a motor that may still run is never held (nor left running)
            raise SafetyError("the stop before the hold did not go cleanly: " + "; ".join(problems),
                              hint="check the drives with `sherpa monitor --once`; `sherpa stop` stops them all")
    recovery.wait_standstill(clients, settings, clock, sleep, guard.check, before="the hold")
    here = {r.name: int(clients[r.name].get("PX")) for r in refs}
    for r in refs:
        guard.enable(r, UM_POSITION)
    for r in refs:
        clients[r.name].set("PA", 0, here[r.name])
    for r in refs:
        clients[r.name].execute("BG")
    return here


def hold_until_released(guard: MotionGuard, refs: Sequence[DriveRef], *, settings: MotionSettings,
                        sleep: Callable[[float], None], watch: Callable[[], bool]) -> str | None:
    """Keep the hold alive: every poll interval the guard's check, then ``watch()`` (the caller reads
    the positions, shows them and runs its limit watch; True when that ended the hold, e.g. a breach
    recovered: None is returned), then every motor's state. Returns :data:`HELD_UNTIL_STOPPED` once
    a motor was switched off from elsewhere with no fault; a fault raises SafetyError naming the
    drive. Ctrl-C (KeyboardInterrupt) is raised to the caller: :func:`ctrl_c_ends_hold`."""
    while True:
        guard.check()
        if watch():
            return None
        off = [r for r in refs if not decode_sr(int(guard.query(r, "SR"))).motor_on]
        if off:
            for r in off:
                mf = int(guard.query(r, "MF"))
                if mf:  # a trip is an error, never a normal end
                    raise SafetyError(f"{guard.client(r).label}: the motor was switched off during the hold: "
                                      + "; ".join(describe_mf(mf)))
            return HELD_UNTIL_STOPPED  # `sherpa stop` (the guard's exit stops a partner still on)
        sleep(settings.poll_interval)


def ctrl_c_ends_hold(report: GuardReport, exc: BaseException) -> None:
    """Ctrl-C is how a hold (or an open-ended velocity jog) is meant to end, but a stop or restore
    that failed is never hidden behind it: raises SafetyError then."""
    if not report.ok:
        problems = [f"{d.drive}: {p}" for d in report.drives for p in d.problems]
        raise SafetyError("the stop after the motion did not go cleanly: " + "; ".join(problems),
                          hint="check the drives with `sherpa monitor --once`; `sherpa stop` stops them all",
                          motion_report=report) from exc


class Held(Protocol):
    """A moving command's result that may end in a hold (ops/joint_jog.py, ops/diffdrive.py)."""
    held_at: dict[str, int] | None
    held_until: str
    breaches: list[Breach]


def ended_hold(result: Held, report: GuardReport, exc: KeyboardInterrupt) -> Mapping[str, int | None]:
    """A Ctrl-C that reached the command: the normal end of its hold (then ``result.held_until`` says
    so, and where the guard's stop found each motor is returned), else raised again (a Ctrl-C during
    the move itself, or after a limit breach, ends the command as interrupted)."""
    if result.held_at is None or result.breaches:
        raise exc
    ctrl_c_ends_hold(report, exc)
    result.held_until = HELD_UNTIL_CTRL_C
    return positions(report)


def positions(report: GuardReport) -> Mapping[str, int | None]:
    """Where the guard's exit found each motor (PX once stopped; None: unreadable)."""
    return {d.drive: d.position for d in report.drives}
