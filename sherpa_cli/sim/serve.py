"""Run the simulated arm as its own process: served over python-can-remote, or on (v)CAN buses."""

from __future__ import annotations

import contextlib
import errno
import logging
import socket
import sys
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from sherpa_cli import netaddr
from sherpa_cli.config.model import ArmConfig
from sherpa_cli.errors import UsageError
from sherpa_cli.sim.arm import SimArm

if TYPE_CHECKING:
    from http.server import HTTPServer

log = logging.getLogger(__name__)

# how a socket says its peer is gone: a client killed, unplugged or closed without a goodbye
_GONE_ERRNOS = frozenset({errno.EPIPE, errno.ECONNRESET, errno.ECONNABORTED, errno.ENOTCONN})


def client_gone(exc: BaseException | None) -> bool:
    """Whether ``exc`` (or an exception it was raised while handling) says the client's socket is gone."""
    seen: set[int] = set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        if isinstance(exc, OSError) and (isinstance(exc, (BrokenPipeError, ConnectionError))
                                         or exc.errno in _GONE_ERRNOS):
            return True
        exc = exc.__context__
    return False


def parse_host_port(text: str, buses: int = 1) -> tuple[str, int]:
    """``HOST:PORT`` of ``--serve``; bus i is served on PORT + i (sherpa_cli/netaddr.py)."""
    return netaddr.parse_host_port(text, "--serve", example="127.0.0.1:54701", ports=buses,
                                   what=f"the {buses} buses are served on")


is_loopback = netaddr.is_loopback


def check_bind_address(host: str, allow_remote: bool) -> None:
    netaddr.check_bind(host, allow_remote, "--serve", "serve the simulated arm")


def _server_class() -> Callable[..., HTTPServer]:
    """python-can-remote's server, made quiet about clients that leave and tidy with their buses,
    through socketserver's own hooks (``handle_error``, ``process_request_thread``).

    Every client gets a python-can bus on the served channel, which python-can-remote shuts down
    only when the client's send thread ends normally: a client that went away while frames were
    flowing left it open, and python-can warned "VirtualBus was not properly shut down" at exit."""
    from can_remote import RemoteServer

    class Server(RemoteServer):
        def __init__(self, *args: Any, **kwargs: Any) -> None:
            super().__init__(*args, **kwargs)
            self.stopping = False
            self.by_thread: dict[int, Any] = {}  # handler thread -> its client's protocol (it has .bus)
            self.lock = threading.Lock()
            server = self

            class Clients(list[Any]):
                """The server's list of client protocols, noting which handler thread added each."""

                def append(self, protocol: Any) -> None:
                    with server.lock:
                        server.by_thread[threading.get_ident()] = protocol
                    super().append(protocol)

            self.clients = Clients()

        def process_request_thread(self, request: Any, client_address: Any) -> None:
            try:
                super().process_request_thread(request, client_address)
            finally:
                with self.lock:
                    protocol = self.by_thread.pop(threading.get_ident(), None)
                if protocol is not None:
                    end_client(protocol)
                    with contextlib.suppress(ValueError):
                        self.clients.remove(protocol)  # left in the list when its handler raised

        def handle_error(self, request: Any, client_address: Any) -> None:
            exc = sys.exc_info()[1]
            if client_gone(exc):
                log.warning("client %s went away", _address(client_address))
            elif not self.stopping:
                super().handle_error(request, client_address)

        def stop(self) -> None:
            self.stopping = True
            self.shutdown()
            self.server_close()
            with self.lock:
                protocols = list(self.by_thread.values())
            for protocol in protocols:
                end_client(protocol)

    return Server


def end_client(protocol: Any) -> None:
    """Stop a client's loops, then shut its bus: in that order, or its send thread would read the
    shut bus and report the error to the client in a loop."""
    protocol.running = False
    bus = getattr(protocol, "bus", None)
    if bus is not None:
        bus.shutdown()


def _address(client_address: Any) -> str:
    if isinstance(client_address, tuple) and len(client_address) >= 2:
        host, port = client_address[0], client_address[1]
        return f"[{host}]:{port}" if ":" in str(host) else f"{host}:{port}"
    return str(client_address)


def _quiet_client_threads(previous: Callable[[threading.ExceptHookArgs], Any]
                          ) -> Callable[[threading.ExceptHookArgs], Any]:
    """A ``threading.excepthook`` for serving: a client's send thread that finds the client gone ends
    without a traceback (the client's handler, or nothing for a client that said goodbye, reports it);
    anything else goes to ``previous``."""
    def hook(args: threading.ExceptHookArgs) -> None:
        if args.thread is not threading.main_thread() and client_gone(args.exc_value):
            log.debug("%s: the client is gone (%s)", getattr(args.thread, "name", "a thread"), args.exc_value)
            return
        previous(args)

    return hook


@dataclass
class Served:
    arm: SimArm
    servers: list[HTTPServer]  # python-can-remote's RemoteServer is one
    bus_map: dict[str, str]  # bus -> "remote:HOST:PORT"
    excepthook: Callable[[threading.ExceptHookArgs], Any] | None = field(default=None, repr=False)

    def stop(self) -> None:
        try:
            for server in self.servers:
                stop = getattr(server, "stop", None)
                if stop is not None:
                    stop()
                else:
                    server.shutdown()
                    server.server_close()
            self.arm.stop()
        finally:
            if self.excepthook is not None:
                threading.excepthook = self.excepthook


def serve(cfg: ArmConfig, host: str, port: int, *, persist: bool = True,
          arm_factory: Callable[..., SimArm] | None = None, event_log: str | None = None) -> Served:
    """Start the arm on private virtual channels and one python-can-remote server per bus.

    Bus i of the config is served on ``port + i``; a server forces its own virtual channel,
    so a client can reach only the simulated bus, whatever it asks for.
    """
    server_class = _server_class()

    token = f"{socket.gethostname()}-{port}"
    channels = {bus: f"sherpa-serve-{token}-{bus}" for bus in cfg.buses}
    extra = {"event_log": event_log} if event_log is not None else {}
    factory: Callable[..., SimArm] = arm_factory or SimArm
    arm = factory(cfg, {b: {"interface": "virtual", "channel": c} for b, c in channels.items()},
                  persist=persist, **extra)
    arm.start()
    servers: list[HTTPServer] = []
    bus_map: dict[str, str] = {}
    previous_hook = threading.excepthook
    threading.excepthook = _quiet_client_threads(previous_hook)
    try:
        for i, (bus, channel) in enumerate(channels.items()):
            try:
                server = server_class(host=host, port=port + i, interface="virtual", channel=channel)
            except OSError as exc:
                raise UsageError(f"--serve {host}:{port + i} (bus {bus}): cannot listen: {exc.strerror or exc}",
                                 hint="choose another port") from exc
            threading.Thread(target=server.serve_forever, name=f"serve-{bus}", daemon=True).start()
            servers.append(server)
            bus_map[bus] = f"remote:{_url_host(host)}:{server.server_port}"
    except BaseException:
        Served(arm, servers, bus_map, previous_hook).stop()
        raise
    return Served(arm, servers, bus_map, previous_hook)


def _url_host(host: str) -> str:
    return f"[{host}]" if ":" in host else host


def run_on_buses(cfg: ArmConfig, endpoints: Mapping[str, Mapping[str, Any]], *, persist: bool = True,
                 event_log: str | None = None) -> SimArm:
    """The arm on real python-can interfaces (kernel vcan), as another machine would see drives."""
    return SimArm(cfg, endpoints, persist=persist, event_log=event_log).start()
