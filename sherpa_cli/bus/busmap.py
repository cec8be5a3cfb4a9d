"""``--bus-map BUS=INTERFACE:CHANNEL``: point configured buses somewhere else without editing the config.

This is how a second terminal reaches ``sherpa sim --serve`` (``remote`` interface), how a
developer uses kernel ``vcan`` (``socketcan:vcan0``), and how ``--sim`` maps every bus to an
in-process ``virtual`` channel. The result is a plain python-can configuration: no bus
type is special-cased anywhere else.
"""

from __future__ import annotations

import dataclasses
import difflib
import re
from collections.abc import Iterable, Mapping

from sherpa_cli.config.model import ArmConfig, BusConfig
from sherpa_cli.errors import UsageError

ENV_VAR = "SHERPA_BUS_MAP"
_INTERFACE_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]*")  # python-can's interface names (socketcan, pcan, remote, ...)


@dataclasses.dataclass(frozen=True)
class BusTarget:
    interface: str
    channel: str

    def __str__(self) -> str:
        return f"{self.interface}:{self.channel}"


def parse_bus_map(specs: Iterable[str]) -> dict[str, BusTarget]:
    """Parse ``can0=socketcan:vcan0`` items (several per argument, comma-separated)."""
    result: dict[str, BusTarget] = {}
    for spec in specs:
        for item in filter(None, (part.strip() for part in spec.split(","))):
            bus, sep, target = item.partition("=")
            interface, sep2, channel = target.partition(":")
            if not sep or not sep2 or not bus.strip() or not interface or not channel:
                raise UsageError(f"--bus-map: '{item}' is not BUS=INTERFACE:CHANNEL",
                                 hint="e.g. --bus-map can0=socketcan:vcan0,can1=remote:127.0.0.1:54702")
            if interface == "udp_multicast":
                # it sends out of the network interface; a sim or test must stay on loopback
                raise UsageError("--bus-map: the udp_multicast interface is not supported; "
                                 "use remote (python-can-remote) or socketcan")
            if not _INTERFACE_NAME.fullmatch(interface.strip()):
                raise UsageError(f"--bus-map: '{item}': '{interface.strip()}' is not an interface name "
                                 "(python-can's: letters, digits, _)",
                                 hint="e.g. --bus-map can0=socketcan:vcan0,can1=remote:127.0.0.1:54702")
            _check_known_interface(item, interface.strip())
            if interface.strip() == "remote":
                _check_remote_port(item, channel.strip())
            if bus.strip() in result:
                raise UsageError(f"--bus-map: bus {bus.strip()} is mapped twice ('{item}' and "
                                 f"'{bus.strip()}={result[bus.strip()]}'): map each bus once")
            result[bus.strip()] = BusTarget(interface.strip(), channel.strip())
    return result


def _check_known_interface(item: str, interface: str) -> None:
    """An interface python-can knows (its own and installed plugins): a typo is a usage error, not
    a bus that cannot open."""
    from can.interfaces import VALID_INTERFACES

    if interface not in VALID_INTERFACES:
        close = difflib.get_close_matches(interface, sorted(VALID_INTERFACES), n=1)
        raise UsageError(f"--bus-map: '{item}': python-can has no interface '{interface}'"
                         + (f"; did you mean '{close[0]}'?" if close else ""),
                         hint="interfaces: " + ", ".join(sorted(VALID_INTERFACES)))


def _check_remote_port(item: str, channel: str) -> None:
    """python-can-remote's address (HOST:PORT or ws://HOST:PORT/PATH): a port, where given, is
    1..65535 in ASCII digits, refused here instead of by the socket layer as a bus that cannot open."""
    from urllib.parse import urlparse

    try:
        port = urlparse(channel if "://" in channel else "ws://" + channel).port
    except ValueError:
        port = -1
    if port is not None and not 1 <= port <= 65535:
        raise UsageError(f"--bus-map: '{item}': the port is not a number 1..65535",
                         hint="e.g. --bus-map can0=remote:127.0.0.1:54701 (what `sherpa sim --serve` prints)")


def apply_bus_map(cfg: ArmConfig, mapping: Mapping[str, BusTarget]) -> ArmConfig:
    """A copy of ``cfg`` whose named buses use the mapped interface/channel."""
    unknown = sorted(set(mapping) - set(cfg.buses))
    if unknown:
        raise UsageError(f"--bus-map names bus(es) not in the config: {', '.join(unknown)}",
                         hint=f"configured buses: {', '.join(cfg.buses)}")
    buses = dict(cfg.buses)
    for name, target in mapping.items():
        old = buses[name]
        # options of the old interface (e.g. socketcan's fd) may not apply to the new one
        buses[name] = dataclasses.replace(old, interface=target.interface, channel=target.channel,
                                          options={})
    return dataclasses.replace(cfg, buses=buses)


def format_bus_map(mapping: Mapping[str, BusTarget]) -> str:
    return ",".join(f"{bus}={target}" for bus, target in mapping.items())


def bus_kwargs(bus: BusConfig) -> dict:
    """Keyword arguments for ``can.Bus``; what the config leaves open, python-can's own config decides."""
    kwargs: dict = dict(bus.options)
    if bus.interface is not None:
        kwargs["interface"] = bus.interface
    if bus.channel is not None:
        kwargs["channel"] = bus.channel
    if bus.bitrate is not None and bus.interface not in ("virtual", "remote"):
        kwargs["bitrate"] = bus.bitrate
    return kwargs
