"""The load a simulated motor drives: the joint's inertia, friction and gravity, and the electrical
limits on the current the drive can put through the motor.

Joint side, SI units (radians at the joint; the motor model converts from counts):

    J w' = Kt i - b w - Fc sign(w) - G cos(theta_g)        (Coulomb friction holds a joint at rest
           - Tc sin(n theta + phase)                         while the other torques are below Fc)
    |i| <= peak                                             (the drive's peak current, MC)
    R |i| + Ke |w| <= V                  while motoring      (back-EMF eats the supply voltage)
    R i^2 + Ke |w| |i| <= V I_supply     while motoring      (a supply that gives at most I_supply A)

``theta`` is the motor's angle in joint radians; ``theta_g`` the angle gravity acts on: the same for a
plain joint, a pair's Σ angle for a pair's motor (sim/arm.py). 0 is horizontal; G is the gravity
torque at horizontal, 0 for every joint whose axis is vertical (the default). Tc is the cogging and
friction ripple: n cycles per joint turn (the motor's poles and the gear's teeth repeat with its
angle), 0 by default. The defaults make a
shoulder-like joint: 1 A settles at (1 - 0.4) / 1.2 = 0.5 rad/s (seed Fig. 9.8/9.9) within about
0.2 s, and a lab supply (no current limit) never limits it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


def _sign(x: float) -> int:
    return (x > 0) - (x < 0)


@dataclass(frozen=True)
class Load:
    inertia: float = 0.06  # kg m^2 at the joint
    torque_constant: float = 1.0  # N m per A at the joint (motor Kt x gear ratio)
    viscous: float = 1.2  # N m s/rad
    coulomb: float = 0.4  # N m
    gravity: float = 0.0  # N m at horizontal (a pitch joint); 0: a vertical axis
    back_emf: float = 4.0  # V s/rad at the joint
    resistance: float = 1.0  # ohm, winding
    supply_voltage: float = 25.0  # V (the seed's bench supply)
    supply_current: float | None = None  # A the supply gives at most; None: a lab supply, no limit
    peak_current: float = 20.0  # A, the drive's peak (MC)
    cogging_torque: float = 0.0  # N m, amplitude of the position-periodic torque ripple
    cogging_cycles: int = 0  # its periods per joint turn
    cogging_phase: float = 0.0  # rad, where the ripple's cycle starts against position 0

    def __post_init__(self) -> None:
        for name in ("inertia", "torque_constant", "resistance", "supply_voltage", "peak_current"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"Load.{name} must be a finite number > 0, got {value!r}")
        for name in ("viscous", "coulomb", "back_emf", "cogging_torque"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"Load.{name} must be a finite number >= 0, got {value!r}")
        if self.cogging_cycles < 0 or not math.isfinite(self.cogging_phase):
            raise ValueError("Load.cogging_cycles must be >= 0 and cogging_phase a finite number")
        if not math.isfinite(self.gravity):
            raise ValueError("Load.gravity must be a finite number")
        if self.supply_current is not None and not (math.isfinite(self.supply_current) and self.supply_current > 0):
            raise ValueError("Load.supply_current must be a finite number > 0 (or None)")

    @property
    def accel_per_amp(self) -> float:
        """rad/s^2 per A with no friction or gravity: what a servo loop's gains are scaled by."""
        return self.torque_constant / self.inertia

    def current(self, amps: float, omega: float, bus: float | None = None) -> float:
        """The current the drive can really put through the motor when asked for ``amps`` at ``omega`` rad/s.
        ``bus``: the drive's bus voltage where a sagging supply (sim/supply.py) sets it; its current
        limit then acts through the voltage, not as a power bound here."""
        limit = self.peak_current
        if amps * omega > 0:  # motoring: the supply delivers the power
            emf = self.back_emf * abs(omega)
            limit = min(limit, max(0.0, ((self.supply_voltage if bus is None else bus) - emf) / self.resistance))
            if self.supply_current is not None and bus is None:
                power = self.supply_voltage * self.supply_current
                limit = min(limit, (-emf + math.sqrt(emf * emf + 4 * self.resistance * power)) / (2 * self.resistance))
        return max(-limit, min(limit, amps))

    def ripple(self, theta: float) -> float:
        """The cogging and friction ripple's torque (N m) at the motor angle ``theta`` (joint rad)."""
        if not (self.cogging_torque and self.cogging_cycles):
            return 0.0
        return self.cogging_torque * math.sin(self.cogging_cycles * theta + self.cogging_phase)

    def step(self, amps: float, omega: float, theta: float, dt: float, gravity_theta: float | None = None) -> float:
        """The joint's speed (rad/s) ``dt`` s later, driven by ``amps`` (already limited) from ``omega``;
        gravity acts on ``gravity_theta`` (a pair's Σ angle), else on ``theta``."""
        drive = self.torque_constant * amps - self.gravity * math.cos(theta if gravity_theta is None else gravity_theta) \
            - self.ripple(theta)
        if omega == 0.0:
            if abs(drive) <= self.coulomb:
                return 0.0  # static friction holds it
            net = drive - self.coulomb * _sign(drive)
        else:
            net = drive - self.viscous * omega - self.coulomb * _sign(omega)
        new = omega + net / self.inertia * dt
        if omega != 0.0 and _sign(new) != _sign(omega) and abs(drive) <= self.coulomb:
            return 0.0  # friction stops it; it does not push it back
        return new
