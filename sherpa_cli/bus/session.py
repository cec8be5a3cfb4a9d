"""A session with the arm: its buses open, drive clients on demand, and (with --sim) the simulated arm.

Commands open one session, do their work through it and close it; every exit path closes
the buses and stops the in-process simulated arm (which saves its drives' flash).

The simulated arm is injected: the CLI (cli/context.py) builds it and hands it over, so
this module never imports the simulator package (sim/); the session only wires its buses to the
arm's endpoints, starts it and stops it.
"""

from __future__ import annotations

import contextlib
import functools
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import replace
from typing import TYPE_CHECKING, Any, Protocol

from sherpa_cli.bus.busmap import BusTarget, apply_bus_map
from sherpa_cli.bus.held_signals import signals_held
from sherpa_cli.bus.links import BusLink, close_links, open_links

# What a name means is decided in bus/targets.py (DriveRef lives there); ``resolve_target`` is
# its one-drive policy under the name older callers import.
from sherpa_cli.bus.targets import DriveRef
from sherpa_cli.bus.targets import single_drive as resolve_target
from sherpa_cli.config.model import ArmConfig
from sherpa_cli.errors import CommunicationError, UsageError

if TYPE_CHECKING:
    from sherpa_cli.bus.sdo import DriveSdo
    from sherpa_cli.elmo.client import DriveClient

__all__ = ["ArmSession", "DriveRef", "resolve_target"]

SIM_TIMEOUT_HINT = ("the simulated arm answered too slowly (a busy machine?): raise `sim: reply_timeout` in "
                    "the config; or a fault in its `sim:` section silenced the drive")


class InProcessArm(Protocol):
    """What the session needs of an injected simulated arm (sim/arm.py's ``SimArm``)."""

    @property
    def endpoints(self) -> Mapping[str, Mapping[str, Any]]:
        """bus name -> ``can.Bus`` keyword arguments of the arm's end of that bus (interface, channel)"""
        ...

    def start(self) -> object: ...

    def stop(self) -> None: ...


class NoBusError(CommunicationError):
    """Not one of the buses a best-effort session wanted could be opened (exit 3); ``failed`` names
    each with why."""

    def __init__(self, failed: Mapping[str, CommunicationError]) -> None:
        self.failed = dict(failed)
        first = next(iter(self.failed.values()))
        super().__init__(first.message if len(self.failed) == 1 else
                         "no bus could be opened: " + "; ".join(e.message for e in self.failed.values()),
                         hint=first.hint)


