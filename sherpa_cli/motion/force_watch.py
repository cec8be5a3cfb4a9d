"""The force limit a guarded move watches: |F| and |T| of the arm's F/T sensor against its limits.

:class:`ForceWatch` reads one sample per :meth:`~ForceWatch.check` through a :class:`WrenchSource`
(devices/ft_sensor.py ``FtReader``) and returns what should stop the move -- never raises it, so
the caller (the motion guard) stops the drives first and reports after:

- :class:`ForceLimitError` (a SafetyError) when |F| > ``force_limit`` or |T| > ``torque_limit``,
  naming the norm, its limit and the axis that carries most of it;
- :class:`SensorStatusError` (a SafetyError) when the sensor's status word is not 0 (it says its
  own readings are not to be trusted);
- :class:`SensorSilentError` (a CommunicationError) when no sample arrived for longer than
  ``silent_s``, or for ``max_misses`` requests in a row (a count: the same on any clock, where each
  unanswered request waits on the bus in wall time): a watch that cannot see is no watch.

A missed sample inside ``silent_s`` is no stop: one late reply on a busy bus must not end a move.
The clock is injected.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Protocol

from sherpa_cli.config.model import DeviceConfig
from sherpa_cli.devices.ft_sensor import Wrench
from sherpa_cli.errors import CommunicationError, SafetyError, SherpaError, UsageError


class WrenchSource(Protocol):
    """One sample, or a CommunicationError when the sensor did not answer in time."""

    def read(self) -> Wrench: ...


class ForceLimitError(SafetyError):
    """|F| or |T| crossed its limit."""

    def __init__(self, message: str, *, axis: str, value: float, limit: float, wrench: Wrench,
                 hint: str = "the arm pressed on something: move it back before the next try") -> None:
        super().__init__(message, hint=hint)
        self.axis, self.value, self.limit, self.wrench = axis, value, limit, wrench

    def before_motion(self) -> ForceLimitError:
        """The same reading found by the guard's first sample, before anything moved: the arm already
        presses on something (after a force-limit stop, typically), and no guarded move can start, not
        even one that would back it out -- so the hint says what can."""
        return ForceLimitError(
            f"{self.message}: no motion starts past the limit; nothing moved", axis=self.axis, value=self.value,
            limit=self.limit, wrench=self.wrench,
            hint="the arm already presses on something (or the sensor's zero is off: `sherpa ft show`); back it "
                 "out with the motor off, by hand, or with the sensor's force_limit raised in the config for that "
                 "one move (--force-limit only tightens it) (docs/motion.md, \"The force limit\")")


class SensorStatusError(SafetyError):
    """The sensor's status word reports a problem."""


class SensorSilentError(CommunicationError):
    """No sample for longer than the watch's bound."""


def _dominant(w: Wrench, names: tuple[str, str, str]) -> tuple[str, float]:
    axes = w.axes()
    name = max(names, key=lambda n: abs(axes[n]))
    return name, axes[name]


def tightened(configured: float | None, requested: float | None, what: str) -> float | None:
    """The limit a command runs with: ``requested`` (a --force-limit) may only tighten the config's."""
    if requested is None:
        return configured
    if not (requested > 0 and math.isfinite(requested)):
        raise UsageError(f"{what} {requested:g}: expected a number > 0")
    return requested if configured is None else min(configured, requested)


class ForceWatch:
    """Checks one sample against the limits; see the module's docstring."""

    def __init__(self, source: WrenchSource, *, force_limit: float | None, torque_limit: float | None,
                 silent_s: float, name: str = "F/T sensor", clock: Callable[[], float] = time.monotonic,
                 max_misses: int | None = None) -> None:
        if force_limit is None and torque_limit is None:
            raise UsageError(f"{name}: a force watch needs a force_limit or a torque_limit")
        self.source, self.force_limit, self.torque_limit = source, force_limit, torque_limit
        self.silent_s, self.name, self.clock = silent_s, name, clock
        self.last_sample_at = clock()  # the bound counts from the start of the watch
        self.last: Wrench | None = None
        self.misses = 0
        self.max_misses = max_misses
        self.misses_in_row = 0

    @classmethod
    def for_device(cls, source: WrenchSource, dev: DeviceConfig, *, silent_s: float,
                   force_limit: float | None = None, torque_limit: float | None = None,
                   clock: Callable[[], float] = time.monotonic, max_misses: int | None = None) -> ForceWatch:
        """A watch with the device's limits, tightened by a command's own (never loosened)."""
        if dev.ft is None:
            raise UsageError(f"{dev.name} is no F/T sensor")
        return cls(source, force_limit=tightened(dev.ft.force_limit, force_limit, "--force-limit"),
                   torque_limit=tightened(dev.ft.torque_limit, torque_limit, "--torque-limit"), silent_s=silent_s,
                   name=f"F/T sensor {dev.name}", clock=clock, max_misses=max_misses)

    def check(self) -> SherpaError | None:
        try:
            w = self.source.read()
        except CommunicationError as exc:
            self.misses += 1
            self.misses_in_row += 1
            silent_for = self.clock() - self.last_sample_at
            too_many = self.max_misses is not None and self.misses_in_row >= self.max_misses
            if silent_for > self.silent_s or too_many:
                return SensorSilentError(f"{self.name} silent for {silent_for * 1000:.0f} ms, {self.misses_in_row} "
                                         f"requests unanswered (bound {self.silent_s * 1000:.0f} ms"
                                         + (f" or {self.max_misses} requests" if self.max_misses else "")
                                         + f"): the force limit cannot be watched; last: {exc.message}",
                                         hint="check the sensor's cable and power before moving with it again")
            return None
        self.last_sample_at = self.clock()
        self.misses_in_row = 0
        self.last = w
        if not w.status.ok:
            return SensorStatusError(f"{self.name} reports status {w.status} in sample {w.sample}: its readings "
                                     "cannot be trusted", hint="see the sensor's system status code table")
        for norm, limit, names, unit, label in ((w.force, self.force_limit, ("Fx", "Fy", "Fz"), "N", "force"),
                                                (w.torque, self.torque_limit, ("Tx", "Ty", "Tz"), "N·m", "torque")):
            if limit is not None and norm > limit:
                axis, value = _dominant(w, names)
                return ForceLimitError(
                    f"{label} limit: {self.name} read |{'F' if unit == 'N' else 'T'}| {norm:.2f} {unit} > "
                    f"{limit:g} {unit} (mostly {axis} {value:+.2f} {unit}) in sample {w.sample}",
                    axis=axis, value=value, limit=limit, wrench=w)
        return None
