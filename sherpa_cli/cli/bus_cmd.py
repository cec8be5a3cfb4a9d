"""`sherpa bus status|watch|up|down`: the configured buses' links (docs/bus.md)."""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from typing import TYPE_CHECKING, Any

import typer

from sherpa_cli.cli.context import AppState, state
from sherpa_cli.errors import CommunicationError, ExitCode, UsageError

if TYPE_CHECKING:
    from rich.console import Group

    from sherpa_cli.bus.session import ArmSession, InProcessArm
    from sherpa_cli.config.model import ArmConfig
    from sherpa_cli.ops.buslink import LinkChange
    from sherpa_cli.ops.buswatch import WatchState

app = typer.Typer(no_args_is_help=True, help="The CAN buses: link state, error frames, bring-up (docs/bus.md).")

# the watch's clock and sleep go through here so tests can run it on their own time
clock: Callable[[], float] = time.monotonic
sleep: Callable[[float], None] = time.sleep
MAX_SECONDS = 24 * 3600.0
MAX_WINDOW = 60.0  # s: the longest load window of `bus status`

Buses = typer.Argument(None, metavar="[BUS]...", help="Configured bus names; default: every bus.")


def mapped_config(st: AppState) -> ArmConfig:
    """The config as the session sees it: with --bus-map applied (the interfaces actually used)."""
    from sherpa_cli.bus.busmap import apply_bus_map, parse_bus_map

    cfg = st.load_config()
    mapping = parse_bus_map(st.bus_map)
    if mapping and not st.sim:
        cfg = apply_bus_map(cfg, mapping)
    return cfg


def _seconds(value: float | None, option: str, *, zero_ok: bool = False) -> None:
    if value is None:
        return
    low_ok = value >= 0 if zero_ok else value > 0
    if not (low_ok and value <= MAX_SECONDS):  # refuses nan and inf too
        raise UsageError(f"{option} {value}: expected seconds {'>= 0' if zero_ok else '> 0'} and <= {MAX_SECONDS:g}")


@contextmanager
def _sessions(st: AppState, cfg: ArmConfig, names: list[str]) -> Iterator[tuple[ArmSession | None, dict[str, str]]]:
    """With --sim: one session (the simulated arm and its controllers). Else: a session for the buses
    netlink cannot read (python-can opens them); buses it could not open map to the error."""
    if st.sim:
        with st.session(buses=names) as simulated:
            yield simulated, {}
        return
    others = [b for b in names if cfg.buses[b].interface != "socketcan"]
    if not others:
        yield None, {}
        return
    failed: dict[str, str] = {}
    session: ArmSession | None
    with ExitStack() as stack:
        try:
            session = stack.enter_context(st.session(buses=others))
        except CommunicationError as exc:
            failed = dict.fromkeys(others, str(exc))
            session = None
        yield session, failed


# -- status ---------------------------------------------------------------------------------------

@app.command("status")
def status_cmd(
    ctx: typer.Context,
    buses: list[str] | None = Buses,
    window: float = typer.Option(0.5, "--window", metavar="S", help="Seconds over which the bus load is measured "
                                 "(0: no load)."),
) -> None:
    """One row per bus: interface, link state (ERROR-ACTIVE, ERROR-WARNING, ERROR-PASSIVE, BUS-OFF,
    STOPPED, down), TX/RX error counters, bit rate and sample point against the config, restart-ms,
    berr-reporting, the kernel's CAN counters, frames/errors/drops and the load.

    SocketCAN is read through netlink (no privileges needed); other interfaces say what they cannot
    report. Exit 1 when a bus is missing, down, BUS-OFF, ERROR-PASSIVE or at another bit rate.

    \b
    Examples:
      sherpa bus status
      sherpa --json bus status can1
    """
    from dataclasses import replace

    from sherpa_cli.bus.health import findings
    from sherpa_cli.ops import buslink

    st = state(ctx)
    _seconds(window, "--window", zero_ok=True)
    if window > MAX_WINDOW:
        raise UsageError(f"--window {window}: expected seconds >= 0 and <= {MAX_WINDOW:g}")
    cfg = mapped_config(st)
    names = buslink.select_buses(cfg, buses)
    with _sessions(st, cfg, names) as (session, failed):
        statuses = buslink.status(cfg, names, session=session, window=window, sleep=sleep)
    statuses = [replace(s, present=None, error=failed[s.bus], not_reported={"all": failed[s.bus]})
                if s.bus in failed else s for s in statuses]
    problems = {s.bus: findings(s) for s in statuses}
    if st.json_mode:
        st.out.json({"buses": [{**s.as_json(), "problems": [f.__dict__ for f in problems[s.bus]]} for s in statuses]})
    else:
        render_status(st, statuses, problems)
    if any(problems.values()) or failed:
        raise typer.Exit(int(ExitCode.PROBLEM))


