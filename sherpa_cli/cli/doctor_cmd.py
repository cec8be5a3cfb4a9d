"""`sherpa doctor`: one pass/fail table over the laptop, the config, the buses and the drives."""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import TYPE_CHECKING

import typer

from sherpa_cli.cli.context import AppState, state
from sherpa_cli.errors import CommunicationError, ExitCode, SherpaError, UsageError
from sherpa_cli.words import plural

if TYPE_CHECKING:
    from types import ModuleType

    from sherpa_cli.bus.health import Finding
    from sherpa_cli.bus.linkstate import LinkStatus
    from sherpa_cli.config.model import ArmConfig
    from sherpa_cli.ops.doctor import DoctorReport

sleep: Callable[[float], None] = time.sleep  # tests run the listening window on their own time
clock: Callable[[], float] = time.monotonic


def doctor(
    ctx: typer.Context,
    window: float = typer.Option(1.0, "--window", metavar="S", help="Seconds to listen for another master's "
                                 "heartbeat on the host node id (and over which the bus load is measured)."),
) -> None:
    """Check everything a first session at the arm needs, one row each, with the fix for every failure:
    Python and packages; the config; per bus the interface, link, bit rate, state and load; the drives
    expected against those that answer, their model and firmware, heartbeats; the host node id free;
    user programs (PS); calibration; the state directory. Exit 1 on any failure.

    \b
    Examples:
      sherpa doctor
      sherpa --sim doctor
      sherpa --json doctor
    """
    from sherpa_cli.ops import buslink
    from sherpa_cli.ops import doctor as doc
    from sherpa_cli.paths import state_dir

    st = state(ctx)
    if not (0 <= window <= 60):  # refuses nan and inf too
        raise UsageError(f"--window {window}: expected 0..60 seconds")
    report = doc.DoctorReport()
    doc.check_environment(report, doc.package_versions(), linux=sys.platform.startswith("linux"))
    cfg = None
    try:
        from sherpa_cli.cli.bus_cmd import mapped_config

        cfg = mapped_config(st)
    except SherpaError as exc:
        report.add("config", False, str(exc), exc.hint or "`sherpa config check FILE` shows every problem")
    if cfg is not None:
        report.add("config", True, f"{cfg.source}: {plural(len(cfg.buses), 'bus', 'buses')}, {plural(len(cfg.drives), 'drive')}, "
                   + plural(len(cfg.joints), "joint") + (f", {plural(len(cfg.warnings), 'warning')}" if cfg.warnings else ""))
        _arm(st, report, cfg, buslink, doc, window)
    else:
        for name in ("buses", "drives"):
            report.skip(name, "no valid config")
    doc.check_state_dir(report, state_dir())
    if st.json_mode:
        st.out.json(report.as_json())
    else:
        _render(st, report)
    if report.failed:
        raise typer.Exit(int(ExitCode.PROBLEM))


def _arm(st: AppState, report: DoctorReport, cfg: ArmConfig, buslink: ModuleType, doc: ModuleType,
         window: float) -> None:
    from sherpa_cli.api import Arm

    names = list(cfg.buses)
    load_window = min(window, 0.5)
    if st.sim:
        with st.session() as session:
            statuses = buslink.status(cfg, names, session=session, window=load_window, sleep=sleep)
            usable = doc.check_buses(report, statuses)
            Arm(session).doctor(usable, report=report, window=window, clock=clock, sleep=sleep)
        return
    netlinked = [b for b in names if cfg.buses[b].interface == "socketcan"]
    statuses = {s.bus: s for s in buslink.status(cfg, netlinked, session=None, window=load_window, sleep=sleep)}
    fit = [b for b in netlinked if not any(f.problem in ("missing", "down", "bus-off", "stopped")
                                           for f in _findings(statuses[b]))]
    others = [b for b in names if b not in netlinked]
    try:
        with st.session(buses=fit + others) as session:
            for s in buslink.status(cfg, others, session=session, window=load_window, sleep=sleep):
                statuses[s.bus] = s
            usable = doc.check_buses(report, [statuses[b] for b in names])
            Arm(session).doctor(usable, report=report, window=window, clock=clock, sleep=sleep)
    except CommunicationError as exc:
        if any(c.name.startswith("bus ") for c in report.checks):
            raise
        doc.check_buses(report, [statuses[b] for b in names if b in statuses])
        report.add("session", False, f"the buses could not be opened: {exc}",
                   exc.hint or "check the adapters with `sherpa bus status`")


def _findings(s: LinkStatus) -> list[Finding]:
    from sherpa_cli.bus.health import findings

    return findings(s)


def _render(st: AppState, report: DoctorReport) -> None:
    rows = [[c.name, c.result, c.detail] for c in report.checks]
    st.out.table("sherpa doctor", ["check", "result", "detail"], rows)
    for c in report.failed:
        st.out.line(f"{c.name}: {c.hint}")
    n = len(report.failed)
    st.out.line(f"{len(report.checks) - n - sum(c.result == 'skip' for c in report.checks)} ok, {n} failed"
                + (f", {sum(c.result == 'skip' for c in report.checks)} skipped" if any(
                    c.result == 'skip' for c in report.checks) else ""))
