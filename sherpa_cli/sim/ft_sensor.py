"""A simulated ATI Net F/T sensor on the bus (`devices:` type ft_sensor, `sim: ft_sensors:`).

It answers the one-byte request ``0x02`` on its base id with the two short-data frames (base+5: Fx,
Tx, Fy, Ty; base+6: Fz, Tz, status word, sample number; INT16 little endian) and takes ``0x04`` as
bias. What it feels, in the sensor frame:

- gravity of a payload of ``payload_kg`` whose centre of mass is ``payload_com`` from the sensor,
  the sensor tilted about its x axis by the sum of the ``wrist`` joints' angles (0 rad: gravity
  along -z);
- a spring contact when ``wall_joint`` is past ``wall_position`` (on ``wall_side``):
  ``wall_stiffness`` N (or N·m) per rad past the wall, along ``wall_axis``;
- a bias drift growing linearly from power-up, and Gaussian noise from a seeded generator, so a
  run with the same requests reads the same numbers.

Bias stores the noiseless reading of that instant; later readings subtract it. ``silent_at``
makes it stop answering (a cut cable). The frames are written here with struct, not with
sherpa_cli.devices (the simulator sits beside the stack), which also keeps the tool's codec honest.
"""

from __future__ import annotations

import math
import random
import struct
from collections.abc import Callable, Mapping

from sherpa_cli.config.model import DeviceConfig, JointConfig, SimFtConfig
from sherpa_cli.sim.clock import Clock

REQUEST_SHORT, BIAS = 0x02, 0x04
GRAVITY = 9.81  # m/s^2
AXIS_INDEX = {"Fx": 0, "Fy": 1, "Fz": 2, "Tx": 3, "Ty": 4, "Tz": 5}
Six = tuple[float, float, float, float, float, float]


def _int16(value: float) -> int:
    return max(-0x8000, min(0x7FFF, round(value)))


class SimFtSensor:
    """One simulated sensor; the bus pump hands it the frames on its base id (:meth:`receive`)."""

    def __init__(self, dev: DeviceConfig, sim: SimFtConfig, clock: Clock, joints: Mapping[str, JointConfig],
                 joint_counts: Callable[[str], float]) -> None:
        assert dev.ft is not None and dev.ft.counts_per_force and dev.ft.counts_per_torque  # config/validate.py
        self.name, self.sim, self.clock = dev.name, sim, clock
        self.base_id = dev.ft.base_id
        self.counts_per_force, self.counts_per_torque = dev.ft.counts_per_force, dev.ft.counts_per_torque
        self.joints, self.joint_counts = joints, joint_counts
        self.power_up = clock.now()
        self.rng = random.Random(sim.seed)
        self.bias: Six = (0.0,) * 6
        self.biased = False
        self.sample = 0
        self.requests = 0  # for tests
        self.bias_commands = 0

    # -- what it feels ---------------------------------------------------------------------------
    def _angle(self, joint: str) -> float:
        j = self.joints[joint]
        return self.joint_counts(joint) * 2 * math.pi / j.cpr

    def load(self) -> Six:
        """Gravity of the payload plus the wall contact (N, N·m), without drift, noise or bias."""
        s = self.sim
        tilt = sum(self._angle(j) for j in s.wrist)
        weight = s.payload_kg * GRAVITY
        f = [0.0, weight * math.sin(tilt), -weight * math.cos(tilt)]
        rx, ry, rz = s.payload_com
        t = [ry * f[2] - rz * f[1], rz * f[0] - rx * f[2], rx * f[1] - ry * f[0]]
        out = f + t
        if s.wall_joint is not None:
            pos = self.joint_counts(s.wall_joint)
            past = pos - s.wall_position if s.wall_side == "high" else s.wall_position - pos
            if past > 0:
                out[AXIS_INDEX[s.wall_axis]] += s.wall_stiffness * past * 2 * math.pi / self.joints[s.wall_joint].cpr
        return tuple(out)  # type: ignore[return-value]

    def reading(self, now: float, *, noise: bool = True) -> Six:
        """What the sensor reports at ``now`` (N, N·m): load + drift (+ noise) - bias."""
        s = self.sim
        age = max(0.0, now - self.power_up)
        load = self.load()
        out = []
        for i, value in enumerate(load):
            force = i < 3
            value += age * (s.drift_force if force else s.drift_torque)
            if noise:
                sigma = s.noise_force if force else s.noise_torque
                value += self.rng.gauss(0.0, sigma) if sigma > 0 else 0.0
            out.append(value - self.bias[i])
        return tuple(out)  # type: ignore[return-value]

    # -- the bus ----------------------------------------------------------------------------------
    def silent(self, now: float) -> bool:
        return self.sim.silent_at is not None and now - self.power_up >= self.sim.silent_at

    def receive(self, can_id: int, data: bytes) -> list[tuple[int, bytes]]:
        """A frame on the bus; returns the frames the sensor sends for it."""
        if can_id != self.base_id or len(data) < 1:
            return []
        now = self.clock.now()
        if self.silent(now):
            return []
        if data[0] == BIAS:
            self.bias_commands += 1
            self.bias = (0.0,) * 6
            self.bias = self.reading(now, noise=False)
            self.biased = True
            return []
        if data[0] != REQUEST_SHORT:
            return []
        self.requests += 1
        fx, fy, fz, tx, ty, tz = self.reading(now)
        cf, ct = self.counts_per_force, self.counts_per_torque
        sample = self.sample
        self.sample = (self.sample + 1) & 0xFFFF
        first = struct.pack("<hhhh", _int16(fx * cf), _int16(tx * ct), _int16(fy * cf), _int16(ty * ct))
        second = struct.pack("<hhHH", _int16(fz * cf), _int16(tz * ct), self.sim.status, sample)
        return [(self.base_id + 5, first), (self.base_id + 6, second)]

    # -- RAM between `--sim` commands ----------------------------------------------------------------
    def ram_snapshot(self, advance: bool = True) -> dict[str, object]:
        # the age carries the drift on: the bias was taken against the drift of that moment
        return {"ram": True, "ft": {"bias": list(self.bias), "biased": self.biased, "sample": self.sample,
                                    "age": self.clock.now() - self.power_up}}

    def restore_ram(self, saved: Mapping[str, object]) -> None:
        ft = saved.get("ft")
        if not isinstance(ft, dict) or not isinstance(ft.get("bias"), list) or len(ft["bias"]) != 6:
            raise ValueError("F/T sensor state missing")
        self.bias = tuple(float(v) for v in ft["bias"])  # type: ignore[assignment]
        self.biased = bool(ft.get("biased"))
        self.sample = int(ft.get("sample", 0)) & 0xFFFF
        self.power_up = self.clock.now() - max(0.0, float(ft.get("age", 0.0)))

    def restore_position(self, position: float) -> None:
        """A power cycle: a real sensor forgets its bias."""
