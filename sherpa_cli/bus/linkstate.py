"""The state of one configured bus: what its interface reports, and nothing it does not.

:func:`read_link` takes one snapshot of a bus: through :class:`~sherpa_cli.bus.netlink.Netlink`
(SocketCAN via pyroute2, or the simulated arm's controllers with ``--sim``), else python-can's
``BusABC.state`` where the backend implements it. Every figure an interface cannot give is named in
:attr:`LinkStatus.not_reported` ("not reported by vcan"); nothing is filled in by guessing.

:func:`link_source` picks the source for a bus of an open session (the motion guard's bus watch
reads the same snapshots while it moves); :func:`bus_load` turns two snapshots' frame counters into
the share of the bit rate used.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

from sherpa_cli.bus.netlink import Netlink, NetlinkUnavailable, Pyroute2Netlink, unavailable_reason
from sherpa_cli.config.model import BusConfig

if TYPE_CHECKING:
    import can

    from sherpa_cli.bus.session import ArmSession

ACTIVE, WARNING, PASSIVE, BUS_OFF, STOPPED, DOWN = (
    "ERROR-ACTIVE", "ERROR-WARNING", "ERROR-PASSIVE", "BUS-OFF", "STOPPED", "down")
MISSING = "missing"
# bits on the bus of a standard (11-bit id) data frame besides its data bytes, without stuff bits:
# SOF 1, id 11, RTR/IDE/r0 3, DLC 4, CRC 15+1, ACK 2, EOF 7, intermission 3
FRAME_OVERHEAD_BITS = 47
FIGURES = ("state", "counters", "bitrate", "sample_point", "restart_ms", "berr_reporting", "device_stats",
           "stats", "load")


@dataclass(frozen=True)
class LinkStatus:
    """One bus as its interface reports it (None: not known; :attr:`not_reported` says why)."""

    bus: str
    interface: str | None
    channel: str | None
    source: str  # "netlink", "simulated controller", "python-can", "none"
    configured_bitrate: int | None = None
    present: bool | None = None
    up: bool | None = None
    kind: str | None = None  # the link's kind (can, vcan, ...) where netlink says
    can_state: str | None = None  # ERROR-ACTIVE ... BUS-OFF, STOPPED (a CAN controller's own state)
    tec: int | None = None
    rec: int | None = None
    bitrate: int | None = None
    sample_point: float | None = None  # 0..1
    restart_ms: int | None = None
    berr_reporting: bool | None = None
    device_stats: Mapping[str, int] | None = None
    stats: Mapping[str, int] | None = None
    load: float | None = None  # share of the bit rate used over the window, 0..1
    load_window: float | None = None
    error: str | None = None  # why the interface could not be read at all
    not_reported: Mapping[str, str] = field(default_factory=dict)  # figure -> "not reported by vcan"

    @property
    def state(self) -> str:
        """The one word for the link: missing, down, a controller state, or up (state not reported)."""
        if self.present is False:
            return MISSING
        if self.up is False:
            return DOWN
        if self.can_state is not None:
            return self.can_state
        return "up" if self.up else "unknown"

    @property
    def bitrate_mismatch(self) -> bool:
        return (self.bitrate is not None and self.configured_bitrate is not None
                and self.bitrate != self.configured_bitrate)

    def as_json(self) -> dict[str, Any]:
        return {"bus": self.bus, "interface": self.interface, "channel": self.channel, "source": self.source,
                "present": self.present, "up": self.up, "kind": self.kind, "state": self.state,
                "controller_state": self.can_state, "tec": self.tec, "rec": self.rec, "bitrate": self.bitrate,
                "configured_bitrate": self.configured_bitrate, "sample_point": self.sample_point,
                "restart_ms": self.restart_ms, "berr_reporting": self.berr_reporting,
                "device_stats": dict(self.device_stats) if self.device_stats is not None else None,
                "stats": dict(self.stats) if self.stats is not None else None,
                "load": self.load, "load_window_s": self.load_window, "error": self.error,
                "not_reported": dict(self.not_reported)}


def _who(interface: str | None, kind: str | None) -> str:
    if kind and kind != "can":
        return kind
    return interface or "python-can's config"


def from_netlink(cfg: BusConfig, figures: Mapping[str, Any] | None, *, source: str = "netlink",
                 interface: str | None = None, channel: str | None = None) -> LinkStatus:
    """A LinkStatus from the mapping :meth:`Netlink.link` returned (None: no such interface)."""
    iface = interface if interface is not None else cfg.interface
    chan = channel if channel is not None else cfg.channel
    base = LinkStatus(cfg.name, iface, chan, source, cfg.bitrate)
    if figures is None:
        return replace(base, present=False, error=f"no interface {chan}",
                       not_reported={k: f"no interface {chan}" for k in FIGURES})
    kind = figures.get("kind")
    who = _who(iface, kind)
    missing: dict[str, str] = {}

    def got(key: str, figure: str | None = None) -> Any:
        value = figures.get(key)
        if value is None and figure is not None:
            missing.setdefault(figure, f"not reported by {who}")
        return value

    sp = got("sample_point", "sample_point")
    ctrl = figures.get("ctrlmode")
    berr = ctrl.get("berr_reporting") if isinstance(ctrl, Mapping) else None
    if berr is None:
        missing.setdefault("berr_reporting", f"not reported by {who}")
    tec, rec = got("tec", "counters"), got("rec", "counters")
    status = replace(base, present=True, up=figures.get("up"), kind=kind,
                     can_state=got("can_state", "state"), tec=tec, rec=rec,
                     bitrate=got("bitrate", "bitrate"),
                     sample_point=(sp / 1000 if isinstance(sp, int | float) and sp > 1 else sp),
                     restart_ms=got("restart_ms", "restart_ms"), berr_reporting=berr,
                     device_stats=got("device_stats", "device_stats"), stats=got("stats", "stats"),
                     not_reported=missing)
    return status


def from_python_can(cfg: BusConfig, bus: can.BusABC) -> LinkStatus:
    """A LinkStatus from an open python-can bus: its ``state`` only where the backend implements it
    (BusABC's own answers ERROR_ACTIVE whatever the bus does: that would be a guess)."""
    import can

    who = cfg.interface or "python-can's config"
    missing = {k: f"not reported by {who}" for k in FIGURES if k != "load"}
    state = None
    if type(bus).state is not can.BusABC.state:
        try:
            value = bus.state
        except (NotImplementedError, can.CanError, OSError):
            value = None
        if value is not None:
            state = {can.BusState.ACTIVE: ACTIVE, can.BusState.PASSIVE: PASSIVE,
                     can.BusState.ERROR: BUS_OFF}.get(value)
            missing.pop("state", None)
    return LinkStatus(cfg.name, cfg.interface, cfg.channel, "python-can", cfg.bitrate, present=True, up=True,
                      can_state=state, not_reported=missing)


#: :attr:`LinkStatus.source` of a bus of the --sim arm: its controller is simulated in this process
SIMULATED = "simulated controller"


def source_for(cfg: BusConfig, sim: object = None) -> tuple[Netlink | None, str | None, str]:
    """(netlink, name to ask it for, source label) for one bus: the simulated arm's controller
    (``sim``: the injected arm, with --sim), pyroute2 for a SocketCAN bus, else (None, None, why not)."""
    netlink = getattr(sim, "netlink", None)  # the injected arm's controllers (None: no --sim)
    if netlink is not None:
        return netlink, cfg.name, SIMULATED
    if cfg.interface == "socketcan":
        reason = unavailable_reason()
        if reason is not None:
            return None, None, reason
        return shared_netlink(), cfg.channel, "netlink"
    return None, None, f"not reported by {cfg.interface or 'this interface'}"


def link_source(session: ArmSession, bus: str) -> tuple[Netlink | None, str | None, str]:
    """:func:`source_for` a bus of an open session."""
    return source_for(session.cfg.buses[bus], getattr(session, "sim", None))


_NETLINK: Pyroute2Netlink | None = None


def shared_netlink() -> Pyroute2Netlink:
    """One pyroute2 socket for the process (reading links is cheap; opening a socket per read is not)."""
    global _NETLINK
    if _NETLINK is None:
        _NETLINK = Pyroute2Netlink()
    return _NETLINK


def snapshot(cfg: BusConfig, netlink: Netlink | None, name: str | None, label: str,
             pycan_bus: can.BusABC | None = None) -> LinkStatus:
    """One reading of a bus from the source :func:`source_for` picked, else from an open python-can bus
    (its backend's own state, where it has one). Never raises for a bus it cannot read:
    :attr:`LinkStatus.error` and :attr:`LinkStatus.not_reported` say why."""
    if netlink is not None and name is not None:
        try:
            figures = netlink.link(name)
        except (OSError, NetlinkUnavailable) as exc:
            return LinkStatus(cfg.name, cfg.interface, cfg.channel, label, cfg.bitrate, error=str(exc),
                              not_reported={k: str(exc) for k in FIGURES})
        return from_netlink(cfg, figures, source=label)
    if pycan_bus is not None:
        status = from_python_can(cfg, pycan_bus)
        if label.startswith("netlink figures need"):
            status = replace(status, not_reported={k: label for k in status.not_reported})
        return status
    return LinkStatus(cfg.name, cfg.interface, cfg.channel, "none", cfg.bitrate, error=label,
                      not_reported={k: label for k in FIGURES})


def read_link(session: ArmSession, bus: str) -> LinkStatus:
    """One snapshot of a bus of an open session (what the preflight and the guard's bus watch read).
    With --sim the simulated controller stands in for the configured adapter, and is named like it."""
    netlink, name, label = link_source(session, bus)
    link = getattr(session, "links", {}).get(bus)
    cfg: BusConfig = session.cfg.buses[bus]
    sim_cfg = getattr(getattr(session, "sim", None), "cfg", None)
    if label == SIMULATED and sim_cfg is not None and bus in sim_cfg.buses:
        cfg = sim_cfg.buses[bus]
    return snapshot(cfg, netlink, name, label, link.bus if link is not None else None)


def bus_load(before: Mapping[str, int] | None, after: Mapping[str, int] | None, seconds: float,
             bitrate: int | None) -> float | None:
    """Share of the bit rate used between two ``stats`` snapshots: frames x 47 bits plus data bytes x 8,
    over bit rate x seconds; stuff bits are not counted, so this is a lower bound. None when a figure
    is missing."""
    if before is None or after is None or not bitrate or seconds <= 0:
        return None
    try:
        frames = (after["rx_packets"] - before["rx_packets"]) + (after["tx_packets"] - before["tx_packets"])
        data = (after["rx_bytes"] - before["rx_bytes"]) + (after["tx_bytes"] - before["tx_bytes"])
    except KeyError:
        return None
    return max(0.0, (frames * FRAME_OVERHEAD_BITS + data * 8) / (bitrate * seconds))


def frames_load(frames: int, data_bytes: int, seconds: float, bitrate: int | None) -> float | None:
    """The same from frames counted by listening (python-can): what this host received."""
    if not bitrate or seconds <= 0:
        return None
    return (frames * FRAME_OVERHEAD_BITS + data_bytes * 8) / (bitrate * seconds)
