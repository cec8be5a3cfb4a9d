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
optional import); tests use a scripted source with the same ``read()``.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Iterable, Protocol, Sequence

from sherpa_cli.config.model import ArmConfig, JoystickConfig, JoystickMap
from sherpa_cli.errors import SherpaError, UsageError
from sherpa_cli.joints import diffpair


@dataclass(frozen=True)
class JoyEvent:
    """An axis moved (value -1..1, normalized from the device's range) or a button changed (1 / 0)."""

    code: str  # evdev name: ABS_X, BTN_TRIGGER
    value: float


class EventSource(Protocol):
    def read(self) -> Sequence[JoyEvent] | None:
        """Events since the last call, without blocking; None when the device is gone."""


class ScriptedSource:
    """Events at given times (s from the first read) on an injected clock: tests and demos."""

    def __init__(self, script: Iterable[tuple[float, str, float]], clock: Callable[[], float]) -> None:
        self.script = sorted(script, key=lambda e: e[0])
        self.clock = clock
        self.t0: float | None = None
        self.i = 0

    def read(self) -> Sequence[JoyEvent] | None:
        now = self.clock()
        if self.t0 is None:
            self.t0 = now
        out = []
        while self.i < len(self.script) and self.script[self.i][0] <= now - self.t0:
            _, code, value = self.script[self.i]
            out.append(JoyEvent(code, value))
            self.i += 1
        return out


def _evdev() -> Any:
    if not sys.platform.startswith("linux"):
        raise UsageError(f"the joystick needs Linux (evdev); this is {sys.platform}")
    try:
        import evdev
    except ImportError:
        raise UsageError("the joystick needs the python package 'evdev', which is not installed",
                         hint="pip install evdev (Linux only)") from None
    return evdev


@dataclass(frozen=True)
class JoystickInfo:
    path: str
    name: str
    axes: tuple[str, ...]
    buttons: tuple[str, ...]


def _names(ecodes: Any, table: dict, code: int) -> str:
    name = table.get(code, str(code))
    return name[0] if isinstance(name, list) else name


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
                                tuple(_names(evdev.ecodes, evdev.ecodes.BTN | evdev.ecodes.KEY, c) for c in keys)))
        dev.close()
    return out


class EvdevSource:
    """A Linux input device through python-evdev, read without blocking; axes normalized to -1..1."""

    def __init__(self, path: str | None) -> None:
        evdev = _evdev()
        self.ecodes = evdev.ecodes
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
        for code, info in self.dev.capabilities().get(self.ecodes.EV_ABS, []):
            self.ranges[code] = (info.min, info.max)

    def read(self) -> Sequence[JoyEvent] | None:
        out = []
        try:
            for ev in self.dev.read():
                if ev.type == self.ecodes.EV_ABS:
                    lo, hi = self.ranges.get(ev.code, (-1, 1))
                    mid, half = (lo + hi) / 2, max((hi - lo) / 2, 1e-9)
                    out.append(JoyEvent(_names(self.ecodes, self.ecodes.ABS, ev.code),
                                        max(-1.0, min(1.0, (ev.value - mid) / half))))
                elif ev.type == self.ecodes.EV_KEY:
                    name = _names(self.ecodes, self.ecodes.BTN | self.ecodes.KEY, ev.code)
                    out.append(JoyEvent(name, 1.0 if ev.value else 0.0))
        except BlockingIOError:
            pass
        except OSError:
            return None  # unplugged
        return out

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


def command(live: Any, cfg: ArmConfig, m: JoystickMap, values: dict[str, float], dz: float) -> str:
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


def run_joystick(live: Any, cfg: ArmConfig, jcfg: JoystickConfig, source: EventSource, *,
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
    while True:
        events = source.read()
        if events is None:
            live.stop_all()
            run.ended_by = "the joystick is gone"
            break
        for ev in events:
            if ev.code == jcfg.deadman:
                now_held = ev.value >= 0.5
                if held and not now_held:
                    live.stop_all()  # release: stop at once, before anything else
                    run.releases += 1
                    if on_status:
                        on_status("dead-man released: every joint stopped")
                elif now_held and not held and on_status:
                    on_status("dead-man held: moving")
                held = now_held
            else:
                values[ev.code] = ev.value
        now = clock()
        if now >= next_t:
            next_t = max(next_t + period, now)
            run.periods += 1
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