def _cell(value: object, fmt: Callable[[Any], str] = str) -> str:
    return "-" if value is None else fmt(value)


NAMES = {"state": "controller state", "counters": "error counters", "bitrate": "bit rate",
         "sample_point": "sample point", "restart_ms": "restart-ms", "berr_reporting": "berr-reporting",
         "device_stats": "kernel CAN counters", "stats": "frame counters", "load": "load", "all": "anything"}


def render_status(st: AppState, statuses: list[Any], problems: dict[str, list[Any]]) -> None:
    from sherpa_cli.bus.linkstate import SIMULATED

    rows = []
    for s in statuses:
        rate = _cell(s.bitrate)
        if s.bitrate_mismatch:
            rate += f" (config {s.configured_bitrate})"
        iface = f"{s.interface or '-'}:{s.channel or '-'}" + (f" ({s.kind})" if s.kind and s.kind != "can" else "")
        rows.append([s.bus, iface, s.state, f"{s.tec}/{s.rec}" if s.tec is not None else "-", rate,
                     _cell(s.sample_point, lambda v: f"{v:.3f}"), _cell(s.restart_ms),
                     _cell(s.berr_reporting, lambda v: "on" if v else "off"),
                     _cell(s.load, lambda v: f"{v * 100:.1f} %")])
    st.out.table("buses", ["bus", "interface", "state", "TEC/REC", "bit rate", "sample pt", "restart-ms", "berr",
                           "load"], rows, right=(3, 5, 6, 8), drop=(5, 7, 6, 1))
    counted = [s for s in statuses if s.device_stats is not None or s.stats is not None]
    if counted:
        crows = []
        for s in counted:
            d, f = s.device_stats or {}, s.stats or {}
            crows.append([s.bus, *(_cell(d.get(k)) for k in ("bus_error", "arbitration_lost", "error_warning",
                                                             "error_passive", "bus_off", "restarts")),
                          f"{_cell(f.get('rx_packets'))}/{_cell(f.get('tx_packets'))}",
                          f"{_cell(f.get('rx_errors'))}/{_cell(f.get('tx_errors'))}",
                          f"{_cell(f.get('rx_dropped'))}/{_cell(f.get('tx_dropped'))}"])
        st.out.table("kernel counters", ["bus", "bus err", "arb lost", "warning", "passive", "bus-off", "restarts",
                                         "frames rx/tx", "errors rx/tx", "drops rx/tx"], crows,
                     right=range(1, 10))
    for s in statuses:
        why: dict[str, list[str]] = {}
        for key, reason in s.not_reported.items():
            why.setdefault(reason, []).append(NAMES.get(key, key))
        for reason, keys in why.items():
            st.out.line(f"{s.bus}: {', '.join(keys)}: {reason}")
    if any(s.source == SIMULATED for s in statuses):
        st.out.line("(--sim: the figures are the simulated arm's CAN controllers)")
    for s in statuses:
        for f in problems.get(s.bus, []):
            st.out.line(f"{s.bus}: {f.text}")
            st.out.line(f"  fix: {f.hint}")


