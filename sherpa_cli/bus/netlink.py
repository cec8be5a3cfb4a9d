"""The link of a SocketCAN interface over netlink (pyroute2), behind a small seam of our own.

:class:`Netlink` is the seam: ``link(name)`` reads one interface as a plain mapping, ``set_link``
changes it. :class:`Pyroute2Netlink` is the real one (pyroute2's documented ``IPRoute`` calls:
``link_lookup``, ``link('get')``, ``link('set', kind='can', can_bittiming=...)``, as in its
examples/iproute/socketcan.py); the simulated arm offers the same two methods for its buses, and
tests fake them. Reading needs no privilege; setting needs CAP_NET_ADMIN (a PermissionError).

The mapping ``link()`` returns (keys absent or None: the interface does not report it):

- ``kind``: "can", "vcan", "vxcan", ... (IFLA_INFO_KIND); ``up``: the administrative flag IFF_UP;
  ``operstate``: "UP", "DOWN", "UNKNOWN", ...
- ``can_state``: "ERROR-ACTIVE", "ERROR-WARNING", "ERROR-PASSIVE", "BUS-OFF", "STOPPED", "SLEEPING"
- ``tec``, ``rec``: the error counters; ``bitrate``, ``sample_point`` (per mille, as the kernel
  gives it), ``clock`` (Hz); ``restart_ms``; ``ctrlmode``: {"berr_reporting": bool, "listen_only":
  bool, "one_shot": bool, "loopback": bool, ...}
- ``device_stats``: the kernel's CAN counters {"bus_error", "error_warning", "error_passive",
  "bus_off", "arbitration_lost", "restarts"} (IFLA_INFO_XSTATS, struct can_device_stats)
- ``stats``: {"rx_packets", "tx_packets", "rx_bytes", "tx_bytes", "rx_errors", "tx_errors",
  "rx_dropped", "tx_dropped"} (IFLA_STATS64)
"""

from __future__ import annotations

import os
import struct
import sys
from collections.abc import Mapping
from typing import Any, Protocol

from sherpa_cli.errors import CommunicationError

# struct can_device_stats (include/uapi/linux/can/netlink.h), six u32 in this order
DEVICE_STATS = ("bus_error", "error_warning", "error_passive", "bus_off", "arbitration_lost", "restarts")
STATS = ("rx_packets", "tx_packets", "rx_bytes", "tx_bytes", "rx_errors", "tx_errors", "rx_dropped", "tx_dropped")
IFF_UP = 0x1
CAN_STATES = ("ERROR-ACTIVE", "ERROR-WARNING", "ERROR-PASSIVE", "BUS-OFF", "STOPPED", "SLEEPING")


class NetlinkUnavailable(CommunicationError):
    """Netlink cannot be read here: not Linux, or pyroute2 is not installed (exit 3)."""


class Netlink(Protocol):
    """Read and change network links (the seam: pyroute2, the simulated arm's buses, test fakes)."""

    def link(self, name: str) -> Mapping[str, Any] | None:
        """The interface's figures (module docstring), or None when there is no such interface."""
        ...

    def set_link(self, name: str, *, up: bool | None = None, bitrate: int | None = None,
                 restart_ms: int | None = None, berr_reporting: bool | None = None) -> None:
        """Change the interface: CAN settings (the link must be down) and/or the up flag. Raises
        PermissionError without CAP_NET_ADMIN, OSError when the kernel refuses (e.g. a bit rate on vcan)."""
        ...


def unavailable_reason() -> str | None:
    """Why netlink cannot be read on this machine, or None when it can."""
    if not sys.platform.startswith("linux"):
        return f"netlink figures need Linux (this is {sys.platform})"
    try:
        import pyroute2  # noqa: F401
    except ImportError:
        return "netlink figures need pyroute2 (pip install pyroute2)"
    return None


def _hex_bytes(value: object) -> bytes:
    """pyroute2 gives a 'hex' NLA as text like '01:00:00:00'; accept bytes too."""
    if isinstance(value, bytes | bytearray):
        return bytes(value)
    if isinstance(value, str):
        text = value.replace(":", "").replace(" ", "")
        try:
            return bytes.fromhex(text)
        except ValueError:
            return b""
    return b""


def parse_device_stats(raw: object) -> dict[str, int] | None:
    """struct can_device_stats (six u32, native byte order) from IFLA_INFO_XSTATS."""
    data = _hex_bytes(raw)
    if len(data) < 4 * len(DEVICE_STATS):
        return None
    return dict(zip(DEVICE_STATS, struct.unpack(f"={len(DEVICE_STATS)}I", data[:4 * len(DEVICE_STATS)]), strict=True))


