"""`sherpa jog --joystick`: a joystick drives joints through ops/live_jog.LiveJog (docs/jog.md).

The config's ``joystick:`` section maps axes to joints (velocity or torque, a sensitivity, a
deadzone) and two axes to a differential pair: ``mix: xy`` drives motor a with X+Y and motor b
with X-Y (the seed's XY+/XY-), ``mix: sigma_delta`` the Σ joint with X and the Δ joint with Y.

Commands go out ``rate_hz`` times a second **only while the dead-man button is held**; its
release stops every joint at once and nothing more is sent until it is pressed again. Each
velocity/torque command also expires by itself a few periods later (LiveJog's keepalive), so a
joystick reader that hangs or a device that disappears leaves no motor running. The limits are
LiveJog's: speed and current limits, no command further out than the normal range edge, and the
full-range watch.

The event source is injected: :class:`EvdevSource` reads a Linux input device (python-evdev, an
optional import); tests use a scripted source with the same ``read()`` and ``active_keys()``.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from types import ModuleType
from typing import TYPE_CHECKING, Protocol

from sherpa_cli.config.model import ArmConfig, JoystickConfig, JoystickMap
from sherpa_cli.errors import SherpaError, UsageError
from sherpa_cli.joints import diffpair

if TYPE_CHECKING:
    from sherpa_cli.ops.live_jog import LiveJog


@dataclass(frozen=True)
class JoyEvent:
    """An axis moved (value -1..1, normalized from the device's range) or a button changed (1 / 0)."""

    code: str  # evdev name: ABS_X, BTN_TRIGGER
    value: float


SYN_DROPPED = "SYN_DROPPED"  # the event a source reports when the device's buffer overflowed: events were lost


class EventSource(Protocol):
    def read(self) -> Sequence[JoyEvent] | None:
        """Events since the last call, without blocking; None when the device is gone."""

    def active_keys(self) -> set[str]:
        """The names of the buttons the device reports held now (its own state, not the events);
        raises when it cannot be asked."""


class ScriptedSource:
    """Events at given times (s from the first read) on an injected clock: tests and demos.

    ``lost``: (time, code, value) changes of the device's state that no :meth:`read` reports (events
    lost in an overflowing buffer); :meth:`active_keys` still sees them. ``keys_fail_at``: from this
    time on :meth:`active_keys` raises, like a device that cannot be asked."""

    def __init__(self, script: Iterable[tuple[float, str, float]], clock: Callable[[], float], *,
                 lost: Iterable[tuple[float, str, float]] = (), keys_fail_at: float | None = None) -> None:
        self.script = sorted(script, key=lambda e: e[0])
        self.lost = sorted(lost, key=lambda e: e[0])
        self.keys_fail_at = keys_fail_at
        self.clock = clock
        self.t0: float | None = None
        self.i = 0

    def _elapsed(self) -> float:
        now = self.clock()
        if self.t0 is None:
            self.t0 = now
        return now - self.t0

    def read(self) -> Sequence[JoyEvent] | None:
        t = self._elapsed()
        out = []
        while self.i < len(self.script) and self.script[self.i][0] <= t:
            _, code, value = self.script[self.i]
            out.append(JoyEvent(code, value))
            self.i += 1
        return out

    def active_keys(self) -> set[str]:
        t = self._elapsed()
        if self.keys_fail_at is not None and t >= self.keys_fail_at:
            raise OSError("the device cannot be asked (test)")
        held: set[str] = set()
        for _, code, value in sorted([e for e in self.script + self.lost if e[0] <= t], key=lambda e: e[0]):
            if code.startswith(("BTN_", "KEY_")):
                (held.add if value >= 0.5 else held.discard)(code)
        return held


def _evdev() -> ModuleType:
    if not sys.platform.startswith("linux"):
        raise UsageError(f"the joystick needs Linux (evdev); this is {sys.platform}")
    try:
        import evdev
    except ImportError:
        raise UsageError("the joystick needs the python package 'evdev', which is not installed",
                         hint="pip install 'sherpa-cli[joystick]' (or pip install evdev; Linux only)") from None
    return evdev


@dataclass(frozen=True)
class JoystickInfo:
    path: str
    name: str
    axes: tuple[str, ...]
    buttons: tuple[str, ...]


def _names(ecodes: ModuleType, table: dict, code: int) -> str:
    name = table.get(code, str(code))
    return name[0] if isinstance(name, (list, tuple)) else name  # an aliased code: a tuple (evdev >= 1.7)


def _all_names(table: dict, code: int) -> tuple[str, ...]:
    name = table.get(code, str(code))
    return tuple(name) if isinstance(name, (list, tuple)) else (name,)


def list_joysticks() -> list[JoystickInfo]:
    """Input devices with absolute axes (joysticks, gamepads), with their axis and button names."""
    evdev = _evdev()
    out = []
    for path in evdev.list_devices():
        try:
            dev = evdev.InputDevice(path)
        except OSError:
            continue
        caps = dev.capabilities()
        abs_codes = [c[0] if isinstance(c, tuple) else c for c in caps.get(evdev.ecodes.EV_ABS, [])]
        if not abs_codes:
            continue
        keys = caps.get(evdev.ecodes.EV_KEY, [])
        out.append(JoystickInfo(path, dev.name, tuple(_names(evdev.ecodes, evdev.ecodes.ABS, c) for c in abs_codes),
                                tuple("/".join(_all_names(evdev.ecodes.BTN | evdev.ecodes.KEY, c)) for c in keys)))
        dev.close()
    return out


class EvdevSource:
    """A Linux input device through python-evdev, read without blocking; axes normalized to -1..1.

    ``deadman``: the dead-man button's name, checked here (an evdev button name the device has)
    and reported under that name even where evdev knows the code by several (BTN_TRIGGER is also
    BTN_JOYSTICK); ``where`` names the setting in messages."""

    def __init__(self, path: str | None, deadman: str | None = None, *, where: str = "joystick.deadman") -> None:
        evdev = _evdev()
        self.ecodes = evdev.ecodes
        self.keys = self.ecodes.BTN | self.ecodes.KEY
        self.chosen: dict[int, str] = {}  # key code -> the name the config uses for it
        code = None
        if deadman is not None:
            code = self.ecodes.ecodes.get(deadman)
            if not deadman.startswith(("BTN_", "KEY_")) or not isinstance(code, int):
                raise UsageError(f"{where}: '{deadman}' is not an evdev button name",
                                 hint="sherpa jog --list-joysticks shows the buttons of each device")
            self.chosen[code] = deadman
        self.dropping = False  # after SYN_DROPPED, until the next SYN_REPORT
        if path is None:
            found = list_joysticks()
            if not found:
                raise UsageError("no joystick found (no input device with axes under /dev/input)",
                                 hint="plug it in; check permissions (group 'input'); sherpa jog --list-joysticks")
            path = found[0].path
        try:
            self.dev = evdev.InputDevice(path)
        except (OSError, FileNotFoundError) as exc:
            raise UsageError(f"joystick {path}: {exc.strerror or exc}",
                             hint="sherpa jog --list-joysticks shows the devices; check permissions") from None
        self.path = path
        self.ranges = {}
        caps = self.dev.capabilities()
        for c, info in caps.get(self.ecodes.EV_ABS, []):
            self.ranges[c] = (info.min, info.max)
        if code is not None and code not in caps.get(self.ecodes.EV_KEY, []):
            have = ", ".join("/".join(_all_names(self.keys, c)) for c in caps.get(self.ecodes.EV_KEY, [])) or "none"
            self.dev.close()
            raise UsageError(f"{where}: joystick {path} has no button {deadman} (its buttons: {have})",
                             hint="name one of its buttons in the config's joystick.deadman")

    def read(self) -> Sequence[JoyEvent] | None:
        out: list[JoyEvent] = []
        try:
            for ev in self.dev.read():
                if ev.type == self.ecodes.EV_SYN:
                    if ev.code == self.ecodes.SYN_DROPPED:  # the buffer overflowed: events were lost
                        self.dropping = True
                        out.append(JoyEvent(SYN_DROPPED, 1.0))
                    elif ev.code == self.ecodes.SYN_REPORT:
                        self.dropping = False
                    continue
                if self.dropping:  # the rest of a broken report: the loop asks the key state instead
                    continue
                if ev.type == self.ecodes.EV_ABS:
                    lo, hi = self.ranges.get(ev.code, (-1, 1))
                    mid, half = (lo + hi) / 2, max((hi - lo) / 2, 1e-9)
                    out.append(JoyEvent(_names(self.ecodes, self.ecodes.ABS, ev.code),
                                        max(-1.0, min(1.0, (ev.value - mid) / half))))
                elif ev.type == self.ecodes.EV_KEY:
                    name = self.chosen.get(ev.code) or _names(self.ecodes, self.keys, ev.code)
                    out.append(JoyEvent(name, 1.0 if ev.value else 0.0))
        except BlockingIOError:
            pass
        except OSError:
            return None  # unplugged
        return out

    def active_keys(self) -> set[str]:
        """Every name of every key the device reports held (its EVIOCGKEY state); raises OSError when
        the device cannot be asked (the loop counts that as the dead-man released)."""
        return {n for c in self.dev.active_keys() for n in _all_names(self.keys, c)}

    def close(self) -> None:
        self.dev.close()


def deadzone(x: float, dz: float) -> float:
    """0 inside the deadzone, then rescaled so full deflection is still 1."""
    if abs(x) <= dz:
        return 0.0
    return (abs(x) - dz) / (1 - dz) * (1 if x > 0 else -1)


def _clamp1(x: float) -> float:
    return max(-1.0, min(1.0, x))


@dataclass
class JoystickRun:
    """What the loop did: the caller renders it."""

    periods: int = 0
    commands: int = 0  # commands sent while the dead-man was held
    releases: int = 0  # dead-man releases (each stopped everything)
    ended_by: str = ""
    messages: list[str] = field(default_factory=list)  # refusals and limit messages, each once

    def note(self, text: str) -> None:
        if text and text not in self.messages:
            self.messages.append(text)


def joints_of(cfg: ArmConfig, jcfg: JoystickConfig) -> list[str]:
    """The joints a joystick config drives (a pair: both its joints)."""
    out: list[str] = []
    for m in jcfg.axes:
        names = [m.joint] if m.joint is not None else [cfg.pairs[m.pair].sigma, cfg.pairs[m.pair].delta]  # type: ignore[index]
        out += [n for n in names if n not in out]
    return out


def command(live: LiveJog, cfg: ArmConfig, m: JoystickMap, values: dict[str, float], dz: float) -> str:
    """Send one map's command from the axes' present values; returns what LiveJog said."""
    sign = -1.0 if m.invert else 1.0
    if m.joint is not None:
        x = sign * deadzone(values.get(m.axis or "", 0.0), dz)
        axis = live.axes[m.joint]
        if m.mode == "velocity":
            return live.set_velocity(m.joint, round(x * m.sensitivity * (axis.vel_limit or 0)))
        return live.set_torque(m.joint, x * m.sensitivity * (axis.current_limit or 0.0))
    pair = cfg.pairs[m.pair]  # type: ignore[index]
    x = sign * deadzone(values.get(m.x or "", 0.0), dz)
    y = sign * deadzone(values.get(m.y or "", 0.0), dz)
    sigma, delta = live.axes[pair.sigma], live.axes[pair.delta]
    if m.mode == "velocity":
        if m.mix == "xy":  # one motor at v moves Σ and Δ at v each: the slower joint bounds it
            full = min(v for v in (sigma.vel_limit, delta.vel_limit) if v) * m.sensitivity
            va, vb = round(_clamp1(x + y) * full), round(_clamp1(x - y) * full)
        else:
            va, vb = diffpair.motor_velocities(round(x * m.sensitivity * (sigma.vel_limit or 0)),
                                               round(y * m.sensitivity * (delta.vel_limit or 0)))
        if va == 0 and vb == 0:
            live.stop(pair.sigma)
            live.stop(pair.delta)
            return ""
        return live.set_motor_velocities(pair.sigma, {pair.drive_a: va, pair.drive_b: vb})
    full_i = (sigma.current_limit or 0.0) * m.sensitivity
    if m.mix == "xy":
        ia, ib = _clamp1(x + y) * full_i, _clamp1(x - y) * full_i
    else:
        ia, ib = diffpair.motor_currents(x * full_i / 2, y * full_i / 2)  # |I_a|, |I_b| <= full_i
    if ia == 0 and ib == 0:
        live.stop(pair.sigma)
        live.stop(pair.delta)
        return ""
    return live.set_motor_currents(pair.sigma, {pair.drive_a: ia, pair.drive_b: ib})


def _deadman_down(source: EventSource, name: str) -> bool:
    """Whether the device reports the dead-man held now; a query that fails counts as released."""
    try:
        return name in source.active_keys()
    except Exception:  # noqa: BLE001 - fail-safe: whatever the failure, the dead-man counts as released
        return False


def run_joystick(live: LiveJog, cfg: ArmConfig, jcfg: JoystickConfig, source: EventSource, *,
                 clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep,
                 duration: float | None = None, on_status: Callable[[str], None] | None = None) -> JoystickRun:
    """The loop: read events, and at ``rate_hz`` send each map's command while the dead-man is held.
    Ends after ``duration`` s (tests), when the device is gone, or at Ctrl-C (the caller's guard stops)."""
    run = JoystickRun()
    period = 1.0 / jcfg.rate_hz
    values: dict[str, float] = {}
    held = False
    t_end = None if duration is None else clock() + duration
    next_t = clock()

    def deadman(now_held: bool) -> None:
        nonlocal held
        if held and not now_held:
            live.stop_all()  # release: stop at once, before anything else
            run.releases += 1
            if on_status:
                on_status("dead-man released: every joint stopped")
        elif now_held and not held and on_status:
            on_status("dead-man held: moving")
        held = now_held

    while True:
        events = source.read()
        if events is None:
            live.stop_all()
            run.ended_by = "the joystick is gone"
            break
        for ev in events:
            if ev.code == SYN_DROPPED:  # events were lost: the axes read so far are stale
                values.clear()
                deadman(_deadman_down(source, jcfg.deadman))
            elif ev.code == jcfg.deadman:
                deadman(ev.value >= 0.5)
            else:
                values[ev.code] = ev.value
        now = clock()
        if now >= next_t:
            next_t = max(next_t + period, now)
            run.periods += 1
            if held:  # the device's own key state each period: a release event may have been lost (R11)
                deadman(_deadman_down(source, jcfg.deadman))
            if held:
                for m in jcfg.axes:
                    try:
                        said = command(live, cfg, m, values, jcfg.deadzone)
                    except SherpaError as exc:
                        said = f"not sent: {exc}"
                    run.commands += 1
                    if "not sent" in said or "edge" in said:
                        run.note(said)
            live.tick()
            for text in live.messages:
                run.note(text)
        if t_end is not None and clock() >= t_end:
            run.ended_by = "time up"
            break
        sleep(max(0.0, min(period / 4, next_t - clock())))
    return run
