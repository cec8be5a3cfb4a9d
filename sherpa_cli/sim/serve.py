"""Run the simulated arm as its own process: served over python-can-remote, or on (v)CAN buses."""

from __future__ import annotations

import socket
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from sherpa_cli import netaddr
from sherpa_cli.config.model import ArmConfig
from sherpa_cli.errors import UsageError
from sherpa_cli.sim.arm import SimArm

if TYPE_CHECKING:
    from http.server import HTTPServer


def parse_host_port(text: str, buses: int = 1) -> tuple[str, int]:
    """``HOST:PORT`` of ``--serve``; bus i is served on PORT + i (sherpa_cli/netaddr.py)."""
    return netaddr.parse_host_port(text, "--serve", example="127.0.0.1:54701", ports=buses,
                                   what=f"the {buses} buses are served on")


is_loopback = netaddr.is_loopback


def check_bind_address(host: str, allow_remote: bool) -> None:
    netaddr.check_bind(host, allow_remote, "--serve", "serve the simulated arm")


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
