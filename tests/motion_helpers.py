"""What the motion tests share: the fast jog arm, the calibration mark `home` leaves, motors off."""

from __future__ import annotations

from pathlib import Path

from sherpa_cli.bus.session import DriveRef

JOG_CONFIG = Path(__file__).resolve().parent / "data" / "jog-fast-arm.yaml"


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
