"""`sherpa jog --interactive`: a full-screen terminal view of the joints with keyboard control
(textual). It only renders and maps keys; everything that moves a motor goes through
ops/live_jog.LiveJog (one motion guard, the joint limits and limit watch of `jog`).

No terminal reports key releases, so holding a key is not a dead-man: a press is one step, and a
velocity or torque command stops by itself ``keepalive`` s after the last press (docs/jog.md).
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, ClassVar

from rich.text import Text
from textual.app import App, ComposeResult
from textual.binding import Binding, BindingType
from textual.screen import ModalScreen
from textual.widgets import Input, Static

from sherpa_cli.errors import SherpaError
from sherpa_cli.joints import units
from sherpa_cli.words import plural

if TYPE_CHECKING:
    from sherpa_cli.ops.home import HomePlan, HomeReport
    from sherpa_cli.ops.live_jog import LiveJog

# per mode: the increments a key press can use, in joint units (rad, rad/s, A)
INCREMENTS: dict[str, tuple[float, ...]] = {
    "position": (0.005, 0.01, 0.05, 0.1, 0.25),
    "velocity": (0.01, 0.05, 0.1, 0.25, 0.5),
    "torque": (0.05, 0.1, 0.25, 0.5),
}
DEFAULT_INCREMENT = {"position": 2, "velocity": 2, "torque": 1}  # 0.05 rad, 0.1 rad/s, 0.1 A
UNITS = {"position": "rad", "velocity": "rad/s", "torque": "A"}
TYPED_EXAMPLES = {"position": "0.5, -10deg, 200counts", "velocity": "0.2, 5deg/s, 300counts/s",
                  "torque": "0.5, 0.5A, 800mA"}
BAR = 36
DETAIL_LINES = 7  # the detail panel's border and its six lines
LIST_BAR = 16  # the joint list's bars: one line per joint fits 80 columns
KEY_HELP = ("↑↓ joint  ←→ step/set  t type set point  Enter start  s stop  Space STOP ALL\n"
            "m mode  +/- step size  c calibrate  g get status  d details  q quit")


def bar(counts: int | None, full: tuple[int, int], normal: tuple[int, int], width: int = BAR) -> str:
    """``[··──────●──────··]``: the full range, the normal range as a line, the position as a dot."""
    lo, hi = full
    span = max(hi - lo, 1)

    def col(x: int) -> int:
        return min(width - 1, max(0, round((x - lo) * (width - 1) / span)))

    cells = ["─" if col(normal[0]) <= i <= col(normal[1]) else "·" for i in range(width)]
    if counts is not None:
        cells[col(counts)] = "●" if lo <= counts <= hi else ("◀" if counts < lo else "▶")
    return "[" + "".join(cells) + "]"


KIND_TEXT = {"home_switch": "home switch", "end_switches": "end switches", "pair": "differential pair",
             "abs_encoder": "absolute encoder"}


def plan_lines(plan: HomePlan) -> list[str]:
    """The home plan as `sherpa home` shows it: what moves, which way, how fast, how far at most."""
    out = []
    for u in plan.units:
        out.append(f"{u.name} ({KIND_TEXT.get(u.kind, u.kind)}; drives {', '.join(u.drives)})")
        out += [f"  uses {s}" for s in u.switches]
        if not u.moves:
            out.append("  no motion: reads the encoder and sets PX from it")
        for m in u.moves:
            way = "up" if m.direction > 0 else "down"
            out.append(f"  {m.what}: {m.joint} {way} at {m.speed} counts/s, at most {m.max_distance} counts")
    return out


def report_line(report: HomeReport) -> str:
    """One line per homed unit, as `sherpa home` reports it."""
    parts = []
    for u in report.units:
        sets = ", ".join(f"{j} = {v}" for j, v in u.set_to.items())
        at = ", ".join(f"{j} at {v} counts" for j, v in u.positions.items())
        text = f"{u.name}: homed ({KIND_TEXT.get(u.kind, u.kind)}): set {sets}; now {at}"
        if u.repeat_difference is not None:
            text += f"; repeat difference {u.repeat_difference:+d} counts"
        parts.append(text)
    return " | ".join(parts) or "nothing homed"


class HomeConfirm(ModalScreen[bool]):
    """The calibrate key's question: the home plan, Enter/y homes, Esc/n cancels."""

    DEFAULT_CSS = """
    HomeConfirm { align: center middle; }
    #plan { width: auto; max-width: 100%; height: auto; padding: 1 2; border: thick $warning; background: $surface; }
    """
    BINDINGS: ClassVar[list[BindingType]] = [
        Binding("enter,y", "answer(True)", "home now"),
        Binding("escape,n", "answer(False)", "cancel"),
    ]

    def __init__(self, joint: str, lines: Sequence[str]) -> None:
        super().__init__()
        self.joint = joint
        self.lines = list(lines)

    def compose(self) -> ComposeResult:
        text = Text(f"calibrate {self.joint}: home it now?\n", style="bold")
        text.append("\n".join(self.lines) + "\n\n")
        text.append("Enter/y: home now   Esc/n: cancel   (Space aborts a running homing)", style="bold")
        yield Static(text, id="plan")

    def action_answer(self, yes: bool) -> None:
        self.dismiss(yes)


