"""Kinematic motor model of one simulated drive: profiles, not physics.

The reference and the motor are the same thing here (a perfect servo loop), so PE/VE are 0.
Positions are exact integer counts plus a fractional remainder, so PX never drifts from
what the profile integrated.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

from sherpa_cli.sim.load import Load
from sherpa_cli.sim.supply import Supply

Mode = Literal["idle", "velocity", "position", "stop", "torque"]
COUNTS_PER_RAD = 3600 / (2 * math.pi)  # a joint of 3600 counts per turn when nothing says otherwise


NO_LOAD_ACCEL = 10000.0  # cnt/s^2 per A of a Motor without a load


def _sign(x: float) -> int:
    return (x > 0) - (x < 0)


@dataclass
class Motor:
    counts: int = 0  # physical position, whole counts
    frac: float = 0.0  # remainder in [0, 1)
    v: float = 0.0  # cnt/s
    a: float = 0.0  # cnt/s^2 of the last step (IQ outside torque mode)
    mode: Mode = "idle"
    v_target: float = 0.0
    x_target: int = 0
    speed: float = 0.0  # SP of the running PTP move
    accel: float = 0.0
    decel: float = 0.0
    torque_amps: float = 0.0  # UM=1: the current TC asks for
    at_target: bool = False  # a PTP move finished (MS=0)
    load: Load | None = None  # what torque mode drives (sim/load.py); None: 10000 cnt/s^2 per A, no friction
    counts_per_rad: float = COUNTS_PER_RAD
    current: float = 0.0  # A through the motor in the last torque-mode step
    supply: Supply | None = None  # a supply whose voltage sags (sim/supply.py); None: stiff, load.py's bounds
    gravity_angle: Callable[[], float] | None = None  # the angle gravity acts on (a pair's Σ, rad); None: own

    @property
    def position(self) -> float:
        return self.counts + self.frac

    def off(self) -> None:
        """Motor disabled: the model has no coasting, it stops dead."""
        self.v = self.a = self.current = 0.0
        self.mode = "idle"
        self.at_target = False
        if self.supply is not None:
            # an off drive takes no steps; its supply refills the bus within C V / I (0.3 s on the seed's
            # bench), shorter than the settle window before the motor can be on again
            self.supply.bus = self.supply.voltage

    def jog(self, v_target: float, accel: float, decel: float) -> None:
        self.mode, self.v_target, self.accel, self.decel = "velocity", v_target, accel, decel
        self.at_target = False

    def move_to(self, target: int, speed: float, accel: float, decel: float) -> None:
        self.mode, self.x_target, self.speed, self.accel, self.decel = "position", target, speed, accel, decel
        self.at_target = False

    def stop(self, decel: float) -> None:
        if self.mode in ("idle", "torque") and self.v == 0:
            self.mode = "idle"
            return
        self.mode, self.v_target, self.decel = "stop", 0.0, decel
        self.at_target = False

    def torque(self, amps: float) -> None:
        self.mode, self.torque_amps, self.at_target = "torque", amps, False

    @property
    def rounded(self) -> int:
        """The count the encoder shows (the kinematic model moves in whole counts plus a remainder)."""
        return self.counts

    def _drive_load(self, amps: float, dt: float, midpoint: bool = True) -> None:
        """One step of the load driven by ``amps`` (limited by the drive and the supply first); the
        position moves by the mean speed of the step, or (``midpoint`` False: semi-implicit Euler, for a
        servo loop) by the new speed."""
        v0 = self.v
        if self.load is None:
            self.current = amps
            self.v = v0 + amps * NO_LOAD_ACCEL * dt
        else:
            k, w0 = self.counts_per_rad, v0 / self.counts_per_rad
            supply = self.supply
            self.current = self.load.current(amps, w0) if supply is None else supply.current(self.load, amps, w0)
            tilt = None if self.gravity_angle is None else self.gravity_angle()
            self.v = self.load.step(self.current, w0, self.position / k, dt, tilt) * k
            if supply is not None:
                supply.drain(self.load, self.current, w0, dt)
        self.a = (self.v - v0) / dt
        self._advance(((v0 + self.v) / 2 if midpoint else self.v) * dt)

    def intended_direction(self) -> int:
        """Where the motion is heading (or about to), for the stop-switch check."""
        if self.v:
            return _sign(self.v)
        if self.mode == "velocity":
            return _sign(self.v_target)
        if self.mode == "position":
            return _sign(self.x_target - self.position)
        return 0

    def step(self, dt: float) -> None:
        v0 = self.v
        if self.mode == "position":
            self._step_position(dt)
            return
        if self.mode == "torque":
            self._drive_load(self.torque_amps, dt)
            return
        if self.mode in ("velocity", "stop"):
            self.v = _approach(v0, self.v_target, self.accel, self.decel, dt)
            if self.mode == "stop" and self.v == 0:
                self.mode = "idle"
        self.a = (self.v - v0) / dt
        self._advance((v0 + self.v) / 2 * dt)

    def _step_position(self, dt: float) -> None:
        v0 = self.v
        d = self.x_target - self.position
        direction = _sign(d)
        if direction == 0 and v0 == 0:
            self._arrive()
            return
        if v0 != 0 and v0 * direction <= 0:
            # Moving away from (or past) the target after a retarget: brake before turning.
            v1 = _approach(v0, 0.0, self.accel, self.decel, dt)
        else:
            # Fastest speed from which DC still stops exactly at the target.
            desired = min(self.speed, math.sqrt(2 * self.decel * abs(d)))
            speed = abs(v0)
            speed = min(speed + self.accel * dt, desired) if speed < desired else max(speed - self.decel * dt, desired)
            v1 = direction * speed
        dx = (v0 + v1) / 2 * dt
        if direction and v1 * direction >= 0 and dx * direction >= abs(d):
            self.a = -v0 / dt
            self._arrive()
            return
        self.v, self.a = v1, (v1 - v0) / dt
        self._advance(dx)

    def _arrive(self) -> None:
        self.counts, self.frac, self.v = self.x_target, 0.0, 0.0
        self.mode, self.at_target = "idle", True

    def _advance(self, dx: float) -> None:
        total = self.frac + dx
        whole = math.floor(total)
        self.counts += whole
        self.frac = total - whole


def motion_status(motor: Motor, unit_mode: int, motor_on: bool) -> int:
    """MS: 0 at target, 1 stationary or motor off, 2 profiler active ([CR MS]); in UM=2
    1 means "at the commanded speed". Torque mode has no profiler, so it reads 1."""
    if not motor_on or unit_mode == 1:
        return 1
    if unit_mode == 2:
        at_speed = motor.mode == "velocity" and motor.v == motor.v_target
        return 2 if motor.mode in ("velocity", "stop") and not at_speed else 1
    if motor.mode in ("position", "stop", "velocity"):  # velocity: a jog in UM=5 keeps the profiler busy
        return 2
    return 0 if motor.at_target else 1


def _approach(v: float, target: float, accel: float, decel: float, dt: float) -> float:
    """One step of a speed ramp: AC while speeding up, DC while slowing down or reversing."""
    if v == target:
        return v
    if v != 0 and (target * v < 0 or abs(target) < abs(v)):
        rate = decel
        # A reversal brakes to zero first; the next step speeds up the other way with AC.
        goal = target if target * v > 0 else 0.0
    else:
        rate, goal = accel, target
    dv = rate * dt
    return goal if abs(goal - v) <= dv else v + math.copysign(dv, goal - v)
