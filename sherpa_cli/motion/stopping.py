"""The one stop path: stop frames (ST, or JV=0 + BG; TC=0 first in torque mode), the standstill
wait, and the fault check that decides whether a drive may move at all."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Iterable, Mapping
from typing import TYPE_CHECKING

from sherpa_cli.drive import Drive
from sherpa_cli.elmo.protocol import UM_TORQUE
from sherpa_cli.errors import DriveRefusedError, DriveTimeoutError, SherpaError

if TYPE_CHECKING:
    from sherpa_cli.elmo.client import DriveClient

log = logging.getLogger(__name__)


def why(exc: BaseException) -> str:
    """An exception for the report: a SherpaError's own message, any other with its type named."""
    return str(exc) if isinstance(exc, SherpaError) else f"{type(exc).__name__}: {exc}"


def stop_drive(client: DriveClient, *, unit_mode: int | None, method: str = "auto", standstill_timeout: float = 2.0,
               poll_interval: float = 0.01, clock: Callable[[], float] = time.monotonic,
               sleep: Callable[[float], None] = time.sleep,
               pulse: Callable[[], None] | None = None,
               standstill_velocity: int = 0) -> tuple[str, bool | None, list[str]]:
    """Stop one drive's motion: ST (JV=0 + BG where ST is refused), TC=0 first in torque mode; then
    wait for |VX| <= ``standstill_velocity`` (bounded). Returns (how, standstill reached or None if the motor is off, problems).

    ``pulse`` (the motion guard's sign of life) is called before every request, so a hung request
    lets the heartbeat stop within one request's allowance."""
    beat = pulse or (lambda: None)
    # patient: a drive that was just switched on or off is deaf while it settles (protocol.mo_settle)
    if not ask_patiently(client, "MO", clock, sleep, client.settings.mo_confirm_timeout, poll_interval,
                          on_try=beat):
        return "motor was off", None, []
    how, problems = send_stop(client, unit_mode=unit_mode, method=method, pulse=beat)
    standstill = wait_standstill(client, standstill_timeout=standstill_timeout, poll_interval=poll_interval,
                                 clock=clock, sleep=sleep, pulse=beat, standstill_velocity=standstill_velocity)
    if standstill is False:
        problems.append(f"not at standstill {standstill_timeout:g} s after the stop")
    return how, standstill, problems


def send_stop(client: DriveClient, *, unit_mode: int | None, method: str = "auto",
              pulse: Callable[[], None] | None = None) -> tuple[str, list[str]]:
    """The stop frames of one drive, the one stop path of the guard, `sherpa stop` and the jogs: in
    torque mode TC=0 first; then by ``method`` (motion.stop_method): ``st`` ST (a refusal is a
    problem), ``jv0`` JV=0 + BG, ``auto`` ST and JV=0 + BG where the drive refuses ST (speed mode on
    some firmware). Does not wait; returns (how, problems)."""
    beat = pulse or (lambda: None)
    problems: list[str] = []
    how = []
    if unit_mode == UM_TORQUE:
        try:
            beat()
            client.set("TC", 0, 0.0)
            how.append("TC=0")
        except SherpaError as exc:
            problems.append(f"TC=0: {exc}")
    use_jv = method == "jv0"
    if not use_jv:
        try:
            beat()
            client.execute("ST")
            how.append("ST")
        except DriveRefusedError as exc:
            if method == "st" or unit_mode == UM_TORQUE:
                problems.append(f"ST refused: {exc}")
            else:
                log.info("%s: ST refused (%s); stopping with JV=0 + BG", client.label, exc)
                use_jv = True
    if use_jv:
        beat()
        client.set("JV", 0, 0)
        beat()
        client.execute("BG")
        how.append("JV=0 + BG")
    return " + ".join(how) or "-", problems


