"""`sherpa jog --interactive`: a full-screen terminal view of the joints with keyboard control
(textual). It only renders and maps keys; everything that moves a motor goes through
ops/live_jog.LiveJog (one motion guard, the joint limits and limit watch of `jog`).

No terminal reports key releases, so holding a key is not a dead-man: a press is one step, and a
velocity or torque command stops by itself ``keepalive`` s after the last press (docs/jog.md).
"""

from __future__ import annotations

from typing import Any, Callable

from rich.text import Text
from textual.app import App, ComposeResult
from textual.binding import Binding
from textual.containers import Vertical
from textual.widgets import Footer, Static

from sherpa_cli.errors import SherpaError
from sherpa_cli.joints.units import counts_to_rad

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


class JogView(App):
    """The view; ``live`` is an entered LiveJog, ``calibrate(joint) -> str`` runs homing (or is None)."""

    CSS = """
    #joints { height: auto; }
    .joint { height: auto; padding: 0 1; }
    #status { dock: bottom; height: auto; padding: 0 1; background: $boost; }
    """
    BINDINGS = [
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

    def __init__(self, live: Any, *, calibrate: Callable[[str], str] | None = None,
                 tick_period: float = 0.1) -> None:
        super().__init__()
        self.live = live
        self.calibrate_joint = calibrate
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
            self.query_one(f"#j-{name}", Static).update(text)
        status = Text(self.live.deadman + "\n")
        last = self.live.messages[-1] if self.live.messages else ""
        status.append(self.message or last, style="bold")
        self.query_one("#status", Static).update(status)

    # -- periodic -------------------------------------------------------------------------------

    def tick(self) -> None:
        try:
            self.live.tick()
        except BaseException as exc:  # the guard failed (dead-man, signal): leave, the guard stops all
            self.error = exc
            self.exit()
            return
        for name in self.names:  # an expired command resets its set point: a new press starts small
            if name not in self.live.running:
                self.setpoint[name] = 0.0
        self.render_state()

    def _do(self, fn: Callable[[], Any]) -> None:
        try:
            out = fn()
            self.message = out if isinstance(out, str) else ""
        except SherpaError as exc:
            self.message = f"error: {exc}"
        except BaseException as exc:
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
        self._do(lambda: self.live.set_mode(name, nxt) or f"{name}: {nxt} mode")

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
        self._do(lambda: self.live.stop(name) or f"{name}: stopped")

    def action_stop_all(self) -> None:
        for name in self.names:
            self.setpoint[name] = 0.0
        self._do(lambda: self.live.stop_all() or "STOP: every joint stopped")

    def action_calibrate(self) -> None:
        if self.calibrate_joint is None:
            self.message = "calibrate: not available yet (sherpa home)"
            self.render_state()
            return
        name, calibrate = self.current, self.calibrate_joint
        self._do(lambda: calibrate(name))

    async def action_quit(self) -> None:
        self.exit()


def counts_text(counts: int, cpr: int) -> str:
    return f"{counts_to_rad(counts, cpr):+.4f} rad ({counts} counts)"
