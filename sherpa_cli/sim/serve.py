"""Run the simulated arm as its own process: served over python-can-remote, or on (v)CAN buses."""

from __future__ import annotations

import ipaddress
import socket
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from sherpa_cli.config.model import ArmConfig
from sherpa_cli.errors import UsageError
from sherpa_cli.sim.arm import SimArm

if TYPE_CHECKING:
    from http.server import HTTPServer


def parse_host_port(text: str, buses: int = 1) -> tuple[str, int]:
    """``HOST:PORT`` of ``--serve``; bus i is served on PORT + i, so every one of the ``buses``
    ports must be a TCP port (1..65535). Digits are ASCII (``str.isdigit`` takes any script's)."""
    host, sep, port_text = text.rpartition(":")
    if not sep or not host or not (port_text.isascii() and port_text.isdigit()):
        raise UsageError(f"--serve: '{text}' is not HOST:PORT", hint="e.g. --serve 127.0.0.1:54701")
    last = 65535 - max(buses, 1) + 1
    if len(port_text) > 5 or not 1 <= int(port_text) <= last:
        ports = f"the {buses} buses are served on PORT..PORT+{buses - 1}, " if buses > 1 else ""
        raise UsageError(f"--serve {text}: port {port_text[:12]} is out of range; {ports}so PORT must be 1..{last}",
                         hint="e.g. --serve 127.0.0.1:54701")
    return host.strip("[]"), int(port_text)


def is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def check_bind_address(host: str, allow_remote: bool) -> None:
    if not is_loopback(host) and not allow_remote:
        raise UsageError(f"--serve {host}: refusing to serve the simulated arm beyond this machine",
                         hint="bind to 127.0.0.1, or pass --allow-remote if other machines must reach it")


@dataclass
class Served:
    arm: SimArm
    servers: list[HTTPServer]  # python-can-remote's RemoteServer is one
    bus_map: dict[str, str]  # bus -> "remote:HOST:PORT"

    def stop(self) -> None:
        for server in self.servers:
            server.shutdown()
            server.server_close()
        self.arm.stop()


def serve(cfg: ArmConfig, host: str, port: int, *, persist: bool = True,
          arm_factory: Callable[..., SimArm] | None = None, event_log: str | None = None) -> Served:
    """Start the arm on private virtual channels and one python-can-remote server per bus.

    Bus i of the config is served on ``port + i``; a server forces its own virtual channel,
    so a client can reach only the simulated bus, whatever it asks for.
    """
    from can_remote import RemoteServer

    token = f"{socket.gethostname()}-{port}"
    channels = {bus: f"sherpa-serve-{token}-{bus}" for bus in cfg.buses}
    extra = {"event_log": event_log} if event_log is not None else {}
    factory: Callable[..., SimArm] = arm_factory or SimArm
    arm = factory(cfg, {b: {"interface": "virtual", "channel": c} for b, c in channels.items()},
                  persist=persist, **extra)
    arm.start()
    servers: list[HTTPServer] = []
    bus_map: dict[str, str] = {}
    try:
        for i, (bus, channel) in enumerate(channels.items()):
            try:
                server = RemoteServer(host=host, port=port + i, interface="virtual", channel=channel)
            except OSError as exc:
                raise UsageError(f"--serve {host}:{port + i} (bus {bus}): cannot listen: {exc.strerror or exc}",
                                 hint="choose another port") from exc
            threading.Thread(target=server.serve_forever, name=f"serve-{bus}", daemon=True).start()
            servers.append(server)
            bus_map[bus] = f"remote:{_url_host(host)}:{server.server_port}"
    except BaseException:
        for server in servers:
            server.shutdown()
            server.server_close()
        arm.stop()
        raise
    return Served(arm, servers, bus_map)


def _url_host(host: str) -> str:
    return f"[{host}]" if ":" in host else host


def run_on_buses(cfg: ArmConfig, endpoints: Mapping[str, Mapping[str, Any]], *, persist: bool = True,
                 event_log: str | None = None) -> SimArm:
    """The arm on real python-can interfaces (kernel vcan), as another machine would see drives."""
    return SimArm(cfg, endpoints, persist=persist, event_log=event_log).start()
