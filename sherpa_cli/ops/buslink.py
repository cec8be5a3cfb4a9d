"""`sherpa bus status`, `bus up`, `bus down`: the configured buses' links, read and set through netlink.

Status reads every bus twice, a window apart, for the load: SocketCAN through pyroute2 (no session,
so a bus that is down or missing is still shown), the simulated controllers with ``--sim``, other
interfaces through an open python-can bus (its own ``state`` where the backend has one, the load
from the frames this host received). Up and down set what the seed's bring-up (Appendix D.3 step 1)
sets by hand: the bit rate from the config, restart-ms, berr-reporting on, the link up. Without
CAP_NET_ADMIN they change nothing and say which ``ip link`` commands to run as root.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from contextlib import nullcontext
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

from sherpa_cli.bus.errwatch import watching
from sherpa_cli.bus.linkstate import LinkStatus, bus_load, frames_load, snapshot, source_for
from sherpa_cli.bus.netlink import Netlink, NetlinkUnavailable
from sherpa_cli.config.model import ArmConfig, BusConfig
from sherpa_cli.errors import CommunicationError, PrivilegeError, UsageError

if TYPE_CHECKING:
    from sherpa_cli.bus.session import ArmSession

DEFAULT_RESTART_MS = 100
DEFAULT_WINDOW = 0.5  # s over which `bus status` measures the load


def select_buses(cfg: ArmConfig, names: Sequence[str] | None) -> list[str]:
    """The named buses (default: all, in config order); an unknown name is a usage error."""
    if not names:
        return list(cfg.buses)
    import difflib

    out = []
    for name in names:
        if name not in cfg.buses:
            close = difflib.get_close_matches(name, list(cfg.buses), n=1)
            raise UsageError(f"unknown bus '{name}'" + (f"; did you mean '{close[0]}'?" if close else ""),
                             hint="configured buses: " + ", ".join(cfg.buses))
        if name not in out:
            out.append(name)
    return out


def status(cfg: ArmConfig, names: Sequence[str], *, session: ArmSession | None = None, window: float = DEFAULT_WINDOW,
           sleep: Callable[[float], None] = time.sleep) -> list[LinkStatus]:
    """Every named bus: a snapshot, then another ``window`` seconds later for the load.

    ``session``: an open session holding the buses that are not read through netlink (and the
    simulated arm with --sim); None: every bus is read through netlink alone."""
    sim = getattr(session, "sim", None)
    sources = {b: source_for(cfg.buses[b], sim) for b in names}
    links = getattr(session, "links", {}) if session is not None else {}

    def take(bus: str) -> LinkStatus:
        netlink, name, label = sources[bus]
        link = links.get(bus)
        return snapshot(cfg.buses[bus], netlink, name, label, link.bus if link is not None else None)

    first = {b: take(b) for b in names}
    listened = [b for b in names if first[b].stats is None and b in links]
    if window <= 0:
        return [replace(first[b], not_reported={**first[b].not_reported, "load": "no window (--window 0)"})
                for b in names]
    # listened is empty without a session (no links)
    with watching(session, listened) if session is not None and listened else nullcontext() as watch:
        sleep(window)
        second = {b: take(b) for b in names}
        traffic = {b: watch.traffic(b) for b in listened} if watch is not None else {}
    out = []
    for b in names:
        s = second[b]
        load = bus_load(first[b].stats, s.stats, window, s.bitrate or cfg.buses[b].bitrate)
        missing = dict(s.not_reported)
        if load is None and b in traffic:
            frames, data = traffic[b]
            load = frames_load(frames, data, window, cfg.buses[b].bitrate)
            if load is None:
                missing["load"] = "no bit rate in the config to compare the traffic with"
        if load is not None:
            missing.pop("load", None)
        elif "load" not in missing:
            missing["load"] = missing.get("stats", "no frame counters")
        out.append(replace(s, load=load, load_window=window if load is not None else None, not_reported=missing))
    return out


# -- up / down ------------------------------------------------------------------------------------

@dataclass
class LinkChange:
    """What `bus up` / `bus down` did to one bus, and what the interface could not take."""

    bus: str
    channel: str | None
    kind: str | None = None
    done: list[str] = field(default_factory=list)
    not_taken: list[str] = field(default_factory=list)  # settings the interface has no place for (vcan)
    commands: list[str] = field(default_factory=list)  # the `ip link` equivalent

    def as_json(self) -> dict[str, Any]:
        return {"bus": self.bus, "channel": self.channel, "kind": self.kind, "done": self.done,
                "not_taken": self.not_taken, "ip_commands": self.commands}


def ip_commands(channel: str, *, bitrate: int | None, restart_ms: int | None, berr: bool, up: bool,
                can: bool = True) -> list[str]:
    """The root commands that do what `bus up` / `bus down` do (iproute2 syntax)."""
    if not up:
        return [f"ip link set {channel} down"]
    cmds = [f"ip link set {channel} down"]
    if can:
        settings = " ".join(x for x in (
            f"bitrate {bitrate}" if bitrate else "", f"restart-ms {restart_ms}" if restart_ms is not None else "",
            f"berr-reporting {'on' if berr else 'off'}") if x)
        cmds.append(f"ip link set {channel} type can {settings}")
    cmds.append(f"ip link set {channel} up")
    return cmds


def _require_socketcan(cfg: BusConfig, sim: object) -> str:
    if sim is not None:
        return cfg.name
    if cfg.interface != "socketcan" or not cfg.channel:
        raise UsageError(f"bus {cfg.name} uses interface {cfg.interface or '(python-can config)'}: bus up/down "
                         "set SocketCAN links only", hint="bring other adapters up with their own tools")
    return cfg.channel


def _privilege_error(changes: list[LinkChange], what: str) -> PrivilegeError:
    cmds = [c for ch in changes for c in ch.commands]
    return PrivilegeError(f"{what} needs CAP_NET_ADMIN (changing a network link); this process lacks it, "
                          "nothing was changed. As root run:\n  " + "\n  ".join(cmds),
                          hint="run those commands with sudo, or run sherpa as root")


def netlink_for(cfg: BusConfig, sim: object) -> Netlink:
    netlink, _name, label = source_for(cfg, sim)
    if netlink is None:
        raise NetlinkUnavailable(f"bus {cfg.name}: {label}")
    return netlink


def bring_up(cfg: ArmConfig, names: Sequence[str], *, bitrate: int | None = None,
             restart_ms: int = DEFAULT_RESTART_MS, berr_reporting: bool = True, sim: object = None,
             netlink: Netlink | None = None) -> list[LinkChange]:
    """Set each named bus's CAN link: down, bit rate (``bitrate`` or the config's), restart-ms,
    berr-reporting, up. A vcan link takes none of the CAN settings: it is only brought up, and
    :attr:`LinkChange.not_taken` says so. PermissionError -> PrivilegeError naming the commands."""
    plans: list[tuple[BusConfig, str, Netlink, Mapping[str, Any], int | None]] = []
    for name in names:
        bus = cfg.buses[name]
        channel = _require_socketcan(bus, sim)
        rate = bitrate if bitrate is not None else bus.bitrate
        nl = netlink if netlink is not None else netlink_for(bus, sim)
        figures = _read(nl, channel, bus)
        if figures.get("kind") == "can" and not rate:
            raise UsageError(f"bus {name} has no bitrate in the config", hint=f"give --bitrate, or set buses.{name}.bitrate")
        plans.append((bus, channel, nl, figures, rate))
    changes = []
    for bus, channel, _nl, figures, rate in plans:
        is_can = figures.get("kind") == "can"
        change = LinkChange(bus.name, bus.channel, figures.get("kind"))
        change.commands = ip_commands(bus.channel or channel, bitrate=rate, restart_ms=restart_ms,
                                      berr=berr_reporting, up=True, can=is_can)
        if not is_can:
            kind = change.kind or "this interface"
            change.not_taken = [f"bit rate ({rate} in the config)" if rate else "bit rate", "restart-ms",
                                "berr-reporting"]
            change.not_taken = [f"{x}: {kind} has no CAN controller" for x in change.not_taken]
        changes.append(change)
    try:
        for (_bus, channel, nl, figures, rate), change in zip(plans, changes, strict=True):
            if change.kind == "can":
                if figures.get("up"):
                    nl.set_link(channel, up=False)
                    change.done.append("link down")
                nl.set_link(channel, bitrate=rate, restart_ms=restart_ms, berr_reporting=berr_reporting)
                change.done.append(f"bit rate {rate}, restart-ms {restart_ms}, "
                                   f"berr-reporting {'on' if berr_reporting else 'off'}")
            nl.set_link(channel, up=True)
            change.done.append("link up")
    except PermissionError as exc:
        if any(ch.done for ch in changes):
            raise CommunicationError(f"bus up: permission refused half-way ({exc}); done so far: "
                                     + "; ".join(f"{ch.bus}: {', '.join(ch.done)}" for ch in changes if ch.done)) from exc
        raise _privilege_error(changes, "bus up") from exc
    except OSError as exc:
        raise CommunicationError(f"bus up: the kernel refused: {exc}",
                                 hint="check `ip -details link show` and docs/bus.md") from exc
    return changes


def bring_down(cfg: ArmConfig, names: Sequence[str], *, sim: object = None,
               netlink: Netlink | None = None) -> list[LinkChange]:
    """Set each named bus's link down."""
    plans = []
    for name in names:
        bus = cfg.buses[name]
        channel = _require_socketcan(bus, sim)
        nl = netlink if netlink is not None else netlink_for(bus, sim)
        figures = _read(nl, channel, bus)
        change = LinkChange(name, bus.channel, figures.get("kind"),
                            commands=ip_commands(bus.channel or channel, bitrate=None, restart_ms=None, berr=False,
                                                 up=False))
        plans.append((channel, nl, change))
    try:
        for channel, nl, change in plans:
            nl.set_link(channel, up=False)
            change.done.append("link down")
    except PermissionError as exc:
        raise _privilege_error([c for _, _, c in plans], "bus down") from exc
    except OSError as exc:
        raise CommunicationError(f"bus down: the kernel refused: {exc}") from exc
    return [c for _, _, c in plans]


def _read(nl: Netlink, channel: str, bus: BusConfig) -> Mapping[str, Any]:
    try:
        figures = nl.link(channel)
    except OSError as exc:
        raise CommunicationError(f"bus {bus.name}: cannot read link {channel}: {exc}") from exc
    if figures is None:
        raise CommunicationError(f"bus {bus.name}: no interface {channel}",
                                 hint=f"plug in the adapter (a USB adapter shows in `ip link` as {channel} once "
                                 "its driver is loaded); for a test bus: modprobe vcan; "
                                 f"ip link add dev {channel} type vcan")
    return figures