class SetPointDialog(ModalScreen[str | None]):
    """The typed set point of the selected joint in its mode's joint unit: Enter takes it, Esc cancels."""

    DEFAULT_CSS = """
    SetPointDialog { align: center middle; }
    #box { width: 70; height: auto; padding: 1 2; border: thick $accent; background: $surface; }
    #error { color: $error; height: auto; }
    """
    BINDINGS: ClassVar[list[BindingType]] = [Binding("escape", "cancel", "cancel")]

    def __init__(self, joint: str, mode: str, check: Callable[[str], str | None]) -> None:
        super().__init__()
        self.joint, self.mode, self.check = joint, mode, check

    def compose(self) -> ComposeResult:
        from textual.containers import Vertical

        with Vertical(id="box"):
            yield Static(Text(f"{self.joint}: {self.mode} set point in {UNITS[self.mode]} "
                              f"(e.g. {TYPED_EXAMPLES[self.mode]})", style="bold"))
            yield Input(placeholder=TYPED_EXAMPLES[self.mode].split(",")[0], id="value")
            yield Static("", id="error")
            yield Static("Enter: set it (Enter again in the view starts)   Esc: cancel")

    def on_mount(self) -> None:
        self.query_one(Input).focus()

    def on_input_submitted(self, event: Input.Submitted) -> None:
        problem = self.check(event.value)
        if problem:
            self.query_one("#error", Static).update(problem)
            return
        self.dismiss(event.value)

    def action_cancel(self) -> None:
        self.dismiss(None)


