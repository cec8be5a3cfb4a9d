"""`sherpa monitor [TARGET ...]`: a live view of the drives (or one snapshot with --once)."""

from __future__ import annotations

import contextlib
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from typing import TYPE_CHECKING, Any

import typer

from sherpa_cli.cli.context import AppState, state
from sherpa_cli.cli.options import ApplyHeartbeat, Targets
from sherpa_cli.cli.robotics import (
    DEFAULT_AT,
    AllowRemote,
    Foxglove,
    FoxgloveAt,
    MonitorFeed,
    check_live,
    live_view,
)
from sherpa_cli.errors import ExitCode, UsageError
from sherpa_cli.words import plural

if TYPE_CHECKING:
    from rich.console import Group
    from rich.table import Table

    from sherpa_cli.config.model import ArmConfig
    from sherpa_cli.ops.ft import SensorReading
    from sherpa_cli.ops.monitor import DriveStatus, MonitorSnapshot

# Seconds between polls in the live view; the CLI's sleep goes through here so tests can stop it.
sleep: Callable[[float], None] = time.sleep


def monitor(
    ctx: typer.Context,
    targets: Targets = None,
    once: bool = typer.Option(False, "--once", help="Print one snapshot and exit (no ages or times in it)."),
    interval: float = typer.Option(0.5, "--interval", metavar="S", help="Seconds between polls in the live view."),
    heartbeat: int | None = typer.Option(
        None, "--heartbeat", metavar="MS",
        help="With --apply: set the drives' producer heartbeat (0x1017) to MS while monitoring (RAM only, the "
        "old value is written back at exit). Without --apply it is a dry run: shown, not written. Default: "
        "only listen to the heartbeat the drives already send."),
    apply: ApplyHeartbeat = False,
    duration: float | None = typer.Option(None, "--for", metavar="S", help="End the live view by itself after "
                                          "S seconds' worth of polls (S / --interval polls)."),
    foxglove: Foxglove = False,
    foxglove_at: FoxgloveAt = DEFAULT_AT,
    allow_remote: AllowRemote = False,
) -> None:
    """Show every drive: NMT state and heartbeat, MO, UM, position in joint units, SR and MF decoded,
    and the last EMCY with its Elmo text. With --foxglove the same goes live to Foxglove (joint
    states, motor counts, drive status, bus load, each EMCY; docs/log.md).

    Each drive is NMT-started (the binary interpreter answers only when Operational) and then only
    queried: MO, UM, PX, SR, MF, plus SDO reads of 0x1017 and 0x1003:1 (the last stored error).
    Nothing else is written unless --heartbeat and --apply are given. Drives on different buses are polled at
    the same time; a drive that stops answering shows "no answer", never its old values.
    Ctrl-C ends the live view with exit code 0. --once exits 1 when a drive does not answer or
    has a motor failure latched (MF not 0).

    \b
    Examples:
      sherpa monitor
      sherpa monitor shoulder_diff elbow_pitch --interval 0.2
      sherpa --json monitor --once
      sherpa monitor --heartbeat 200 --apply
      sherpa monitor --foxglove
    """
    from sherpa_cli.bus.targets import drive_refs
    from sherpa_cli.ops.monitor import MAX_INTERVAL_S

    st = state(ctx)
    if st.json_mode and not once:
        raise UsageError("--json needs --once: the live view is for a terminal", hint="sherpa --json monitor --once")
    if not 0 < interval <= MAX_INTERVAL_S:  # also refuses nan and inf (time.sleep(inf) overflows)
        raise UsageError(f"--interval {interval}: expected a number of seconds > 0 and <= {MAX_INTERVAL_S:g}")
    if duration is not None and not 0 < duration <= 86400:
        raise UsageError(f"--for {duration}: expected seconds > 0 and <= 86400")
    if once and (foxglove or duration is not None):
        raise UsageError(f"{'--foxglove' if foxglove else '--for'} is for the live view, not --once")
    check_live(foxglove, foxglove_at, allow_remote)
    cfg = st.load_config()
    refs = drive_refs(cfg, targets)
    buses = list(dict.fromkeys(ref.bus for ref in refs))
    if heartbeat is not None and not 0 < heartbeat <= 0xFFFF:
        raise UsageError(f"--heartbeat {heartbeat}: expected 1..65535 ms (0x1017 is 16 bits)")
    if heartbeat is not None and not apply:
        # setting 0x1017 is a write: a dry run says what it would do and only listens
        st.out.warn(f"dry run: --heartbeat {heartbeat} would set the producer heartbeat (0x1017) of "
                    f"{plural(len(refs), 'drive')} to {heartbeat} ms in RAM; nothing is written (add --apply)")
        heartbeat = None
    from sherpa_cli.api import Arm

    with live_view(st, foxglove, foxglove_at, allow_remote) as view, st.session(buses=buses) as session:
        arm = Arm(session)
        if once:
            from sherpa_cli.ops.ft import read_sensors

            with arm.monitor(targets, count=1, heartbeat_ms=heartbeat, apply=heartbeat is not None,
                             wait_for_heartbeats=True) as stream:
                rows = list(next(stream))
                # the F/T sensors on the monitored buses: one sample each (a whole-arm view only)
                sensors = read_sensors(session, [d for d in cfg.ft_sensors() if d.bus in buses]) if not targets \
                    else []
            _render_once(st, rows, sensors)
            if any(not r.answering or r.mf or r.problem for r in rows) or \
                    any(s.wrench is None or not s.wrench.status.ok for s in sensors):
                # a silent drive or sensor, a latched motor failure, a sensor reporting a fault
                raise typer.Exit(int(ExitCode.PROBLEM))
            return
        after_poll = None
        if view is not None:
            view.listen(session.links)
            after_poll = MonitorFeed(view, cfg).publish
        polls = None if duration is None else max(1, round(duration / interval))
        # the module's sleep is looked up at each wait: tests step it
        stream = arm.monitor(targets, interval=interval, count=polls, heartbeat_ms=heartbeat,
                             apply=heartbeat is not None, sleep=lambda s: sleep(s))
        # Ctrl-C is how a live view ends: exit 0 after the monitor restores 0x1017
        with stream, contextlib.suppress(KeyboardInterrupt):
            _live(st, stream, cfg, after_poll=after_poll)