def _state_name(value: object) -> str | None:
    if value is None:
        return None
    if isinstance(value, int):
        return CAN_STATES[value] if 0 <= value < len(CAN_STATES) else f"state {value}"
    return str(value).replace("_", "-").upper()


class Pyroute2Netlink:
    """:class:`Netlink` over pyroute2's ``IPRoute`` (Linux). One netlink socket, opened on first use."""

    def __init__(self) -> None:
        reason = unavailable_reason()
        if reason is not None:
            raise NetlinkUnavailable(reason)
        self._ipr: Any = None

    def _route(self) -> Any:
        if self._ipr is None:
            from pyroute2 import IPRoute

            self._ipr = IPRoute()
        return self._ipr

    def close(self) -> None:
        if self._ipr is not None:
            self._ipr.close()
            self._ipr = None

    def _index(self, name: str) -> int | None:
        found = self._route().link_lookup(ifname=name)
        return int(found[0]) if found else None

    def link(self, name: str) -> Mapping[str, Any] | None:
        index = self._index(name)
        if index is None:
            return None
        msg = self._route().link("get", index=index)[0]
        return decode_link(msg)

    def set_link(self, name: str, *, up: bool | None = None, bitrate: int | None = None,
                 restart_ms: int | None = None, berr_reporting: bool | None = None) -> None:
        from pyroute2.netlink.exceptions import NetlinkError

        index = self._index(name)
        if index is None:
            raise FileNotFoundError(f"no interface {name}")
        route = self._route()
        try:
            can: dict[str, Any] = {}
            if bitrate is not None:
                can["can_bittiming"] = {"bitrate": int(bitrate)}
            if restart_ms is not None:
                can["can_restart_ms"] = int(restart_ms)
            if berr_reporting is not None:
                can["can_ctrlmode"] = {"berr_reporting": "on" if berr_reporting else "off"}
            if can:
                route.link("set", index=index, kind="can", **can)
            if up is not None:
                route.link("set", index=index, state="up" if up else "down")
        except NetlinkError as exc:
            code = int(getattr(exc, "code", 0) or 0)
            # OSError(errno, text) builds the matching subclass: EPERM -> PermissionError
            raise OSError(code, os.strerror(code) if code else str(exc)) from exc


def decode_link(msg: Any) -> dict[str, Any]:
    """The mapping of :class:`Netlink` from one pyroute2 ifinfmsg (its documented ``get``/``get_attr``)."""
    out: dict[str, Any] = {}
    flags = msg.get("flags")
    out["up"] = bool(int(flags) & IFF_UP) if flags is not None else None
    out["operstate"] = msg.get_attr("IFLA_OPERSTATE")
    stats = msg.get_attr("IFLA_STATS64") or msg.get_attr("IFLA_STATS")
    if stats is not None:
        out["stats"] = {k: int(stats[k]) for k in STATS if k in stats}
    info = msg.get_attr("IFLA_LINKINFO")
    if info is None:
        out["kind"] = None
        return out
    out["kind"] = info.get_attr("IFLA_INFO_KIND")
    xstats = info.get_attr("IFLA_INFO_XSTATS")
    if xstats is not None:
        out["device_stats"] = parse_device_stats(xstats)
    data = info.get_attr("IFLA_INFO_DATA")
    if data is None or out["kind"] != "can":
        return out
    out["can_state"] = _state_name(data.get_attr("IFLA_CAN_STATE"))
    berr = data.get_attr("IFLA_CAN_BERR_COUNTER")
    if berr is not None:
        out["tec"], out["rec"] = int(berr["txerr"]), int(berr["rxerr"])
    timing = data.get_attr("IFLA_CAN_BITTIMING")
    if timing is not None:
        out["bitrate"] = int(timing["bitrate"]) or None
        out["sample_point"] = int(timing["sample_point"]) or None
    out["clock"] = data.get_attr("IFLA_CAN_CLOCK")
    out["restart_ms"] = data.get_attr("IFLA_CAN_RESTART_MS")
    mode = data.get_attr("IFLA_CAN_CTRLMODE")
    if mode is not None:
        out["ctrlmode"] = {k: v == "on" for k, v in mode.items() if isinstance(v, str) and v in ("on", "off")}
    return out