class JogView(App):
    """The seed's test GUI (Appendix E) in the terminal; ``live`` is an entered LiveJog.

    One line per joint (position, a bar between its limits, mode, what runs) in a list that always
    shows the selected joint, and the selected joint's panel: position in rad/deg/counts, the step
    size and set point in joint units (the set point shown is what was sent), Get Status (OK/Fail,
    decoded SR/MF on request), the last note. The key help is always on screen (80x24 and up).
    ``calibrate``: the ``c`` key homes the selected joint (ops/live_jog.LiveJog.calibrate, in a
    worker thread so Space can abort it)."""

    CSS = """
    #list { height: 1fr; padding: 0 1; }
    #detail { height: auto; padding: 0 1; border-top: solid $primary; }
    #status { height: auto; padding: 0 1; background: $boost; }
    #keys { height: auto; padding: 0 1; color: $text-muted; }
    """
    BINDINGS: ClassVar[list[BindingType]] = [
        Binding("up", "select(-1)", "joint up", show=False),
        Binding("down", "select(1)", "joint down", show=False),
        Binding("left", "step(-1)", "step -", show=False),
        Binding("right", "step(1)", "step +", show=False),
        Binding("m", "mode", "mode", show=False),
        Binding("plus,equals_sign,right_square_bracket", "increment(1)", "inc +", show=False),
        Binding("minus,left_square_bracket", "increment(-1)", "inc -", show=False),
        Binding("t", "type", "type set point", show=False),
        Binding("enter", "start", "start", show=False),
        Binding("s", "stop", "stop", show=False),
        Binding("space", "stop_all", "STOP ALL", priority=True, show=False),
        Binding("c", "calibrate", "calibrate", show=False),
        Binding("g", "status", "get status", show=False),
        Binding("d", "details", "details", show=False),
        Binding("q", "quit", "quit", show=False),
        Binding("ctrl+c", "quit", "quit", show=False, priority=True),
    ]

    def __init__(self, live: LiveJog, *, calibrate: bool = True, tick_period: float = 0.1) -> None:
        super().__init__()
        self.live = live
        self.calibrate = calibrate
        self.homing: threading.Thread | None = None  # the calibrate key's homing, while it runs
        self.homing_joint = ""
        self.homing_result: HomeReport | BaseException | None = None  # a HomeReport or the exception homing raised
        self.abort_homing = threading.Event()
        self.quit_after_homing = False
        self.home_log: list[str] = []  # what homing did: the release's stops, the report line
        self.tick_period = tick_period
        self.names = list(live.axes)
        self.selected = 0
        self.inc_index = {name: dict(DEFAULT_INCREMENT) for name in self.names}
        self.setpoint = {name: 0.0 for name in self.names}  # velocity (rad/s) or torque (A) now sent
        self.typed: dict[str, dict[str, float]] = {name: {} for name in self.names}  # mode -> rad, rad/s, A
        self.status: dict[str, list[Any]] = {}  # the last Get Status per joint (LiveJog.status)
        self.show_details = False
        self.message = ""
        self.seen_messages = len(live.messages)  # the session's messages already shown once
        self.error: BaseException | None = None

    # -- layout ---------------------------------------------------------------------------------

    def compose(self) -> ComposeResult:
        yield Static(id="list")
        yield Static(id="detail")
        yield Static(id="status")
        yield Static(Text(KEY_HELP), id="keys")

    def on_mount(self) -> None:
        self.title = "sherpa jog --interactive"
        self._fit_layout()
        self.tick()  # a sign of life for the guard's dead-man as soon as the view is up
        self.set_interval(self.tick_period, self.tick)

    def on_resize(self) -> None:
        self._fit_layout()
        self.call_after_refresh(self.render_state)

    def _fit_layout(self) -> None:
        """Every joint listed once the terminal has the lines for it (and the detail its own): then
        the list takes no more lines than it has joints and the detail the rest, where SR/MF show
        decoded without the d key. A short terminal scrolls the list instead."""
        listing = self.query_one("#list", Static)
        detail = self.query_one("#detail", Static)
        spare = self.size.height - len(self.names) - DETAIL_LINES - 4  # the status and key lines: 2 each
        if spare >= 0:
            listing.styles.height = len(self.names)
            detail.styles.height = "1fr"
        else:
            listing.styles.height = "1fr"
            detail.styles.height = "auto"

    @property
    def current(self) -> str:
        return self.names[self.selected]

    def increment(self, name: str) -> float:
        """The selected mode's step size in joint units (rad, rad/s, A)."""
        mode = self.live.state[name].mode
        return INCREMENTS[mode][self.inc_index[name][mode]]

    def _cpr(self, name: str) -> int:
        return self.live.axes[name].joint_cpr

    def increment_counts(self, name: str) -> int:
        """The position step in counts: at least one."""
        return max(1, abs(units.rad_to_counts(self.increment(name), self._cpr(name))))

    def sent(self, name: str) -> tuple[float, str] | None:
        """What runs for the joint now, from what was sent to its motors: the joint value in its
        unit (a Σ joint's speed is the motors' sum, Δ's their difference) and the motor commands."""
        run = self.live.running.get(name)
        if run is None:
            return None
        axis = self.live.axes[name]
        motors = {d: v for d, v in run.motors.items() if d != "target"}
        if run.mode == "position":
            goal = int(run.motors.get("target", 0))
            return units.counts_to_rad(goal, axis.joint_cpr), ", ".join(f"{d} PA={int(v)}" for d, v in motors.items())
        letters = "TC" if run.mode == "torque" else "JV"
        text = ", ".join(f"{d} {letters}={v:g}" if isinstance(v, float) else f"{d} {letters}={v}"
                         for d, v in motors.items())
        vals = [motors[d] for d in axis.drives if d in motors]
        if run.mode == "torque":
            # the joint's current from its motors' (the inverse of the transpose the set point went
            # through): a Σ joint's is their mean, IΣ = (Ia + Ib) / 2, not their sum
            return axis.current({d: float(v) for d, v in motors.items()}), text
        cps = vals[0] if axis.kind == "plain" else (vals[0] + vals[1] if axis.kind == "sigma" else vals[0] - vals[1])
        return units.counts_per_s_to_rad_per_s(cps, axis.joint_cpr), text

    def _note(self, name: str) -> str:
        """The joint's last note, unless it no longer holds (a calibration refusal once calibrated)."""
        st = self.live.state[name]
        if st.calibrated and "calibrated joint" in st.note:
            return ""
        return st.note

    def _list_rows(self) -> int:
        try:
            height = self.screen_stack[0].query_one("#list", Static).size.height
        except Exception:  # noqa: BLE001 - not laid out yet: every joint
            return len(self.names)
        return height or len(self.names)

    def _row(self, i: int, name: str, width: int) -> Text:
        st = self.live.state[name]
        j = self.live.axes[name].joint_config
        flag = "!" if st.faults else ("?" if not st.calibrated else " ")
        text = Text()
        text.append("▶ " if i == self.selected else "  ", style="bold")
        text.append(f"{name:<{width}}", style="bold reverse" if i == self.selected else "")
        text.append(f" {flag}", style="bold red" if flag == "!" else "yellow")
        text.append(f" {st.rad:+8.4f} rad " if st.rad is not None else "        ? rad ")
        text.append(bar(st.counts, j.full_range, j.normal_range, self._bar_width()))
        text.append(f" {st.mode:<8} {st.command}")
        room = self.size.width - 2  # the list's padding; one line per joint, what does not fit is cut
        if room > 20:
            text.truncate(room, overflow="ellipsis")
        return text

    def _bar_width(self) -> int:
        """The list's bars: LIST_BAR fits 80 columns; a wider terminal gives half its extra columns
        to them (finer positions), the rest to the command column."""
        return LIST_BAR + max(0, (self.size.width - 80) // 2)

    def _room_for_details(self) -> bool:
        """The detail panel is tall enough to show SR/MF decoded without the d key."""
        try:
            return self.screen_stack[0].query_one("#detail", Static).size.height >= 10
        except Exception:  # noqa: BLE001 - not laid out yet
            return False

    def render_state(self) -> None:
        base = self.screen_stack[0]  # the joints' screen, also under a dialog
        rows = max(1, self._list_rows())
        width = min(22, max(len(n) for n in self.names))
        n = len(self.names)
        shown = rows if n <= rows else max(1, rows - 1)  # one line says what is above / below
        first = min(max(0, self.selected - shown // 2), max(0, n - shown))
        listing = Text()
        for i in range(first, min(n, first + shown)):
            if i > first:
                listing.append("\n")
            listing.append_text(self._row(i, self.names[i], width))
        if n > shown:
            listing.append(f"\n  ↑ {first} above, ↓ {n - first - shown} below (↑/↓ select)", style="dim")
        base.query_one("#list", Static).update(listing)
        base.query_one("#detail", Static).update(self._detail())
        status = Text()
        if self.homing is not None:
            what = "aborting homing" if self.abort_homing.is_set() else "homing"
            status.append(f"{what} {self.homing_joint} ... (Space aborts)\n", style="bold yellow")
        status.append((self.message or "ready") + "\n", style="bold")
        s = self.live.settings
        status.append(f"dead-man: heartbeat {s.heartbeat_period * 1000:.0f} ms; velocity/torque stop "
                      f"{self.live.keepalive:g} s after the last key", style="dim")
        base.query_one("#status", Static).update(status)

    def _detail(self) -> Text:
        name = self.current
        st = self.live.state[name]
        axis = self.live.axes[name]
        cpr, j = axis.joint_cpr, axis.joint_config
        text = Text()
        text.append(f"{name}", style="bold")
        text.append(f" ({', '.join(axis.drives)}) ")
        text.append("calibrated" if st.calibrated else f"NOT calibrated: {st.calibration.split(' (')[0]}",
                    style="green" if st.calibrated else "yellow")
        text.append("  faults: " + ("; ".join(st.faults) if st.faults else "none"),
                    style="bold red" if st.faults else "")
        if st.counts is not None:
            text.append(f"\nposition {units.counts_to_rad(st.counts, cpr):+.4f} rad "
                        f"({units.counts_to_deg(st.counts, cpr):+.2f}°, {st.counts} counts)")
        lo, hi = j.normal_range
        text.append(f"  normal [{units.counts_to_rad(lo, cpr):+.3f}, {units.counts_to_rad(hi, cpr):+.3f}] rad")
        unit = UNITS[st.mode]
        step = f"step {self.increment(name):g} {unit}"
        if st.mode == "position":
            step += f" ({self.increment_counts(name)} counts)"
        typed = self.typed[name].get(st.mode)
        text.append(f"\nmode {st.mode}  {step}  set point ")
        text.append("-" if typed is None else f"{typed:+.4g} {unit}", style="bold")
        text.append(" (t: type, Enter: start)")
        now = self.sent(name)
        text.append("\nrunning: ")
        if now is None:
            text.append("nothing")
        else:
            text.append(f"{now[0]:+.4g} {unit}", style="bold")
            text.append(f" = {now[1]}")
        got = self.status.get(name)
        text.append("\nstatus: ")
        if got is None:
            text.append("g: get status")
        else:
            ok = all(d.ok for d in got)
            text.append("OK" if ok else "Fail", style="bold green" if ok else "bold red")
            if not ok:
                text.append(": " + "; ".join(f"{d.drive}: {', '.join(d.problems)}" for d in got if not d.ok))
            shown = self.show_details or self._room_for_details()
            if not self._room_for_details():
                text.append("  (d: hide details)" if self.show_details else "  (d: details)")
            if shown:
                for d in got:
                    text.append(f"\n  {d.drive}: SR 0x{d.sr & 0xFFFFFFFF:08X}, MF 0x{d.mf & 0xFFFFFFFF:08X}: "
                                + "; ".join(d.details))
        note = self._note(name)
        if note:
            text.append(f"\n{note}", style="yellow")
        return text

    # -- periodic -------------------------------------------------------------------------------

    def tick(self) -> None:
        if self.homing is not None:
            if self.homing.is_alive():  # the worker owns the bus; its waits keep the guard alive
                self.render_state()
                return
            self._homing_done()
            if self.quit_after_homing or self.error is not None:
                self.exit()
                return
        try:
            self.live.tick()
        except BaseException as exc:  # noqa: BLE001  the guard failed (dead-man, signal): leave, the guard stops all
            self.error = exc
            self.exit()
            return
        for name in self.names:  # an expired command resets its set point: a new press starts small
            if name not in self.live.running and self.setpoint[name] != 0.0:
                mode = self.live.state[name].mode
                if self.typed[name].get(mode) == self.setpoint[name]:
                    self.typed[name][mode] = 0.0  # the set point shown goes back to 0 with it (docs/jog.md)
                self.setpoint[name] = 0.0
        if len(self.live.messages) > self.seen_messages:  # a limit or trip: shown until the next key
            self.message = self.live.messages[-1]
            self.seen_messages = len(self.live.messages)
        self.render_state()

    def _do(self, fn: Callable[[], Any]) -> bool:
        """Run one session call; its answer becomes the message. False when it raised."""
        if self.homing is not None:
            self.message = f"homing {self.homing_joint} runs: wait for it, or Space to abort it"
            self.render_state()
            return False
        try:
            out = fn()
            self.message = out if isinstance(out, str) else ""
        except SherpaError as exc:
            self.message = f"error: {exc}"
            self.render_state()
            return False
        except BaseException as exc:  # noqa: BLE001  re-raised by the caller of run() (app.error)
            self.error = exc
            self.exit()
            return False
        self.render_state()
        return True

    # -- actions --------------------------------------------------------------------------------

    def action_select(self, delta: int) -> None:
        self.selected = (self.selected + delta) % len(self.names)
        self.message = ""
        self.render_state()

    def action_increment(self, delta: int) -> None:
        name = self.current
        mode = self.live.state[name].mode
        self.inc_index[name][mode] = min(max(self.inc_index[name][mode] + delta, 0), len(INCREMENTS[mode]) - 1)
        self.message = ""
        self.render_state()

    def action_mode(self) -> None:
        name = self.current
        modes = list(INCREMENTS)
        nxt = modes[(modes.index(self.live.state[name].mode) + 1) % len(modes)]
        self.setpoint[name] = 0.0

        def switch() -> str:
            self.live.set_mode(name, nxt)
            return f"{name}: {nxt} mode"

        self._do(switch)

    def action_step(self, sign: int) -> None:
        name = self.current
        mode = self.live.state[name].mode
        if mode == "position":
            counts = sign * self.increment_counts(name)
            self._do(lambda: self.live.step(name, counts))
            return
        self._send(name, round(self.setpoint[name] + sign * self.increment(name), 6))

    def _check_typed(self, name: str, mode: str, text: str) -> str | None:
        try:
            self._parse(name, mode, text)
        except SherpaError as exc:
            return str(exc)
        return None

    def _parse(self, name: str, mode: str, text: str) -> float:
        """A typed set point in the joint's unit (rad, rad/s, A); deg and counts are converted."""
        cpr = self._cpr(name)
        if mode == "position":
            return units.counts_to_rad(units.parse_position(text, cpr, what="set point"), cpr)
        if mode == "velocity":
            return units.counts_per_s_to_rad_per_s(units.parse_velocity(text, cpr, what="set point"), cpr)
        return units.parse_current(text, what="set point")

    def action_type(self) -> None:
        name = self.current
        mode = self.live.state[name].mode

        def typed(value: str | None) -> None:
            if value is None:
                self.message = f"{name}: set point unchanged"
            else:
                self.typed[name][mode] = self._parse(name, mode, value)
                self.message = f"{name}: {mode} set point {self.typed[name][mode]:+.4g} {UNITS[mode]}; Enter starts"
            self.render_state()

        self.push_screen(SetPointDialog(name, mode, lambda text: self._check_typed(name, mode, text)), typed)

    def action_start(self) -> None:
        """Start: send the typed set point (position: go there; velocity/torque: run at it while
        Enter is held, like an arrow key); without one, the current set point again."""
        name = self.current
        mode = self.live.state[name].mode
        typed = self.typed[name].get(mode)
        if mode == "position":
            if typed is None:
                self.message = "position mode: type a target with t (or step with ← →)"
                self.render_state()
                return
            goal = units.rad_to_counts(typed, self._cpr(name))
            self._do(lambda: self.live.step(name, 0, to=goal))
            return
        self._send(name, typed if typed is not None else self.setpoint[name])

    def _send(self, name: str, value: float) -> None:
        """Velocity (rad/s) or torque (A): a set point the session accepted becomes the one the keys
        step from (what runs is shown from the motors' commands, :meth:`sent`); a refused one
        leaves the old set point and what runs as they were."""
        mode = self.live.state[name].mode
        axis = self.live.axes[name]
        before = self.live.running.get(name)
        if mode == "velocity":
            cps = units.rad_per_s_to_counts_per_s(value, axis.joint_cpr)
            ok = self._do(lambda: self.live.set_velocity(name, cps))
        else:
            ok = self._do(lambda: self.live.set_torque(name, value))
        after = self.live.running.get(name)
        if ok and after is not None and after is not before:  # a new command went out
            self.setpoint[name] = value
            self.typed[name][mode] = value  # the set point shown: Enter sends it again
        elif ok and after is None:  # stopped (a set point of 0, or refused at a range edge)
            self.setpoint[name] = 0.0
        self.render_state()

    def action_stop(self) -> None:
        name = self.current
        self.setpoint[name] = 0.0

        def stop() -> str:
            self.live.stop(name)
            return f"{name}: stopped"

        self._do(stop)

    def action_stop_all(self) -> None:
        if self.homing is not None:
            self.abort_homing.set()
            self.message = f"aborting homing {self.homing_joint} ..."
            self.render_state()
            return
        for name in self.names:
            self.setpoint[name] = 0.0

        def stop_all() -> str:
            self.live.stop_all()
            return "STOP: every joint stopped"

        self._do(stop_all)

    def action_status(self) -> None:
        """Get Status: OK or Fail per drive of the selected joint (d shows SR and MF decoded)."""
        name = self.current

        def get() -> str:
            self.status[name] = self.live.status(name)
            bad = [d for d in self.status[name] if not d.ok]
            # the detail panel shows the status itself ("status: OK"): the message only says it was read
            return f"{name}: status read" + (f": {plural(len(bad), 'drive')} Fail" if bad else "")

        self._do(get)

    def action_details(self) -> None:
        if self.current not in self.status:
            self.action_status()
        self.show_details = not self.show_details
        self.render_state()

    def action_calibrate(self) -> None:
        if self.homing is not None:
            self.message = f"homing {self.homing_joint} runs already"
            self.render_state()
            return
        if not self.calibrate:
            self.message = "calibrate: not offered here"
            self.render_state()
            return
        name = self.current
        try:
            plan = self.live.home_plan(name)
        except SherpaError as exc:
            self.message = f"calibrate: {exc}"
            self.render_state()
            return

        def answered(yes: bool | None) -> None:
            if yes:
                self._start_homing(name)
            else:
                self.message = f"calibrate {name}: cancelled, nothing moved"
                self.render_state()

        self.push_screen(HomeConfirm(name, plan_lines(plan)), answered)

    def _start_homing(self, name: str) -> None:
        if self.homing is not None:
            return
        for n in self.names:
            self.setpoint[n] = 0.0
        self.abort_homing.clear()
        self.homing_joint, self.homing_result = name, None

        def work() -> None:
            try:
                self.homing_result = self.live.calibrate(name, abort=self.abort_homing.is_set,
                                                         on_event=self.home_log.append)
            except BaseException as exc:  # noqa: BLE001  handed to the main thread in tick
                self.homing_result = exc

        self.homing = threading.Thread(target=work, name="sherpa-jog-home", daemon=True)
        self.message = f"homing {name} ..."
        self.homing.start()
        self.render_state()

    def _homing_done(self) -> None:
        assert self.homing is not None
        self.homing.join()
        self.homing = None
        result = self.homing_result
        if isinstance(result, SherpaError):
            self.message = f"calibrate {self.homing_joint}: {result}"
        elif isinstance(result, BaseException):
            self.error = result
            return
        else:
            assert result is not None  # work() set it before its thread ended
            self.message = f"calibrate: {report_line(result)}"
        self.home_log.append(self.message)
        self.seen_messages = len(self.live.messages)  # homing's own messages: the line above says it

    async def action_quit(self) -> None:
        if self.homing is not None:  # the worker's homing ends first: its guard stops its motors
            self.abort_homing.set()
            self.quit_after_homing = True
            self.message = f"aborting homing {self.homing_joint}, then leaving ..."
            self.render_state()
            return
        self.exit()


def counts_text(counts: int, cpr: int) -> str:
    return f"{units.counts_to_rad(counts, cpr):+.4f} rad ({counts} counts)"
