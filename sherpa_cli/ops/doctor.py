"""`sherpa doctor`: the first command on a new laptop or arm. One row per check, pass or fail, and
for every failure the fix.

The checks, in the order a technician would walk them: Python and the packages; the config; per
bus the interface, the link, the bit rate, the controller state and the load (bus/linkstate.py,
ops/buslink.py); then, on the buses fit to talk on: the drives expected against those that answer
(ops/scan.py), their model and firmware (ops/identify.py), their heartbeats, whether another
master already heartbeats on the host's node id, user programs (PS), the joints' calibration, and
the state directory. A row whose precondition failed is skipped and says so.
"""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sherpa_cli.bus.health import findings
from sherpa_cli.bus.linkstate import SIMULATED, LinkStatus
from sherpa_cli.config.model import ArmConfig, JointConfig
from sherpa_cli.words import plural

if TYPE_CHECKING:
    from sherpa_cli.bus.session import ArmSession

OK, FAIL, SKIP = "ok", "FAIL", "skip"
PACKAGES = ("sherpa-cli", "python-can", "canopen", "typer", "rich", "pyroute2")
MIN_PYTHON = (3, 11)
DEFAULT_WINDOW = 1.0  # s listened for heartbeats on the host's node id (and the bus load)
HIGH_LOAD = 0.7  # a bus this busy leaves no room for the interpreter's round trips


@dataclass(frozen=True)
class Check:
    name: str
    result: str  # ok | FAIL | skip
    detail: str
    hint: str | None = None

    def as_json(self) -> dict[str, Any]:
        return {"check": self.name, "result": self.result.lower(), "detail": self.detail, "hint": self.hint}


@dataclass
class DoctorReport:
    checks: list[Check] = field(default_factory=list)

    @property
    def failed(self) -> list[Check]:
        return [c for c in self.checks if c.result == FAIL]

    def add(self, name: str, ok: bool, detail: str, hint: str | None = None) -> None:
        self.checks.append(Check(name, OK if ok else FAIL, detail, None if ok else hint))

    def skip(self, name: str, why: str) -> None:
        self.checks.append(Check(name, SKIP, why))

    def as_json(self) -> dict[str, Any]:
        return {"ok": not self.failed, "checks": [c.as_json() for c in self.checks]}


# -- environment ------------------------------------------------------------------------------------

def package_versions() -> dict[str, str | None]:
    """Python and the installed version of each package (None: not installed)."""
    from importlib import metadata

    out: dict[str, str | None] = {"python": ".".join(map(str, sys.version_info[:3]))}
    for name in PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


def check_environment(report: DoctorReport, versions: Mapping[str, str | None], *, linux: bool) -> None:
    py = versions.get("python") or "?"
    parts = tuple(int(p) for p in py.split(".")[:2] if p.isdigit())
    report.add("python", parts >= MIN_PYTHON, f"Python {py}",
               f"sherpa-cli needs Python {'.'.join(map(str, MIN_PYTHON))} or newer")
    needed = [p for p in PACKAGES if p != "pyroute2" or linux]
    missing = [p for p in needed if not versions.get(p)]
    shown = ", ".join(f"{p} {versions[p]}" for p in PACKAGES if versions.get(p))
    report.add("packages", not missing, shown if not missing else f"missing: {', '.join(missing)}",
               "reinstall: pip install -e . (or pip install sherpa-cli)")


# -- buses ----------------------------------------------------------------------------------------

