"""A session with the arm: its buses open, drive clients on demand, and (with --sim) the simulated arm.

Commands open one session, do their work through it and close it; every exit path closes
the buses and, for the in-process simulator, saves the simulated drives' flash.
"""

from __future__ import annotations

import difflib
import uuid
from contextlib import contextmanager
from dataclasses import dataclass, replace
from typing import Any, Iterable, Iterator

from sherpa_cli.bus.busmap import BusTarget, apply_bus_map
from sherpa_cli.bus.links import BusLink, close_links, open_links
from sherpa_cli.config.model import ArmConfig, DriveConfig
from sherpa_cli.errors import UsageError


SIM_TIMEOUT_HINT = ("the simulated arm answered too slowly (a busy machine?): raise `sim: reply_timeout` in "
                    "the config; or a fault in its `sim:` section silenced the drive")


@dataclass(frozen=True)
class DriveRef:
    """A drive addressed by the user: configured (``config`` set) or ad hoc as BUS:NODE."""

    name: str
    bus: str
    node: int
    config: DriveConfig | None = None

    @property
    def address(self) -> str:
        return f"{self.bus}:{self.node}"


def resolve_target(cfg: ArmConfig, text: str) -> DriveRef:
    """A drive from a drive name, a plain joint name, or ``BUS:NODE``."""
    if text in cfg.drives:
        d = cfg.drives[text]
        return DriveRef(d.name, d.bus, d.node, d)
    joint = cfg.joints.get(text)
    if joint is not None and joint.drive:
        d = cfg.drives[joint.drive]
        return DriveRef(d.name, d.bus, d.node, d)
    pair = cfg.pairs.get(text) or (cfg.pairs.get(joint.pair) if joint is not None and joint.pair else None)
    if pair is not None:
        raise UsageError(f"'{text}' is moved by two drives ({pair.drive_a}, {pair.drive_b}); name one of them")
    bus, sep, node_text = text.partition(":")
    if sep:
        if bus not in cfg.buses:
            raise UsageError(f"target '{text}': no bus '{bus}' in the config",
                             hint=f"configured buses: {', '.join(cfg.buses)}")
        if not node_text.isdigit() or not 1 <= int(node_text) <= 127:
            raise UsageError(f"target '{text}': node id must be 1..127")
        node = int(node_text)
        for d in cfg.drives.values():
            if d.bus == bus and d.node == node:
                return DriveRef(d.name, d.bus, d.node, d)
        return DriveRef(text, bus, node, None)
    names = list(cfg.drives) + list(cfg.joints) + list(cfg.pairs)
    close = difflib.get_close_matches(text, names, n=3)
    raise UsageError(f"unknown target '{text}': not a drive, joint or BUS:NODE of the config",
                     hint=f"did you mean {' or '.join(close)}?" if close else "see `sherpa config check` for the names")


class ArmSession:
    """Open buses plus a DriveClient per drive; build with :meth:`open`."""

    def __init__(self, cfg: ArmConfig, links: dict[str, BusLink], sim: Any = None) -> None:
        self.cfg = cfg
        self.links = links
        self.sim = sim  # the in-process SimArm with --sim, for tests and fault injection
        self._clients: dict[tuple[str, int], Any] = {}

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
            # the simulator shares this process on a possibly loaded machine: its patient reply timeout
            wire_cfg = replace(wire_cfg, protocol=replace(wire_cfg.protocol, reply_timeout=cfg.sim_reply_timeout))
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
                                      mo_confirm_timeout=p.mo_confirm_timeout, sv_blackout=p.sv_blackout,
                                      **({"timeout_hint": SIM_TIMEOUT_HINT} if self.sim is not None else {}))
            client = DriveClient(NetworkTransport(self.links[ref.bus].network), ref.node, name=ref.name,
                                 timeout=p.reply_timeout, retries=p.retries, settings=settings)
            self._clients[key] = client
        return client
