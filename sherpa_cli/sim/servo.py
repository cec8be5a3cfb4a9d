"""Servo-loop motor model: the drive's profile (sim/motor.py's kinematic Motor) is the reference,
and the motor follows it through a second-order position loop with a current limit and an
optional supply current limit, so a step has a realistic rise, overshoot and settling.

    a_cmd = wn^2 (x_ref - x) + 2 zeta wn (v_ref - v)        (no feed-forward: a step shows the loop)
    i     = a_cmd / torque_accel, limited to +-current_limit and, at speed v, to
            supply_limit * supply_speed / |v|               (supply current ~ i * |v| / supply_speed)
    v    += (i * torque_accel) dt;  x += v dt               (semi-implicit Euler: stable for wn dt << 1)

Torque mode (UM=1) bypasses the loop: the current is TC, limited the same way.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from sherpa_cli.sim.motor import Motor


@dataclass
class ServoMotor(Motor):
    wn: float = 2 * math.pi * 20.0  # rad/s
    zeta: float = 0.5
    torque_accel_per_amp: float = 10000.0  # cnt/s^2 per A
    current_limit: float = 20.0  # A
    supply_limit: float | None = None  # A
    supply_speed: float = 100000.0  # cnt/s
    current: float = 0.0  # A of the last step
    ref: Motor = field(default_factory=Motor)

    def _sync_ref(self) -> None:
        self.ref.counts, self.ref.frac, self.ref.v, self.ref.a = self.counts, self.frac, self.v, 0.0

    def off(self) -> None:
        super().off()
        self.current = 0.0
        self.ref.off()
        self._sync_ref()

    def jog(self, v_target: float, accel: float, decel: float) -> None:
        if self.ref.mode in ("idle", "torque"):
            self._sync_ref()
        super().jog(v_target, accel, decel)
        self.ref.jog(v_target, accel, decel)

    def move_to(self, target: int, speed: float, accel: float, decel: float) -> None:
        if self.ref.mode in ("idle", "torque"):
            self._sync_ref()
        super().move_to(target, speed, accel, decel)
        self.ref.move_to(target, speed, accel, decel)

    def stop(self, decel: float) -> None:
        super().stop(decel)
        self.ref.stop(decel)

    def torque(self, accel: float) -> None:
        super().torque(accel)
        self.ref.off()

    def _limit(self, amps: float) -> float:
        limit = self.current_limit
        if self.supply_limit is not None and self.v:
            limit = min(limit, self.supply_limit * self.supply_speed / abs(self.v))
        return max(-limit, min(limit, amps))

    def step(self, dt: float) -> None:
        v0 = self.v
        if self.mode == "torque":
            amps = self._limit(self.torque_accel / self.torque_accel_per_amp)
            self._sync_ref()
        else:
            self.ref.step(dt)
            e = self.ref.position - self.position
            amps = self._limit((self.wn * self.wn * e + 2 * self.zeta * self.wn * (self.ref.v - self.v))
                               / self.torque_accel_per_amp)
            self.mode, self.at_target = self.ref.mode, self.ref.at_target and abs(e) < 1.0
            self.x_target, self.v_target = self.ref.x_target, self.ref.v_target
        self.current = amps
        self.v = v0 + amps * self.torque_accel_per_amp * dt
        self.a = (self.v - v0) / dt
        self._advance(self.v * dt)