def check_buses(report: DoctorReport, statuses: Sequence[LinkStatus]) -> list[str]:
    """Five rows per bus; returns the buses fit to talk on (present, up, not bus-off or stopped).

    A bus of the --sim arm is named like the configured adapter, but its link, bit rate, state and
    load are the simulated controller's: its rows say so, lest they read as the kernel's."""
    usable = []
    for s in statuses:
        found = {f.problem: f for f in findings(s)}
        who = f"bus {s.bus}"
        where = f"{s.interface or 'python-can config'}:{s.channel or '-'}"
        simulated = s.source == SIMULATED
        if simulated:
            where += " (simulated in this process)"

        def said(text: str, simulated: bool = simulated) -> str:
            return f"simulated: {text}" if simulated else text

        if s.error and s.present is None:
            report.add(f"{who} interface", False, f"{where}: {s.error}",
                       "on Linux install pyroute2 (a dependency of sherpa-cli); see docs/bus.md")
            for row in ("link", "bit rate", "state", "load"):
                report.skip(f"{who} {row}", "the interface could not be read")
            continue
        if "missing" in found:
            report.add(f"{who} interface", False, f"{where}: {found['missing'].text}", found["missing"].hint)
            for row in ("link", "bit rate", "state", "load"):
                report.skip(f"{who} {row}", "no interface")
            continue
        report.add(f"{who} interface", True, where + (f" ({s.kind})" if s.kind and s.kind != "can" else ""))
        if "down" in found:
            report.add(f"{who} link", False, said(found["down"].text), found["down"].hint)
            for row in ("bit rate", "state", "load"):
                report.skip(f"{who} {row}", "the link is down")
            continue
        report.add(f"{who} link", True, said("up" if s.up else "open (the interface reports no link flag)"))
        if "bitrate" in found:
            report.add(f"{who} bit rate", False, said(found["bitrate"].text), found["bitrate"].hint)
        elif s.bitrate is not None:
            report.add(f"{who} bit rate", True, said(f"{s.bitrate} as configured" if s.configured_bitrate else
                                                     f"{s.bitrate} (the config names none)"))
        else:
            report.add(f"{who} bit rate", True, s.not_reported.get("bitrate", "not reported"))
        bad = [f for k, f in found.items() if k in ("bus-off", "error-passive", "stopped")]
        if bad:
            report.add(f"{who} state", False, said(bad[0].text), bad[0].hint)
        elif s.can_state is not None:
            counters = f" (TEC {s.tec}, REC {s.rec})" if s.tec is not None else ""
            report.add(f"{who} state", True, said(s.can_state + counters))
        else:
            report.add(f"{who} state", True, s.not_reported.get("state", "not reported"))
        if s.load is None:
            report.add(f"{who} load", True, s.not_reported.get("load", "not measured"))
        else:
            report.add(f"{who} load", s.load < HIGH_LOAD, said(f"{s.load * 100:.1f} % over {s.load_window:g} s"),
                       "a node is flooding the bus: `sherpa log capture` shows which ids")
        if not any(k in found for k in ("bus-off", "stopped")):
            usable.append(s.bus)
    return usable


# -- drives -----------------------------------------------------------------------------------------

