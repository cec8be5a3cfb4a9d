"""`sherpa scan`: which node ids answer on each bus, checked against the config."""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import TYPE_CHECKING

import typer

from sherpa_cli.cli.context import AppState, state
from sherpa_cli.cli.options import ApplyReset
from sherpa_cli.errors import ExitCode, UsageError
from sherpa_cli.words import plural

if TYPE_CHECKING:
    from sherpa_cli.ops.ft import SensorReading
    from sherpa_cli.ops.scan import NodeFinding, ScanReport


def scan(
    ctx: typer.Context,
    buses: list[str] | None = typer.Option(None, "--bus", metavar="BUS",
                                              help="Scan only this bus (repeat for several). Default: every bus."),
    reset: bool = typer.Option(False, "--reset", help="With --apply: first send NMT reset communication to "
                               "every node (PDOs and heartbeat settings back to their saved values; a drive that reboots loses its unsaved RAM) and collect their boot-ups. "
                               "Nothing is NMT-started. Without --apply the reset is a dry run: shown, not sent."),
    apply: ApplyReset = False,
) -> None:
    """Probe node ids 1..127 on every bus and compare what answers with the config.

    Each node is asked for 0x1000 (device type) over SDO, all buses at once; answering nodes
    are then asked for 0x1018:1 (vendor) and 0x1008 (device name). Verdicts: expected,
    missing, unexpected, duplicate id, answering slowly, no SDO answer (heard only on 0x700).
    Exit code 1 when a configured drive is missing or a node the config does not name answers.

    \b
    Examples:
      sherpa scan
      sherpa scan --bus can1 --reset --apply
    """
    from sherpa_cli.api import Arm
    from sherpa_cli.ops.ft import read_sensors

    st = state(ctx)
    cfg = st.load_config()
    selected = list(dict.fromkeys(buses)) if buses else list(cfg.buses)
    unknown = [b for b in selected if b not in cfg.buses]
    if unknown:
        raise UsageError(f"no bus '{unknown[0]}' in the config", hint=f"configured buses: {', '.join(cfg.buses)}")
    if reset and not apply:
        # a reset puts the drives' communication settings back (and may drop their RAM): a write, so a dry run unless --apply
        st.out.warn(f"dry run: --reset would send NMT reset communication to every node of "
                    f"{', '.join(selected)} (PDOs and heartbeat settings back to their saved values); not sent (add --apply)")
        reset = False
    sensors = [d for d in cfg.ft_sensors() if d.bus in selected]
    with st.session(buses=selected) as session, _progress(st, selected) as progress:
        report = Arm(session).scan(selected, reset=reset, progress=progress)
        # an F/T sensor is no CANopen node (no SDO, no node id): one request on its base id says it is there
        readings = read_sensors(session, [d for d in sensors if d.bus in session.links]) if sensors else []
    _render(st, report, readings)
    if report.bus_errors:
        first = report.bus_errors[0]
        code = getattr(first.error, "exit_code", ExitCode.BUS)
        raise typer.Exit(int(code) if code != ExitCode.PROBLEM else int(ExitCode.BUS))
    if report.problems or any(r.wrench is None for r in readings):
        raise typer.Exit(int(ExitCode.PROBLEM))


@contextmanager
def _progress(st: AppState, buses: list[str]) -> Iterator[Callable[[str, str, int, int], None] | None]:
    """A live per-bus progress line on stderr, only for a person watching a terminal."""
    if st.json_mode or not sys.stderr.isatty():
        yield None
        return
    from rich.progress import BarColumn, Progress, TextColumn

    # through the sink's stderr console so colour and NO_COLOR follow the global options
    console = st.out._console(stderr=True)
    with Progress(TextColumn("{task.fields[bus]:6}"), BarColumn(), TextColumn("{task.description}"),
                  console=console, transient=True) as bar:
        tasks = {bus: bar.add_task("waiting", total=1, bus=bus) for bus in buses}

        def update(bus: str, phase: str, done: int, total: int) -> None:
            bar.update(tasks[bus], description=f"{phase} {done}/{total}" if phase != "done" else "done",
                       completed=done, total=max(total, 1))

        yield update


def _device(n: NodeFinding) -> str:
    """Vendor (Elmo by name, others as their 0x1018:1 id) and 0x1008, in one column to fit 100 columns."""
    if n.vendor is None and n.device_name is None:
        return "-"
    from sherpa_cli.bus.canopen_names import ELMO_VENDOR_ID

    vendor = n.vendor if n.vendor_id in (None, ELMO_VENDOR_ID) else f"vendor {n.vendor}"
    return " ".join(part for part in (vendor, n.device_name) if part)


def _warn_host_id(st: AppState, report: ScanReport) -> None:
    """A device on the tool's heartbeat id would feed the drives' dead-man consumers (docs/motion.md)."""
    hosts = st.load_config().motion.host_ids
    for bus in report.buses:
        for n in bus.nodes:
            if n.node in hosts and n.answer_s is not None:
                st.out.warn(f"bus {bus.bus}: a device answers on node {n.node}, a heartbeat id of the tool "
                            "(motion.host_node_id / host_id_pool): its heartbeat would keep the drives' dead-man "
                            "from tripping; give the tool ids no device uses")


def _render(st: AppState, report: ScanReport, readings: Sequence[SensorReading] = ()) -> None:
    _warn_host_id(st, report)
    if st.json_mode:
        st.out.json({**report.as_json(), **({"ft_sensors": [r.as_json() for r in readings]} if readings else {})})
        return
    for bus in report.buses:
        if bus.error is not None:
            st.out.error(f"bus {bus.bus}: scan failed: {bus.error}")
            continue
        # NMT only when boot-ups or heartbeats said something (--reset, producers on): no empty column
        with_nmt = any(n.nmt_state for n in bus.nodes)
        rows = []
        for n in bus.nodes:
            rows.append([n.node, f"0x{n.device_type:08X}" if n.device_type is not None else "-",
                         _device(n), n.drive or "-", n.joint or "-",
                         *([n.nmt_state or "-"] if with_nmt else []), n.verdict])
        answered = sum(1 for n in bus.nodes if n.answer_s is not None)
        st.out.table(f"bus {bus.bus}: {plural(answered, 'node')} answered",
                     ["node", "device type", "device", "drive", "joint",
                      *(["NMT"] if with_nmt else []), "verdict"], rows, right=(0,))
        for n in bus.nodes:
            for note in n.notes:
                st.out.line(f"  {bus.bus}:{n.node}: {note}")
    summary = []
    if report.missing:
        summary.append(f"missing: {', '.join(report.missing)}")
    if report.unexpected:
        summary.append(f"unexpected: {', '.join(report.unexpected)}")
    if report.duplicates:
        summary.append(f"duplicate ids: {', '.join(report.duplicates)}")
    if report.slow:
        summary.append(f"answering slowly: {', '.join(report.slow)} (over {report.settings.slow_factor:g}x the bus's "
                       f"median answer time and over {report.settings.slow_floor_s * 1000:g} ms)")
    for r in readings:
        where = (f"F/T sensor {r.device} ({r.bus}, base 0x{r.base_id:03X}, replies on "
                 f"0x{r.base_id + 5:03X}/0x{r.base_id + 6:03X})")
        if r.wrench is None:
            summary.append(f"{where}: no answer: {r.problem}")
        else:
            st.out.line(f"{where}: answered, |F| {r.wrench.force:.2f} N, status {r.wrench.status}")
    if summary:
        for line in summary:
            st.out.line(line)
    elif not report.bus_errors:
        st.out.line("every configured drive answered; no unexpected node")
