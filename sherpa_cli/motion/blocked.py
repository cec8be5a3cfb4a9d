"""Why a commanded motion does not progress: a stall (no progress for ``motion.stall_time``) and
the end or stop switch that blocks it, named by joint and side.

A move blocked by an end switch used to run until its time bound (12.6 s for a pair move) and then
say only that it did not reach its target. The watch loops now end within about ``stall_time`` of
the last progress, and the message names the active switch read from the drive's inputs (IP).

Every mover uses the one watch (:class:`StallWatch`, made by ``MotionSettings.stall_watch`` for a
commanded speed or ``MotionSettings.torque_stall_watch`` for a commanded current) and the one
ending (:func:`blocked_error`, or :func:`blocked_text` where the ending is a note, as in the live jog).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

from sherpa_cli.config.model import ArmConfig, SwitchKind
from sherpa_cli.errors import SafetyError

if TYPE_CHECKING:
    from sherpa_cli.elmo.client import DriveClient

IP_PIN_SHIFT = 16  # IP bits 16.. are the raw input pins (1-based input n at bit 15 + n)


@dataclass
class StallWatch:
    """Fed with motor positions at every sample; :meth:`stalled` once no drive progressed by
    ``min_progress`` counts for ``stall_time`` s. ``stall_time`` 0 turns it off."""

    stall_time: float
    min_progress: int
    _ref: dict[str, int] | None = None
    _since: float = 0.0

    def feed(self, motors: Mapping[str, int], now: float) -> bool:
        """True when the motion counts as blocked at ``now``."""
        if self.stall_time <= 0:
            return False
        if self._ref is None or any(abs(motors[d] - self._ref.get(d, motors[d])) >= self.min_progress
                                    for d in motors):
            self._ref, self._since = dict(motors), now
            return False
        return now - self._since >= self.stall_time

    @property
    def since(self) -> float:
        return self._since


def min_progress_for(speed_counts_per_s: float, stall_time: float) -> int:
    """The progress a motion at this speed surely makes in ``stall_time`` (a tenth of it), at least 2 counts."""
    return max(2, int(abs(speed_counts_per_s) * stall_time * 0.1))


def torque_min_progress(standstill_velocity: float, stall_time: float) -> int:
    """The progress of a torque move (a current, no commanded speed): a motor whose mean speed over
    ``stall_time`` stayed at standstill (``motion.standstill_velocity``) made none, at least 2 counts."""
    return max(2, math.ceil(abs(standstill_velocity) * stall_time))


def active_switches(cfg: ArmConfig, drive: str, client: DriveClient) -> list[str]:
    """The configured end/stop switches of the joints this drive moves whose input is active now,
    as "shoulder_pitch low end switch (input 3)". Empty when none is, or IP cannot be read."""
    try:
        ip = int(client.get("IP"))
    except Exception:  # noqa: BLE001 - naming the switch is a courtesy: the stall is reported anyway
        return []
    found = []
    for joint in cfg.joints.values():
        drives = _joint_drives(cfg, joint.name)
        for sw in joint.switches:
            wired = sw.drives or drives
            if drive not in wired or sw.kind is SwitchKind.HOME:
                continue
            if ip >> (IP_PIN_SHIFT + sw.input - 1) & 1:
                what = f"{sw.side} end switch" if sw.side else "stop switch"
                found.append(f"{joint.name} {what} (input {sw.input})")
    return found


def _joint_drives(cfg: ArmConfig, joint: str) -> tuple[str, ...]:
    j = cfg.joints[joint]
    if j.drive is not None:
        return (j.drive,)
    if j.pair is not None and j.pair in cfg.pairs:
        pair = cfg.pairs[j.pair]
        return (pair.drive_a, pair.drive_b)
    return ()


def blocked_text(cfg: ArmConfig, clients: Mapping[str, DriveClient], drives: Iterable[str], stall_time: float) -> str:
    """The ending of a blocked motion: "blocked: no progress for 1.0 s; <switch> active" (or no switch)."""
    switches = [s for d in drives for s in active_switches(cfg, d, clients[d])]
    unique = list(dict.fromkeys(switches))
    where = f"; {', '.join(unique)} active" if unique else "; no end switch active (a hard stop or a load?)"
    return f"blocked: no progress for {stall_time:g} s{where}"


BLOCKED_HINT = "move the joint away from the switch or the stop, the other way"


def blocked_error(cfg: ArmConfig, clients: Mapping[str, DriveClient], drives: Iterable[str], stall_time: float,
                  *, who: str, at: str = "", hint: str = BLOCKED_HINT) -> SafetyError:
    """The error a blocked motion ends with: "<who>: blocked: ...; <at>" (``at``: where it stopped)."""
    tail = f"; {at}" if at else ""
    return SafetyError(f"{who}: {blocked_text(cfg, clients, drives, stall_time)}{tail}", hint=hint)
