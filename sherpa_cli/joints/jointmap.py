"""Which motors a joint reads from, and how: the one place a joint's value comes from its drives.

A plain joint is its drive's value. A Σ/Δ joint of a differential pair is ``a + sign·b`` of its two
motors for position and velocity (sign +1 for Σ, -1 for Δ: joints/diffpair.py ``to_joints``) and
``(a + sign·b) / 2`` for current (``joint_currents``, the transpose of the motor currents). The
recorders (log/record.py, ops/drive_record.py), the live Foxglove view and the API's state read
joints through it instead of each writing the sum again.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

from sherpa_cli.config.model import ArmConfig, JointConfig


@dataclass(frozen=True)
class JointMap:
    """A joint in terms of its motors: ``a`` alone (``b`` None), or ``a + sign·b`` of a pair."""

    joint: str
    cpr: int
    a: str
    b: str | None = None
    sign: int = 1

    @property
    def drives(self) -> tuple[str, ...]:
        return (self.a,) if self.b is None else (self.a, self.b)

    def value(self, a: float, b: float | None = None) -> float:
        """Position or velocity (counts, counts/s) of the joint from its motors' (b: the pair's second)."""
        if self.b is None:
            return a
        if b is None:
            raise ValueError(f"{self.joint}: a pair joint needs both motors' values")
        return a + self.sign * b

    def current(self, a: float, b: float | None = None) -> float:
        """The joint's torque as motor current (A): a plain joint's own, a pair joint's (a ± b)/2."""
        if self.b is None:
            return a
        if b is None:
            raise ValueError(f"{self.joint}: a pair joint needs both motors' currents")
        return (a + self.sign * b) / 2


def joint_map(cfg: ArmConfig, joint: JointConfig) -> JointMap | None:
    """How ``joint`` reads from its drives; None for a joint of neither kind (no drive, no pair)."""
    if joint.drive is not None:
        return JointMap(joint.name, joint.cpr, joint.drive)
    if joint.pair is not None:
        pair = cfg.pairs[joint.pair]
        return JointMap(joint.name, joint.cpr, pair.drive_a, pair.drive_b, 1 if joint.name == pair.sigma else -1)
    return None


def joint_maps(cfg: ArmConfig) -> Iterator[JointMap]:
    """Every joint of the config that reads from drives, in config order."""
    for joint in cfg.joints.values():
        m = joint_map(cfg, joint)
        if m is not None:
            yield m