# -- watch ------------------------------------------------------------------------------------------

@app.command("watch")
def watch_cmd(
    ctx: typer.Context,
    buses: list[str] | None = Buses,
    seconds: float | None = typer.Option(None, "--for", metavar="S", help="Stop after S seconds (default: Ctrl-C)."),
    interval: float = typer.Option(0.5, "--interval", metavar="S", help="Seconds between two readings of the links."),
) -> None:
    """Live: each bus's state and counters, and every error frame decoded (no ACK, bit/stuff/form/CRC
    errors with their location, controller warning/passive, bus-off, restarted, TEC/REC) with what to
    check. On a terminal a live view; otherwise one line per error frame and a summary at the end.

    The adapter sends error frames only with berr-reporting on (`sherpa bus up` turns it on).
    Ctrl-C ends the watch with exit code 0.

    \b
    Examples:
      sherpa bus watch
      sherpa bus watch can1 --for 10
      sherpa --json bus watch --for 5
    """
    from sherpa_cli.ops import buslink
    from sherpa_cli.ops.buswatch import watch

    st = state(ctx)
    _seconds(seconds, "--for")
    _seconds(interval, "--interval")
    if st.json_mode and seconds is None:
        raise UsageError("--json needs --for: the live view is for a terminal", hint="sherpa --json bus watch --for 5")
    cfg = st.load_config()
    names = buslink.select_buses(cfg, buses)
    live = sys.stdout.isatty() and not st.json_mode
    printer = _LinePrinter(st)
    result = None
    with st.session(buses=names) as session:
        try:
            if live:
                result = _live(st, session, names, seconds, interval)
            else:
                result = watch(session, names, duration=seconds, interval=interval, clock=clock, sleep=sleep,
                               on_update=None if st.json_mode else printer)
        except KeyboardInterrupt:
            pass  # how a live view ends: exit 0
    if result is None:
        return
    if st.json_mode:
        st.out.json(result.as_json())
    elif not live:
        _summary(st, result)


class _LinePrinter:
    """Not a terminal: one line per state change and per error frame; each hint once per bus."""

    def __init__(self, st: AppState) -> None:
        self.st = st
        self.states: dict[str, str] = {}
        self.hinted: set[tuple[str, str]] = set()

    def __call__(self, w: WatchState) -> None:
        out = self.st.out
        for bus in w.buses:
            s = w.links.get(bus)
            if s is None:
                continue
            before = self.states.get(bus)
            if before is None:
                out.line(f"{bus}: {s.state}" + (f" (TEC {s.tec}, REC {s.rec})" if s.tec is not None else ""))
            elif before != s.state:
                out.line(f"{bus}: {before} -> {s.state}")
            self.states[bus] = s.state
        for e in w.new:
            out.line(f"{e.bus}: {e.frame.summary}")
            for hint in e.frame.hints:
                if (e.bus, hint) not in self.hinted:
                    self.hinted.add((e.bus, hint))
                    out.line(f"  hint: {hint}")


def _summary(st: AppState, w: WatchState) -> None:
    rows = []
    for bus in w.buses:
        s = w.links.get(bus)
        counts: dict[str, int] = w.counts.get(bus, {})
        rows.append([bus, s.state if s else "-", f"{s.tec}/{s.rec}" if s is not None and s.tec is not None else "-",
                     ", ".join(f"{k} {n}" for k, n in sorted(counts.items())) or "none"])
    st.out.table("error frames seen", ["bus", "state", "TEC/REC", "error frames"], rows)


def _live(st: AppState, session: ArmSession, names: list[str], seconds: float | None, interval: float) -> WatchState:
    from rich.live import Live

    from sherpa_cli.ops.buswatch import watch

    with Live(console=st.out.console, auto_refresh=False) as live:
        return watch(session, names, duration=seconds, interval=interval, clock=clock, sleep=sleep,
                     on_update=lambda w: live.update(_screen(w), refresh=True))