def stop_other(drive: Drive, *, standstill_timeout: float = 2.0, poll_interval: float = 0.01,
               clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep,
               pulse: Callable[[], None] | None = None,
               standstill_velocity: int = 0) -> tuple[str, bool | None, list[str]]:
    """:func:`stop_drive` for a drive of another type, through the seam (sherpa_cli/drive.py): its
    own stop with its own deceleration, then the same standstill rule and bound."""
    beat = pulse or (lambda: None)
    beat()
    if not drive.status().enabled:
        return "motor was off", None, []
    beat()
    how = drive.stop()
    still = wait_standstill(drive, standstill_timeout=standstill_timeout, poll_interval=poll_interval, clock=clock,
                            sleep=sleep, pulse=beat, standstill_velocity=standstill_velocity)
    return how, still, [f"not at standstill {standstill_timeout:g} s after the stop"] if still is False else []


def standstill(client: DriveClient | Drive, standstill_velocity: int,
               pulse: Callable[[], None] | None = None) -> bool | None:
    """The one standstill rule, one sample: None when the motor is off (no motion left), True when
    |VX| <= ``standstill_velocity``, else False. ``pulse`` before every request. A drive of another
    type (the seam) the same way: its power stage, then its velocity."""
    beat = pulse or (lambda: None)
    beat()
    if isinstance(client, Drive):
        if not client.status().enabled:
            return None
        beat()
        return abs(client.velocity()) <= standstill_velocity
    if not int(client.get("MO")):
        return None
    beat()
    return abs(int(client.get("VX"))) <= standstill_velocity


def wait_standstill(client: DriveClient | Drive, *, standstill_timeout: float = 2.0, poll_interval: float = 0.01,
                    clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep,
                    pulse: Callable[[], None] | None = None, standstill_velocity: int = 0) -> bool | None:
    """After :func:`send_stop`: True once at standstill (:func:`standstill`), None if the motor went
    off meanwhile (a trip: no motion left), False when ``standstill_timeout`` s passed first."""
    deadline = clock() + standstill_timeout
    while True:
        now = standstill(client, standstill_velocity, pulse)
        if now is not False:
            return now
        if clock() >= deadline:
            return False
        sleep(poll_interval)


def wait_all_standstill(clients: Mapping[str, DriveClient | Drive], *, standstill_timeout: float, poll_interval: float,
                        standstill_velocity: int, clock: Callable[[], float] = time.monotonic,
                        sleep: Callable[[float], None] = time.sleep,
                        pulse: Callable[[], None] | None = None) -> list[str]:
    """The one standstill rule for several drives at once, after their stop frames: a drive is at
    standstill when |VX| <= ``standstill_velocity`` or its motor is off; bounded by
    ``standstill_timeout``. Returns the names of the drives NOT at standstill when the time was up
    (empty: all stand still). Callers never start a move (a recovery) while this is not empty."""
    deadline = clock() + standstill_timeout
    moving = dict(clients)
    while True:
        for name, c in list(moving.items()):
            if standstill(c, standstill_velocity, pulse) is not False:
                del moving[name]
        if not moving or clock() >= deadline:
            return sorted(moving)
        sleep(poll_interval)


def recovery_speed(vel_limits: Iterable[int | None], share: float, fallback: int) -> int:
    """The one speed (counts/s) of the move back after a limit breach, for every command:
    ``share`` (motion.recovery_speed) of the slowest speed limit of the joints it moves, or
    ``fallback`` (motion.recovery_fallback_speed) where no joint has one."""
    limits = [abs(v) for v in vel_limits if v]
    return max(1, round((min(limits) * share) if limits else fallback))


def ask_patiently(client: DriveClient, letters: str, clock: Callable[[], float], sleep: Callable[[float], None],
                   patience: float, poll_interval: float, on_try: Callable[[], None] | None = None,
                   index: int = 0) -> int | float:
    """Query until the drive answers or ``patience`` s have passed (then the timeout propagates);
    ``on_try`` is called before every attempt (the motion guard's sign of life, one request at a time)."""
    deadline = clock() + patience
    while True:
        if on_try is not None:
            on_try()
        try:
            return client.get(letters, index)
        except DriveTimeoutError:
            if clock() >= deadline:
                raise
            sleep(poll_interval)