class ArmSession:
    """Open buses plus a DriveClient per drive; build with :meth:`open`."""

    def __init__(self, cfg: ArmConfig, links: dict[str, BusLink], sim: InProcessArm | None = None,
                 unreachable: Mapping[str, CommunicationError] | None = None) -> None:
        self.cfg = cfg
        self.links = links
        # best effort (`sherpa stop`): the buses that could not be opened, with why
        self.unreachable: dict[str, CommunicationError] = dict(unreachable or {})
        self.sim = sim  # the injected in-process arm with --sim, for tests and fault injection
        self._clients: dict[tuple[str, int], DriveClient] = {}
        self._sdo: dict[tuple[str, int], DriveSdo] = {}
        # DriveClient keyword arguments that win over the config's (clock, sleep, timeout, retries):
        # `--sim log step` puts the clients' waits on its stepped time; set before the first client
        self.client_overrides: dict[str, Any] = {}
        # `sherpa --allow-user-program`: the preflight (bus/health.py) lets motion start while a user program runs
        self.allow_user_program = False
        # a command's own F/T limits (`--force-limit`, `force_limit=`): every motion guard of the session
        # watches the arm's F/T sensors with these, which only tighten the sensors' own (motion/force_watch.py)
        self.force_limit: float | None = None  # N
        self.torque_limit: float | None = None  # N·m
        self._request_watchers: list[Callable[[tuple[str, int]], None]] = []

    @classmethod
    @contextmanager
    def open(cls, cfg: ArmConfig, *, sim: InProcessArm | None = None,
             buses: Iterable[str] | None = None, best_effort: bool = False) -> Iterator[ArmSession]:
        """Open the buses (default: all). With ``sim`` (a simulated arm built by the caller, not
        started), start it first and point every configured bus at its endpoint; stop it last.
        ``best_effort``: a bus that cannot be opened does not keep the others closed; it is named
        in :attr:`unreachable` (and raises only if no bus at all could be opened)."""
        if sim is not None and not hasattr(sim, "endpoints"):
            raise TypeError("ArmSession.open(sim=...) takes the simulated arm itself, e.g. "
                            "SimArm.in_process(cfg) from sim/arm.py, not a flag")
        wire_cfg = cfg
        if sim is not None:
            wire_cfg = apply_bus_map(cfg, {name: BusTarget(str(kw["interface"]), str(kw["channel"]))
                                           for name, kw in sim.endpoints.items() if name in cfg.buses})
            # the simulator shares this process on a possibly loaded machine: its patient reply timeout
            wire_cfg = replace(wire_cfg, protocol=replace(wire_cfg.protocol, reply_timeout=cfg.sim_reply_timeout))
            sim.start()
        try:
            failed: dict[str, CommunicationError] | None = {} if best_effort else None
            links = open_links(wire_cfg, buses, failed=failed)
            if failed and not links:
                raise NoBusError(failed)
            session = cls(wire_cfg, links, sim, failed)
            try:
                yield session
            finally:
                for sdo in session._sdo.values():
                    with contextlib.suppress(Exception):  # its network may be gone already
                        sdo.close()
                close_links(links)
        finally:
            if sim is not None:
                with signals_held():  # its pumps and buses: all stopped, whatever signal comes
                    sim.stop()

    def open_bus(self, name: str) -> None:
        """Open one more configured bus in this session (a no-op when it is open): the motion guard's
        F/T sensor may sit on a bus the command's drives do not. Closed with the others."""
        if name in self.links:
            return
        self.links.update(open_links(self.cfg, [name]))

    def client(self, ref: DriveRef) -> DriveClient:
        """The DriveClient of a drive (one per drive: it owns the drive's one-request-at-a-time lock)."""
        from sherpa_cli.elmo.client import ClientSettings, DriveClient
        from sherpa_cli.elmo.transport import NetworkTransport

        key = (ref.bus, ref.node)
        client = self._clients.get(key)
        if client is None:
            if ref.bus not in self.links:
                raise UsageError(f"{ref.name}: bus {ref.bus} is not open in this session")
            p = self.cfg.protocol
            settings = ClientSettings(expect_set_echo=p.set_echo, query_long=p.query_long,
                                      mo_confirm_timeout=p.mo_confirm_timeout, mo_settle=p.mo_settle,
                                      sv_blackout=p.sv_blackout,
                                      **({"timeout_hint": SIM_TIMEOUT_HINT} if self.sim is not None else {}))  # type: ignore[arg-type]
            options: dict[str, Any] = {"timeout": p.reply_timeout, "retries": p.retries, **self.client_overrides}
            client = DriveClient(NetworkTransport(self.links[ref.bus].network), ref.node, name=ref.name,
                                 settings=settings, **options)
            client.on_request = functools.partial(self._request_sent, key)
            self._clients[key] = client
        return client

    def sdo(self, ref: DriveRef) -> DriveSdo:
        """The SDO client of a drive (bus/sdo.py DriveSdo), one per drive for the whole session."""
        from sherpa_cli.bus.sdo import NO_ANSWER_HINT, DriveSdo

        sdo = self._sdo.get(ref.key)
        if sdo is None:
            if ref.bus not in self.links:
                raise UsageError(f"{ref.name}: bus {ref.bus} is not open in this session")
            from sherpa_cli.bus.machine_lock import TransferLock, wire_key

            link = self.links[ref.bus]
            timeout, hint = self.cfg.protocol.sdo_timeout, NO_ANSWER_HINT
            if self.sim is not None:  # the in-process simulator answers SDO on this loaded machine too
                timeout, hint = max(timeout, self.cfg.sim_reply_timeout), SIM_TIMEOUT_HINT
            sdo = DriveSdo(link.network, ref.node, label=f"{ref.name} (node {ref.node})", timeout=timeout,
                           timeout_hint=hint, channel_lock=TransferLock(wire_key(link.config.interface, link.config.channel), ref.node))
            sdo.on_request = functools.partial(self._request_sent, ref.key)
            self._sdo[ref.key] = sdo
        return sdo

    def watch_requests(self, watcher: Callable[[tuple[str, int]], None]) -> Callable[[], None]:
        """Call ``watcher((bus, node))`` on the requesting thread before every interpreter request
        attempt and every SDO transfer of this session's drives, before a frame of it goes out;
        returns the function that stops it. The motion
        guard's sign of life: a command working through many requests (a recorder's PDO set-up, a
        restore) is alive, however slow the bus or the machine, without a check between each."""
        self._request_watchers.append(watcher)

        def stop() -> None:
            if watcher in self._request_watchers:
                self._request_watchers.remove(watcher)
        return stop

    def _request_sent(self, key: tuple[str, int]) -> None:
        for watcher in list(self._request_watchers):
            watcher(key)