def _screen(w: WatchState) -> Group:
    from rich.console import Group
    from rich.text import Text

    from sherpa_cli.cli.output import make_table

    rows = []
    for bus in w.buses:
        s = w.links.get(bus)
        counts: dict[str, int] = w.counts.get(bus, {})
        rows.append([bus, s.state if s else "-", f"{s.tec}/{s.rec}" if s is not None and s.tec is not None else "-",
                     _cell(s.load if s else None, lambda v: f"{v * 100:.1f} %"),
                     ", ".join(f"{k} {n}" for k, n in sorted(counts.items())) or "none"])
    table = make_table(f"bus watch ({w.elapsed:.0f} s; Ctrl-C ends)", ["bus", "state", "TEC/REC", "load",
                                                                       "error frames"], rows)
    recent = [Text(f"{e.bus}: {e.frame.summary}") for e in w.errors[-10:]]
    hints = [Text(f"hint ({bus}): {h}") for bus in w.buses for h in w.hints(bus)]
    return Group(table, *recent, *hints)


# -- up / down ------------------------------------------------------------------------------------

@app.command("up")
def up_cmd(
    ctx: typer.Context,
    buses: list[str] | None = Buses,
    bitrate: int | None = typer.Option(None, "--bitrate", metavar="N", help="Bit rate in bit/s (default: the "
                                       "config's buses.BUS.bitrate)."),
    restart_ms: int = typer.Option(100, "--restart-ms", metavar="MS", help="Restart the controller this long "
                                   "after bus-off (0: never)."),
) -> None:
    """Bring SocketCAN buses up as the seed's bring-up does by hand (Appendix D.3 step 1): link down,
    bit rate from the config, restart-ms, berr-reporting on, link up. Needs CAP_NET_ADMIN (root);
    without it nothing is changed and the exact `ip link` commands to run as root are printed (exit 6).
    A vcan link is only brought up: it has no bit rate, restart-ms or berr-reporting, and that is said.

    \b
    Examples:
      sudo sherpa bus up
      sudo sherpa bus up can1 --bitrate 500000
    """
    from sherpa_cli.ops import buslink

    st = state(ctx)
    if bitrate is not None and not 1 <= bitrate <= 8_000_000:
        raise UsageError(f"--bitrate {bitrate}: expected 1..8000000 bit/s")
    if not 0 <= restart_ms <= 60_000:
        raise UsageError(f"--restart-ms {restart_ms}: expected 0..60000 ms")
    cfg = mapped_config(st)
    names = buslink.select_buses(cfg, buses)
    with _sim_session(st, names) as sim:
        changes = buslink.bring_up(cfg, names, bitrate=bitrate, restart_ms=restart_ms, sim=sim)
    _render_changes(st, changes)


@app.command("down")
def down_cmd(ctx: typer.Context, buses: list[str] | None = Buses) -> None:
    """Set SocketCAN buses down (needs CAP_NET_ADMIN; without it: the `ip link` commands, exit 6).

    \b
    Examples:
      sudo sherpa bus down can1
    """
    from sherpa_cli.ops import buslink

    st = state(ctx)
    cfg = mapped_config(st)
    names = buslink.select_buses(cfg, buses)
    with _sim_session(st, names) as sim:
        changes = buslink.bring_down(cfg, names, sim=sim)
    _render_changes(st, changes)


@contextmanager
def _sim_session(st: AppState, names: list[str]) -> Iterator[InProcessArm | None]:
    if not st.sim:
        yield None
        return
    with st.session(buses=names) as session:
        yield session.sim


def _render_changes(st: AppState, changes: list[LinkChange]) -> None:
    if st.json_mode:
        st.out.json({"buses": [c.as_json() for c in changes]})
        return
    for c in changes:
        st.out.line(f"{c.bus} ({c.channel}): {'; '.join(c.done)}")
        for item in c.not_taken:
            st.out.line(f"  not set: {item}")