def _live(st: AppState, stream: Iterator[MonitorSnapshot], cfg: ArmConfig, *,
          after_poll: Callable[[list[Any]], None] | None = None) -> None:
    """Show each snapshot of ``stream`` as it comes; ``after_poll(rows)`` sees each one."""
    def rows_of(snap: MonitorSnapshot) -> list[Any]:
        rows = list(snap)
        if after_poll is not None:
            after_poll(rows)
        return rows

    if not sys.stdout.isatty():
        # a log, not a screen: one full snapshot per poll
        for snap in stream:
            _print(st, *_renderables(rows_of(snap), cfg, ages=True))
            st.out.line()
        return
    from rich.live import Live

    first = next(stream, None)
    if first is None:
        return
    with Live(_screen(*_renderables(rows_of(first), cfg, ages=True)), console=st.out.console,
              auto_refresh=False) as live:
        for snap in stream:
            live.update(_screen(*_renderables(rows_of(snap), cfg, ages=True)), refresh=True)


def _render_once(st: AppState, rows: Sequence[DriveStatus], sensors: Sequence[SensorReading] = ()) -> None:
    if st.json_mode:
        body: dict[str, Any] = {"drives": [r.as_json(ages=False) for r in rows]}
        if sensors:
            body["ft_sensors"] = [s.as_json() for s in sensors]
        st.out.json(body)
        return
    tables, notes = _renderables(rows, st.load_config(), ages=False)
    if sensors:
        tables.append(_sensor_table(sensors))
        notes.extend(f"{s.device} ({s.bus} base 0x{s.base_id:03X}): {s.problem}" for s in sensors if s.problem)
    _print(st, tables, notes)


