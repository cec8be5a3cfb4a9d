"""A session with the arm: its buses open, drive clients on demand, and (with --sim) the simulated arm.

Commands open one session, do their work through it and close it; every exit path closes
the buses and, for the in-process simulator, saves the simulated drives' flash.
"""

from __future__ import annotations

import uuid
from contextlib import contextmanager
from typing import Any, Iterable, Iterator

from sherpa_cli.bus.busmap import BusTarget, apply_bus_map
from sherpa_cli.bus.links import BusLink, close_links, open_links
from sherpa_cli.config.model import ArmConfig
from sherpa_cli.errors import UsageError
# What a name means is decided in ops/targets.py (DriveRef lives there); ``resolve_target`` is
# its one-drive policy under the name older callers import.
from sherpa_cli.ops.targets import DriveRef
from sherpa_cli.ops.targets import single_drive as resolve_target

__all__ = ["ArmSession", "DriveRef", "resolve_target"]


class ArmSession:
    """Open buses plus a DriveClient per drive; build with :meth:`open`."""

    def __init__(self, cfg: ArmConfig, links: dict[str, BusLink], sim: Any = None) -> None:
        self.cfg = cfg
        self.links = links
        self.sim = sim  # the in-process SimArm with --sim, for tests and fault injection
        self._clients: dict[tuple[str, int], Any] = {}
        self._sdo: dict[tuple[str, int], Any] = {}

    @classmethod
    @contextmanager
    def open(cls, cfg: ArmConfig, *, sim: bool = False, buses: Iterable[str] | None = None,
             sim_factory: Any = None) -> Iterator["ArmSession"]:
        """Open the buses (default: all); with ``sim`` start the simulated arm on virtual channels first."""
        arm = None
        wire_cfg = cfg
        if sim:
            token = uuid.uuid4().hex[:8]  # virtual channels are process-wide: keep sessions apart
            targets = {name: BusTarget("virtual", f"sherpa-sim-{token}-{name}") for name in cfg.buses}
            wire_cfg = apply_bus_map(cfg, targets)
            from sherpa_cli.bus.virtual import open_can_bus
            from sherpa_cli.sim.arm import SimArm

            if sim_factory is None:
                sim_factory = SimArm.for_session
            arm = sim_factory(cfg, {name: t.channel for name, t in targets.items()})
            if isinstance(arm, SimArm) and arm.bus_factory is None:
                arm.bus_factory = open_can_bus  # the virtual interface without its per-frame deep copy
            arm.start()
        try:
            links = open_links(wire_cfg, buses)
            try:
                yield cls(wire_cfg, links, arm)
            finally:
                close_links(links)
        finally:
            if arm is not None:
                arm.stop()

    def client(self, ref: DriveRef):
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
                                      mo_confirm_timeout=p.mo_confirm_timeout, sv_blackout=p.sv_blackout)
            client = DriveClient(NetworkTransport(self.links[ref.bus].network), ref.node, name=ref.name,
                                 timeout=p.reply_timeout, retries=p.retries, settings=settings)
            self._clients[key] = client
        return client

    def sdo(self, ref: DriveRef):
        """The SDO client of a drive (ops/sdo.py DriveSdo), one per drive for the whole session."""
        from sherpa_cli.ops.sdo import DriveSdo

        sdo = self._sdo.get(ref.key)
        if sdo is None:
            if ref.bus not in self.links:
                raise UsageError(f"{ref.name}: bus {ref.bus} is not open in this session")
            sdo = DriveSdo(self.links[ref.bus].network, ref.node, label=f"{ref.name} (node {ref.node})",
                           timeout=self.cfg.protocol.sdo_timeout)
            self._sdo[ref.key] = sdo
        return sdo