def check_drives(report: DoctorReport, session: ArmSession, buses: Sequence[str], *, window: float = DEFAULT_WINDOW,
                 clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep) -> None:
    """Drives, firmware/model, heartbeats, host node id, user programs, calibration (buses: those fit)."""
    from sherpa_cli.bus.targets import DriveRef
    from sherpa_cli.elmo.protocol import HEARTBEAT_BASE
    from sherpa_cli.elmo.userprog import describe_ps, program_running, read_ps
    from sherpa_cli.motion.calibration import read_calibration
    from sherpa_cli.ops.identify import find_mismatches, identify
    from sherpa_cli.ops.scan import DUPLICATE, MISSING, NO_SDO, UNEXPECTED, scan

    cfg: ArmConfig = session.cfg
    names = ("drives", "firmware/model", "heartbeats", "host node id", "user programs", "calibration")
    if not buses:
        for row in names:
            report.skip(row, "no bus fit to talk on")
        return
    hosts = cfg.motion.host_ids  # every id a sherpa motion command may send its dead-man heartbeat as
    heard: dict[str, set[int]] = {}

    def on_host_beat(bus: str, hid: int) -> Callable[[int, bytes, float], None]:
        return lambda can_id, data, ts: heard.setdefault(bus, set()).add(hid)

    subs = [(session.links[b].network, HEARTBEAT_BASE + hid, on_host_beat(b, hid)) for b in buses for hid in hosts]
    start = clock()
    for network, can_id, cb in subs:
        network.subscribe(can_id, cb)
    try:
        result = scan(session, buses)
        left = window - (clock() - start)
        if left > 0:
            sleep(left)
    finally:
        for network, can_id, cb in subs:
            with contextlib.suppress(KeyError, ValueError):
                network.unsubscribe(can_id, cb)
    configured = {d.name for d in cfg.drives.values() if d.bus in buses}
    found: list[str] = []
    problems: list[str] = []
    beats: dict[str, str] = {}
    for bus_scan in result.buses:
        if bus_scan.error is not None:
            problems.append(f"{bus_scan.bus}: {bus_scan.error}")
            continue
        for n in bus_scan.nodes:
            if n.node in hosts and n.drive is None:
                continue  # the host id row says it
            if n.verdict in (MISSING, NO_SDO):
                problems.append(f"{n.drive} ({bus_scan.bus}:{n.node}) {n.verdict}")
            elif n.verdict in (UNEXPECTED, DUPLICATE):
                problems.append(f"node {n.node} on {bus_scan.bus}: {n.verdict}")
            if n.drive is not None and n.verdict not in (MISSING, NO_SDO):
                found.append(n.drive)
                if n.nmt_state:
                    beats[n.drive] = n.nmt_state
    skipped = sorted(d.name for d in cfg.drives.values() if d.bus not in buses)
    detail = f"{len(found)} of {len(configured)} found" + (f" ({len(skipped)} on unusable buses)" if skipped else "")
    report.add("drives", not problems, detail if not problems else "; ".join(problems),
               "check power and wiring of the missing drives, and their node ids (`sherpa scan`)")
    if not found:
        for row in names[1:]:
            report.skip(row, "no drive answered")
        return
    ident = identify(session, [d for d in cfg.drives if d in found])
    mism = find_mismatches(cfg, ident.drives)
    unread = [d.drive for d in ident.drives if d.error]
    firmwares = sorted({str(d.identity.get("software_version")) for d in ident.drives
                        if d.error is None and d.identity.get("software_version") is not None})
    text = "; ".join(f"{d}: {'; '.join(f)}" for d, f in mism.items())
    if unread:
        text = "; ".join(filter(None, [text, "identity unreadable: " + ", ".join(unread)]))
    report.add("firmware/model", not mism and not unread,
               text or f"{plural(len(found), 'drive')} as configured; firmware {', '.join(firmwares) or 'not reported'}",
               "a replaced drive with other firmware or model: check it with `sherpa identify`, correct the "
               "config's model or update the drive")
    if beats:
        states = sorted(set(beats.values()))
        report.add("heartbeats", True, f"{len(beats)} of {plural(len(found), 'drive')} heard: {', '.join(states)}")
    else:
        report.add("heartbeats", True, "no drive sends a heartbeat (0x1017 = 0, the default); "
                   "moving commands watch the drives themselves")
    taken = sorted(heard)
    ids = ", ".join(map(str, hosts))
    def who(bus: str, hid: int) -> str:
        from sherpa_cli.bus.machine_lock import MachineLock, wire_key

        link = session.links[bus]
        pid = MachineLock(wire_key(link.config.interface, link.config.channel), f"host{hid}").holder()
        return (f"{hid} (sherpa" + (f" pid {pid}" if pid else "") + " on this machine)" if pid is not None
                else f"{hid} (not a sherpa command of this machine: another host or tool)")

    report.add("host node id", not taken, f"{ids}: free ({window:g} s listened)"
               if not taken else "; ".join(f"{bus}: heartbeats on host id(s) "
                                          + ", ".join(who(bus, hid) for hid in sorted(heard[bus])) for bus in taken),
               "another master (a second sherpa moving drives, a ROS node) uses a host id: stop it, or give "
               "motion.host_node_id / host_id_pool ids no other node uses")
    refs = {d: DriveRef(d, cfg.drives[d].bus, cfg.drives[d].node, cfg.drives[d]) for d in found}
    running, unknown = [], []
    for d, ref in refs.items():
        ps = read_ps(session.client(ref))
        state = program_running(ps)
        if state:
            running.append(f"{d} (PS={ps})")
        elif state is None:
            unknown.append(f"{d}: {describe_ps(ps)}")
    report.add("user programs", not running,
               "running on " + ", ".join(running) if running else
               (f"none running; {'; '.join(unknown)}" if unknown else f"none running ({plural(len(refs), 'drive')})"),
               "stop the user program (e.g. in Elmo Composer): SV is refused while it runs, and it fights "
               "moving commands (`--allow-user-program` lets them run anyway)")
    joints = [j for j in cfg.joints.values()
              if all(d in refs for d in _joint_drives(cfg, j))]
    try:
        cals = [read_calibration(cfg, j, lambda d: session.client(refs[d])) for j in joints]
    except Exception as exc:  # noqa: BLE001 - a row, not a crash: the reading failed, say how
        report.add("calibration", False, f"not readable: {exc}", "check the drives with `sherpa monitor --once`")
    else:
        homed = [c.joint for c in cals if c.calibrated]
        report.add("calibration", True, f"{len(homed)} of {plural(len(cals), 'joint')} calibrated"
                   + ("" if len(homed) == len(cals) else " (`sherpa home` before position moves)"))


def _joint_drives(cfg: ArmConfig, joint: JointConfig) -> tuple[str, ...]:
    from sherpa_cli.motion.calibration import joint_drives

    return joint_drives(cfg, joint)


# -- state directory --------------------------------------------------------------------------------

def shown_path(path: Path) -> str:
    """The state directory as the user set it: $XDG_STATE_HOME/..., ~/..., else as it is."""
    xdg = os.environ.get("XDG_STATE_HOME")
    for base, name in ((xdg, "$XDG_STATE_HOME"), (str(Path.home()), "~")):
        if base and path.is_relative_to(base):
            return f"{name}/{path.relative_to(base)}"
    return str(path)


def check_state_dir(report: DoctorReport, path: Path) -> None:
    shown = shown_path(path)
    try:
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path, prefix=".doctor-", delete=True):
            pass
    except OSError as exc:
        report.add("state directory", False, f"{shown}: not writable ({exc.strerror or exc})",
                   f"make it writable (chown/chmod {path}) or set XDG_STATE_HOME to a writable directory")
        return
    if not os.access(path, os.W_OK):
        report.add("state directory", False, f"{shown}: not writable",
                   "make it writable or set XDG_STATE_HOME to a writable directory")
        return
    report.add("state directory", True, f"{shown} writable")