def _sensor_table(sensors: Sequence[SensorReading]) -> Table:
    """Fx Fy Fz in N, Tx Ty Tz in N·m; whether the sensor is biased is not known over CAN."""
    from sherpa_cli.cli.output import make_table

    rows = []
    for s in sensors:
        w = s.wrench
        values = ["-"] * 6 if w is None else [f"{round(v, 2) + 0.0:.2f}" for v in (w.fx, w.fy, w.fz)] + \
            [f"{round(v, 3) + 0.0:.3f}" for v in (w.tx, w.ty, w.tz)]
        rows.append([s.device, f"{s.bus}:0x{s.base_id:03X}", *values,
                     "no answer" if w is None else str(w.status)])
    return make_table("F/T sensors", ["sensor", "base", "Fx N", "Fy N", "Fz N", "Tx N·m", "Ty N·m", "Tz N·m",
                                      "status"], rows, right=(2, 3, 4, 5, 6, 7))


def _print(st: AppState, tables: list[Table], notes: list[str]) -> None:
    for table in tables:
        st.out.result(table)
    for note in notes:
        st.out.line(note)


def _screen(tables: list[Table], notes: list[str]) -> Group:
    from rich.console import Group
    from rich.text import Text

    return Group(*tables, *(Text(note) for note in notes))


def _age(seconds: float | None) -> str:
    return "-" if seconds is None else f"{seconds:.1f} s ago"


def _heartbeat(r: DriveStatus, ages: bool) -> str:
    if r.heartbeat_ms is None:
        return "-"  # 0x1017 could not be read
    if not r.heartbeat_ms:
        return "off"
    if r.heartbeat_age is None:
        return "silent"
    return _age(r.heartbeat_age) if ages else f"{r.heartbeat_ms} ms"


def _position(r: DriveStatus, cfg: ArmConfig) -> str:
    """Radians of the drive's joint; a pair's drive a shows the Σ joint, drive b the Δ joint."""
    if r.uncalibrated is not None:
        return "?"  # the counter is not the joint's position: the note says both numbers
    if r.position_rad is None:
        return "-"
    pair = cfg.pair_of_drive(r.drive)
    mark = "" if pair is None else ("Σ " if r.joint == pair.sigma else "Δ ")
    return f"{mark}{r.position_rad + 0.0:.4f}"  # + 0.0: no "-0.0000"


def _renderables(rows: Sequence[DriveStatus], cfg: ArmConfig, *, ages: bool) -> tuple[list[Table], list[str]]:
    """One table per bus, and one note per thing that needs a look (faults, EMCY, silence)."""
    from sherpa_cli.cli.output import make_table

    out: list[Table] = []
    for bus in dict.fromkeys(r.bus for r in rows):
        table_rows = []
        for r in (r for r in rows if r.bus == bus):
            table_rows.append([
                r.node, r.drive, r.nmt, _heartbeat(r, ages),
                "-" if r.mo is None else ("on" if r.mo else "off"), "-" if r.um is None else r.um,
                _position(r, cfg) if r.answering else "-",
                "-" if r.sr is None else ("check" if r.sr_problems else "ok"),
                "-" if r.mf is None else (f"0x{r.mf & 0xFFFFFFFF:08X}" if r.mf else "ok"),
                f"0x{r.emcy.code:04X}" if r.emcy is not None else "-"])
        out.append(make_table(f"bus {bus}", ["node", "drive", "NMT", "heartbeat", "MO", "UM", "rad",
                                             "SR", "MF", "EMCY"], table_rows, right=(0, 6), drop=(5, 3, 9)))
    notes = []
    for r in rows:
        who = f"{r.drive} ({r.address})"
        if not r.answering:
            silent = f" for {r.silent_for:.1f} s" if ages and r.silent_for is not None else ""
            why = r.problem if r.problem and not r.problem.startswith("no answer") else None
            what = r.problem if r.problem and why is None else "no answer"
            notes.append(f"{who}: {what}{silent}" + (f" ({why})" if why else ""))
        if r.mf:
            notes.extend(f"{who}: MF: {f.line()}" for f in r.mf_faults)
        notes.extend(f"{who}: SR: {f.line()}" for f in r.sr_problems)
        if r.uncalibrated is not None:
            notes.append(f"{who}: {r.joint} {r.uncalibrated}")
        if r.emcy is not None:
            when = "raised before the monitor started" if r.emcy_before_start else (
                _age(r.emcy_age) if ages else "heard while monitoring")
            notes.append(f"{who}: last EMCY ({when}): {r.emcy.text}")
    return out, notes
