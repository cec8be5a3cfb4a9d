"""`Arm.joint(name)`: one joint, read in joint units whenever a property is asked."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    from sherpa_cli.config.model import ArmConfig
    from sherpa_cli.ops.state import ArmState, JointLimits, JointState


class StateReader(Protocol):
    """What a handle reads through: an open :class:`~sherpa_cli.api.arm.Arm`."""

    @property
    def config(self) -> ArmConfig: ...

    def state(self, targets: Sequence[str] | None = None) -> ArmState: ...


class JointHandle:
    """A plain or Σ/Δ joint of an open :class:`~sherpa_cli.api.arm.Arm`.

    ``position``, ``velocity`` and ``status`` each read the joint's drives now (a Σ/Δ joint: both
    motors of its pair), so two reads are two snapshots; read ``status`` once for values that belong
    together. ``limits`` is the config's, read from no drive.
    """

    def __init__(self, arm: StateReader, name: str) -> None:
        from sherpa_cli.bus.targets import unknown_target

        if name not in arm.config.joints:
            raise unknown_target(arm.config, name)  # names what exists, as the commands do
        self._arm = arm
        self.name = name

    def __repr__(self) -> str:
        return f"JointHandle({self.name!r})"

    @property
    def status(self) -> JointState:
        """Position, velocity, current, calibrated, motor on, mode and faults, read now."""
        return self._arm.state([self.name])[self.name]

    @property
    def position(self) -> float:
        """rad, read now."""
        return self.status.position

    @property
    def velocity(self) -> float:
        """rad/s, read now."""
        return self.status.velocity

    @property
    def limits(self) -> JointLimits:
        """The configured limits in joint units (rad, rad/s, rad/s², A)."""
        from sherpa_cli.ops.state import joint_limits

        return joint_limits(self._arm.config, self.name)
