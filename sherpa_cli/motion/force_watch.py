"""The force limit a guarded move watches: |F| and |T| of the arm's F/T sensor against its limits.

:class:`ForceWatch` reads one sample per :meth:`~ForceWatch.check` through a :class:`WrenchSource`
(devices/ft_sensor.py ``FtReader``) and returns what should stop the move -- never raises it, so
the caller (the motion guard) stops the drives first and reports after:

- :class:`ForceLimitError` (a SafetyError) when |F| > ``force_limit`` or |T| > ``torque_limit``,
  naming the norm, its limit and the axis that carries most of it, or when an axis of a watched
  quantity reads at the end of the sensor's INT16 range (saturated: its real value is unknown);
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
        """The same reading found by the guard's first sample, before anything moved. A reading past
        the limit does not refuse (ENTRY_MARGIN): only one that cannot be known does (an axis at the
        end of its range), so the hint says what can back the arm out."""
        return ForceLimitError(
            f"{self.message}: no motion starts while the force cannot be known; nothing moved", axis=self.axis,
            value=self.value, limit=self.limit, wrench=self.wrench,
            hint="the arm presses hard on something, or the sensor is overloaded or its zero is off (`sherpa ft "
                 "show`); back it out with the motor off, by hand (docs/motion.md, \"The force limit\")")


class SensorStatusError(SafetyError):
    """The sensor's status word reports a problem."""


class SensorSilentError(CommunicationError):
    """No sample for longer than the watch's bound."""


# A watch that begins past its limit (the arm still pressing where a force stop left it) lets the
# arm move away: it is held to its lowest reading so far plus this share of the limit until it
# reads below the limit. Refusing every motion there would leave the technician no way out but
# editing the config or biasing the sensor under load, which zeroes the contact force.
ENTRY_MARGIN = 0.1


def _dominant(w: Wrench, names: tuple[str, str, str]) -> tuple[str, float]:
    axes = w.axes()
    name = max(names, key=lambda n: abs(axes[n]))
    return name, axes[name]


def check_force_limit(value: float, what: str, quantity: str = "a force in N") -> float:
    """A requested force (or torque) limit: a finite number > 0, else one UsageError naming ``what``."""
    if not (value > 0 and math.isfinite(value)):
        raise UsageError(f"{what} {value:g}: expected {quantity}, > 0")
    return value


def tightened(configured: float | None, requested: float | None, what: str) -> float | None:
    """The limit a command runs with: ``requested`` (a --force-limit, --torque-limit) may only tighten
    the config's."""
    if requested is None:
        return configured
    check_force_limit(requested, what, "a torque in N·m" if "torque" in what else "a force in N")
    return requested if configured is None else min(configured, requested)


class ForceWatch:
    """Checks one sample against the limits; see the module's docstring."""

    def __init__(self, source: WrenchSource, *, force_limit: float | None, torque_limit: float | None,
                 silent_s: float, name: str = "F/T sensor", clock: Callable[[], float] = time.monotonic,
                 max_misses: int | None = None, entry_margin: float = ENTRY_MARGIN) -> None:
        if force_limit is None and torque_limit is None:
            raise UsageError(f"{name}: a force watch needs a force_limit or a torque_limit")
        self.source, self.force_limit, self.torque_limit = source, force_limit, torque_limit
        self.silent_s, self.name, self.clock = silent_s, name, clock
        self.last_sample_at = clock()
        self.last: Wrench | None = None
        self.misses = 0
        self.max_misses = max_misses
        self.misses_in_row = 0
        # when the first unanswered request of the present run of them was sent: silence counts from
        # there, not from the last sample (a command's steps between two checks are no silence)
        self._silent_since: float | None = None
        self.entry_margin = entry_margin
        # quantity ("force"/"torque") -> the lowest norm read since the watch began past its limit
        self._past_at_start: dict[str, float] = {}
        self._started = False

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

    def limit_now(self, label: str, limit: float) -> float:
        """The limit ``label`` ("force"/"torque") is held to now: its configured one, or, while the
        watch began past it and has not yet read below it, the lowest norm read so far plus
        ``entry_margin`` of the limit."""
        low = self._past_at_start.get(label)
        return limit if low is None else low + self.entry_margin * limit

    @property
    def past_at_start(self) -> dict[str, float]:
        """Quantities the watch began past their limit and still reads past it: their lowest norm."""
        return dict(self._past_at_start)

    def _follow(self, label: str, norm: float, limit: float) -> None:
        if not self._started and norm > limit:
            self._past_at_start[label] = norm
        elif label in self._past_at_start:
            if norm <= limit:
                del self._past_at_start[label]  # clear of the contact: the configured limit from now on
            else:
                self._past_at_start[label] = min(self._past_at_start[label], norm)

    def check(self) -> SherpaError | None:
        began = self.clock()
        try:
            w = self.source.read()
        except CommunicationError as exc:
            self.misses += 1
            self.misses_in_row += 1
            if self._silent_since is None:
                self._silent_since = min(began, self.last_sample_at) if not self._started else began
            silent_for = self.clock() - self._silent_since
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
        self._silent_since = None
        self.last = w
        if not w.status.ok:
            return SensorStatusError(f"{self.name} reports status {w.status} in sample {w.sample}: its readings "
                                     "cannot be trusted", hint="see the sensor's system status code table")
        for norm, limit, names, unit, label in ((w.force, self.force_limit, ("Fx", "Fy", "Fz"), "N", "force"),
                                                (w.torque, self.torque_limit, ("Tx", "Ty", "Tz"), "N·m", "torque")):
            full = [n for n in names if n in w.saturated]
            if limit is not None and full:
                # a count at the end of the sensor's range says only "at least this much": the real
                # value may be far past the limit, so the watch cannot tell it is below
                axis = full[0]
                value = w.axes()[axis]
                return ForceLimitError(
                    f"{label} limit: {self.name} reads {axis} at the end of its range ({value:+.2f} {unit}) in "
                    f"sample {w.sample}: the {label} cannot be known, so it is taken as over {limit:g} {unit}",
                    axis=axis, value=value, limit=limit, wrench=w)
            if limit is None:
                continue
            self._follow(label, norm, limit)
            held = self.limit_now(label, limit)
            if norm > held:
                axis, value = _dominant(w, names)
                symbol = "F" if unit == "N" else "T"
                over = f"{limit:g} {unit}" if held == limit else \
                    f"{held:.2f} {unit} (it began past its {limit:g} {unit} limit: lowest reading + {self.entry_margin:.0%})"
                return ForceLimitError(
                    f"{label} limit: {self.name} read |{symbol}| {norm:.2f} {unit} > {over} "
                    f"(mostly {axis} {value:+.2f} {unit}) in sample {w.sample}",
                    axis=axis, value=value, limit=held, wrench=w)
        self._started = True
        return None
