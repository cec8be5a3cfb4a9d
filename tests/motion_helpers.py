"""What the motion tests share: the fast jog arm, the calibration mark `home` leaves, motors off."""

from __future__ import annotations

import uuid
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

from sherpa_cli.bus.session import ArmSession, DriveRef
from sherpa_cli.config.model import ArmConfig
from sherpa_cli.sim.arm import SimArm
from sherpa_cli.sim.stepped import SteppedTime

JOG_CONFIG = Path(__file__).resolve().parent / "data" / "jog-fast-arm.yaml"
VIEW_LIVENESS_S = 5.0


def view_config(path: Path = JOG_CONFIG) -> ArmConfig:
    """An arm (default: the fast jog arm) for the interactive view's tests, with a liveness of 5 s: the textual app runs
    in the test's process, and with four busy processes beside the suite its loop once went over the
    default 1 s without a tick, so the dead-man (rightly) stopped the jog. A busy host's setting
    (docs/motion.md "Dead-man"), not a change to what the view does."""
    import dataclasses

    from sherpa_cli.config import load_config

    cfg = load_config(path)
    return dataclasses.replace(cfg, motion=dataclasses.replace(cfg.motion, liveness_timeout=VIEW_LIVENESS_S))


def calibrate(session, *drives: str) -> None:
    """What `home` leaves behind: UI[3]=1 on each drive (RAM)."""
    for name in drives:
        d = session.cfg.drives[name]
        c = session.client(DriveRef(name, d.bus, d.node, d))
        c.nmt_start()
        c.set("UI", 3, 1)


def motors_off(session) -> bool:
    with session.sim.lock:
        return all(not d.motor_on for d in session.sim.drives.values())


@contextmanager
def stepped_session(cfg: ArmConfig, buses: Sequence[str] | None = None) -> Iterator[tuple[ArmSession, SteppedTime]]:
    """An in-process simulated arm on stepped time (sim/stepped.py) and its session, with the drive
    clients waiting on that clock: the simulated motors move only while the command waits, so how far
    they get does not depend on the host's load. Pass the SteppedTime as the command's ``timebase``."""
    stepped = SteppedTime()
    names = list(buses) if buses is not None else list(cfg.buses)
    tag = uuid.uuid4().hex[:8]
    sim = SimArm(cfg, {b: {"interface": "virtual", "channel": f"stepped-{tag}-{b}"} for b in names},
                 clock=stepped.clock)
    with ArmSession.open(cfg, sim=sim, buses=names) as session:
        def unheard() -> tuple[int, float]:
            return (sum(d.unheard for d in sim.drives.values()), sum(d.unheard_s for d in sim.drives.values()))

        session.client_overrides.update(stepped.client_overrides(cfg.protocol.reply_timeout, cfg.protocol.retries,
                                                                 unheard))
        yield session, stepped
