"""`sherpa jog --interactive`: a full-screen terminal view of the joints with keyboard control
(textual). It only renders and maps keys; everything that moves a motor goes through
ops/live_jog.LiveJog (one motion guard, the joint limits and limit watch of `jog`).

No terminal reports key releases, so holding a key is not a dead-man: a press is one step, and a
velocity or torque command stops by itself ``keepalive`` s after the last press (docs/jog.md).
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, ClassVar

from rich.text import Text
from textual.app import App, ComposeResult
from textual.binding import Binding, BindingType
from textual.containers import Vertical
from textual.screen import ModalScreen
from textual.widgets import Footer, Static

from sherpa_cli.errors import SherpaError
from sherpa_cli.joints.units import counts_to_rad

if TYPE_CHECKING:
    from sherpa_cli.ops.home import HomePlan, HomeReport
    from sherpa_cli.ops.live_jog import LiveJog

# per mode: the increments a key press can use (counts, counts/s, A)
INCREMENTS: dict[str, tuple[float, ...]] = {
    "position": (10, 50, 200, 1000),
    "velocity": (50, 200, 1000, 4000),
    "torque": (0.05, 0.1, 0.25, 0.5),
}
UNITS = {"position": "counts", "velocity": "counts/s", "torque": "A"}
BAR = 36


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


class JogView(App):
    """The view; ``live`` is an entered LiveJog. ``calibrate``: the ``c`` key homes the selected joint
    (ops/live_jog.LiveJog.calibrate, in a worker thread so Space can abort it)."""

    CSS = """
    #joints { height: auto; }
    .joint { height: auto; padding: 0 1; }
    #status { dock: bottom; height: auto; padding: 0 1; background: $boost; }
    """
    BINDINGS: ClassVar[list[BindingType]] = [
        Binding("up", "select(-1)", "joint up"),
        Binding("down", "select(1)", "joint down"),
        Binding("left", "step(-1)", "step -"),
        Binding("right", "step(1)", "step +"),
        Binding("m", "mode", "mode"),
        Binding("plus,equals_sign,right_square_bracket", "increment(1)", "inc +", key_display="+"),
        Binding("minus,left_square_bracket", "increment(-1)", "inc -", key_display="-"),
        Binding("enter", "start", "start"),
        Binding("s", "stop", "stop"),
        Binding("space", "stop_all", "STOP ALL", priority=True),
        Binding("c", "calibrate", "calibrate"),
        Binding("q", "quit", "quit"),
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
        self.inc_index = {name: {m: 1 for m in INCREMENTS} for name in self.names}
        self.setpoint = {name: 0.0 for name in self.names}  # velocity (counts/s) or torque (A)
        self.message = ""
        self.error: BaseException | None = None

    # -- layout ---------------------------------------------------------------------------------

    def compose(self) -> ComposeResult:
        with Vertical(id="joints"):
            for name in self.names:
                yield Static(id=f"j-{name}", classes="joint")
        yield Static(id="status")
        yield Footer()

    def on_mount(self) -> None:
        self.title = "sherpa jog --interactive"
        self.tick()  # a sign of life for the guard's dead-man as soon as the view is up
        self.set_interval(self.tick_period, self.tick)

    @property
    def current(self) -> str:
        return self.names[self.selected]

    def increment(self, name: str) -> float:
        mode = self.live.state[name].mode
        return INCREMENTS[mode][self.inc_index[name][mode]]

    def render_state(self) -> None:
        base = self.screen_stack[0]  # the joints' screen, also under the calibrate question
        for i, name in enumerate(self.names):
            st = self.live.state[name]
            axis = self.live.axes[name]
            j = axis.joint
            text = Text()
            text.append("▶ " if i == self.selected else "  ", style="bold")
            text.append(f"{name:<12}", style="bold" if i == self.selected else "")
            rad = f"{st.rad:+8.4f} rad" if st.rad is not None else "    ? rad"
            cnt = f"({st.counts:>7} counts)" if st.counts is not None else "(   ? counts)"
            text.append(f"{rad} {cnt} ")
            text.append(bar(st.counts, j.full_range, j.normal_range))
            text.append(f"\n    mode {st.mode:<8}  step {self.increment(name):g} {UNITS[st.mode]:<8}  ")
            if st.mode != "position":
                text.append(f"set {self.setpoint[name]:g} {UNITS[st.mode]}  ")
            text.append(f"now {st.command}")
            text.append("\n    ")
            text.append("calibrated" if st.calibrated else "NOT calibrated",
                        style="green" if st.calibrated else "yellow")
            text.append(f"  full [{j.full_range[0]}, {j.full_range[1]}] "
                        f"normal [{j.normal_range[0]}, {j.normal_range[1]}]  ")
            text.append("faults (SR/MF): " + ("; ".join(st.faults) if st.faults else "none"),
                        style="bold red" if st.faults else "")
            if st.note:
                text.append(f"\n    {st.note}", style="yellow")
            base.query_one(f"#j-{name}", Static).update(text)
        status = Text(self.live.deadman + "\n")
        last = self.live.messages[-1] if self.live.messages else ""
        if self.homing is not None:
            what = "aborting homing" if self.abort_homing.is_set() else "homing"
            status.append(f"{what} {self.homing_joint} ... (Space aborts)\n", style="bold yellow")
        status.append(self.message or last, style="bold")
        base.query_one("#status", Static).update(status)

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
            if name not in self.live.running:
                self.setpoint[name] = 0.0
        self.render_state()

    def _do(self, fn: Callable[[], object]) -> None:
        if self.homing is not None:
            self.message = f"homing {self.homing_joint} runs: wait for it, or Space to abort it"
            self.render_state()
            return
        try:
            out = fn()
            self.message = out if isinstance(out, str) else ""
        except SherpaError as exc:
            self.message = f"error: {exc}"
        except BaseException as exc:  # noqa: BLE001  re-raised by the caller of run() (app.error)
            self.error = exc
            self.exit()
            return
        self.render_state()

    # -- actions --------------------------------------------------------------------------------

    def action_select(self, delta: int) -> None:
        self.selected = (self.selected + delta) % len(self.names)
        self.message = ""
        self.render_state()

    def action_increment(self, delta: int) -> None:
        name = self.current
        mode = self.live.state[name].mode
        self.inc_index[name][mode] = min(max(self.inc_index[name][mode] + delta, 0), len(INCREMENTS[mode]) - 1)
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
        inc = self.increment(name)
        if mode == "position":
            self._do(lambda: self.live.step(name, int(sign * inc)))
            return
        self.setpoint[name] = round(self.setpoint[name] + sign * inc, 6)
        self._send(name)

    def action_start(self) -> None:
        name = self.current
        if self.live.state[name].mode == "position":
            self.message = "position mode: ← and → step the joint"
            self.render_state()
            return
        self._send(name)

    def _send(self, name: str) -> None:
        mode = self.live.state[name].mode
        v = self.setpoint[name]
        if mode == "velocity":
            self._do(lambda: self.live.set_velocity(name, int(v)))
        else:
            self._do(lambda: self.live.set_torque(name, v))

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

    async def action_quit(self) -> None:
        if self.homing is not None:  # the worker's homing ends first: its guard stops its motors
            self.abort_homing.set()
            self.quit_after_homing = True
            self.message = f"aborting homing {self.homing_joint}, then leaving ..."
            self.render_state()
            return
        self.exit()


def counts_text(counts: int, cpr: int) -> str:
    return f"{counts_to_rad(counts, cpr):+.4f} rad ({counts} counts)"
