"""The one stop-and-recover path of every mover.

A joint that leaves its full range (motion/limit_watch.py) is handled the same way by `jog`, the
pair jog, the live jog and joystick, `log step` and `diffdrive move`:

1. :func:`stop_now`: the stop frames of every motor of the command at once (motion/stopping.send_stop:
   TC=0 first in torque mode, then by ``motion.stop_method``); nothing queued is sent after this;
2. :func:`wait_standstill`: the one standstill rule (motion/stopping.wait_all_standstill), bounded by
   ``motion.standstill_timeout``; its one outcome on timeout is :class:`StandstillTimeout`;
3. :func:`move_to`: position mode back to the nearest edge of the normal range, equal-duration
   profiles, at ``motion.recovery_speed`` (motion/settings.py), bounded by the one move-time bound
   (motion/axis.move_time_bound).

:func:`recover` runs the three; any failure is a :class:`RecoveryFailed` that says the joint left its
range first and then why the way back failed. ``home`` uses :func:`move_to` for its
own position moves (back-off, return), so every position move of the tool has the same bound.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import TYPE_CHECKING, TypeAlias

from sherpa_cli.drive import Drive, Mode, Ramp
from sherpa_cli.elmo.protocol import UM_TORQUE
from sherpa_cli.errors import SafetyError
from sherpa_cli.motion import limit_watch
from sherpa_cli.motion.axis import Axis, move_time_bound
from sherpa_cli.motion.stopping import send_stop, wait_all_standstill

if TYPE_CHECKING:
    from sherpa_cli.bus.targets import DriveRef
    from sherpa_cli.elmo.client import DriveClient
    from sherpa_cli.motion.guard import MotionGuard
    from sherpa_cli.motion.limit_watch import Breach
    from sherpa_cli.motion.settings import MotionSettings

HINT = "check the joint; `sherpa stop` stops every drive"

# an Elmo drive by its interpreter client (its stop by motion.stop_method, SP alone set), any other
# drive type through the seam (sherpa_cli/drive.py)
Motor: TypeAlias = "DriveClient | Drive"


class StandstillTimeout(SafetyError):
    """The one outcome of a standstill wait that timed out: the next move was not started."""

    def __init__(self, moving: Sequence[str], timeout: float, before: str) -> None:
        super().__init__(f"{', '.join(moving)}: not at standstill {timeout:g} s after the stop; {before} was not "
                         "started", hint=HINT)
        self.moving = tuple(moving)
        self.timeout = timeout
        self.before = before


class RecoveryFailed(SafetyError):
    """A joint left its full range and the way back failed: both said, the breach first."""

    def __init__(self, breaches: Sequence[Breach], cause: SafetyError) -> None:
        left = "; ".join(b.describe() for b in breaches)
        super().__init__(f"{left}; the recovery failed: {cause}", hint=cause.hint or HINT)
        self.breaches = tuple(breaches)
        self.cause = cause


def stop_now(clients: Mapping[str, Motor], mode: str, method: str = "auto") -> None:
    """Stop every motor at once (the stop frames of each, no wait in between); nothing queued is
    sent after this. TC=0 first in torque mode, then by ``method`` (motion.stop_method). A problem
    (ST refused with ``st``) is raised once every motor got its stop."""
    problems = []
    for c in clients.values():
        if isinstance(c, Drive):
            c.stop()
            continue
        _, found = send_stop(c, unit_mode=UM_TORQUE if mode == "torque" else None, method=method)
        problems += [f"{c.label}: {p}" for p in found]
    if problems:
        raise SafetyError("the stop did not go cleanly: " + "; ".join(problems),
                          hint="check the drives with `sherpa monitor --once`; `sherpa stop` stops them all")


def wait_standstill(clients: Mapping[str, Motor], settings: MotionSettings, clock: Callable[[], float],
                    sleep: Callable[[float], None], pulse: Callable[[], None] | None = None, *,
                    before: str = "the next move") -> None:
    """The one standstill rule, bounded; a drive still moving when the time is up raises
    :class:`StandstillTimeout`: ``before`` (a move back, a correction, a hold) is never started
    from motion."""
    moving = wait_all_standstill(clients, standstill_timeout=settings.standstill_timeout,
                                 poll_interval=settings.poll_interval, standstill_velocity=settings.standstill_velocity,
                                 clock=clock, sleep=sleep, pulse=pulse)
    if moving:
        raise StandstillTimeout(moving, settings.standstill_timeout, before)


def move_to(guard: MotionGuard, refs: Mapping[str, DriveRef], clients: Mapping[str, Motor],
            targets: Mapping[str, int], speed: int, settings: MotionSettings, clock: Callable[[], float],
            sleep: Callable[[float], None], what: str) -> None:
    """Position mode (UM=5; the guard cycles MO if the mode changes), every motor of ``targets`` to
    its target with equal-duration profiles at ``speed`` (the longest move's speed; SP set here,
    never what the drive holds; the guard puts SP back), bounded by the one move-time bound."""
    if not targets:
        return
    now = {d: _position(clients[d]) for d in targets}
    longest = max(abs(t - now[d]) for d, t in targets.items())
    duration = longest / speed if longest else 0.0
    for d, t in targets.items():
        guard.enable(refs[d], Mode.POSITION)
        c = clients[d]
        sp = max(1, math.ceil(abs(t - now[d]) / duration)) if duration else speed
        if isinstance(c, Drive):
            ramp = c.ramp()
            c.set_ramp(Ramp(sp, ramp.accel, ramp.decel))
            c.move_to(t)
        else:
            c.set("SP", 0, sp)
            c.set("PA", 0, t)
    for d in targets:
        c = clients[d]
        if isinstance(c, Drive):
            c.begin()
        else:
            c.execute("BG")
    deadline = clock() + move_time_bound(longest, speed)
    while not all(_ended(guard, refs[d], clients[d]) for d in targets):
        guard.check()
        if clock() >= deadline:
            # a motor switched off meanwhile (`sherpa stop` from another terminal: ST, standstill
            # short of the target, MO=0) is the reason, named as such, not the time bound
            guard.check_motors_on([refs[d] for d in targets], what)
            raise SafetyError(f"{what} did not finish in time", hint=HINT)
        sleep(settings.poll_interval)


def _position(c: Motor) -> int:
    return c.position() if isinstance(c, Drive) else int(c.get("PX"))


def _ended(guard: MotionGuard, ref: DriveRef, c: Motor) -> bool:
    # the guard's query: a drive deaf for its MO settle window (`sherpa stop` from elsewhere) is
    # waited for, not taken for a drive that stopped answering
    return c.profile_done() if isinstance(c, Drive) else int(guard.query(ref, "MS")) == 0


def recovery_speed(settings: MotionSettings, axes: Iterable[Axis | None]) -> int:
    """counts/s of the move back: ``motion.recovery_speed`` of the slowest moved joint's limit."""
    return settings.recovery_speed_for(a.vel_limit for a in axes if a is not None)


def recover(guard: MotionGuard, refs: Mapping[str, DriveRef], clients: Mapping[str, Motor],
            watched: Sequence[Axis], breaches: Sequence[Breach], sample: Callable[[], Mapping[str, int]], *,
            settings: MotionSettings, clock: Callable[[], float], sleep: Callable[[float], None],
            speed: int, torque: bool = False, hold: Mapping[str, int] | None = None,
            what: str = "the move back into the normal range") -> dict[str, int]:
    """Breach -> stop -> standstill -> move back (see the module docstring). ``sample`` reads the
    motor positions after the stop; ``hold`` keeps a pair joint that did not breach at a value
    (limit_watch.recovery_targets). Returns the motor targets it moved to. Raises
    :class:`RecoveryFailed` (the breach named first) when any step fails."""
    try:
        stop_now(clients, "torque" if torque else "position", settings.stop_method)
        wait_standstill(clients, settings, clock, sleep, guard.check, before=what)
        back = limit_watch.recovery_targets(watched, sample(), breaches, hold=hold)
        back = {d: t for d, t in back.items() if d in clients}
        move_to(guard, refs, clients, back, speed, settings, clock, sleep, what)
    except SafetyError as exc:
        raise RecoveryFailed(breaches, exc) from exc
    return back
