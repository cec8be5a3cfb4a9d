"""The one servo model of a simulated drive: the drive's profile (sim/motor.py's kinematic Motor) is the
reference, a PID position loop turns the error into a current, the drive clamps it (its peak current,
the supply's voltage and current against the back-EMF: sim/load.py) and the current drives the
joint's load (inertia, friction, gravity):

    a_cmd = wn^2 e + 2 zeta wn (ff v_ref - v) + ki integral(e)   e = x_ref - x (counts); ki = 0.2 wn^3,
                                                                 integrating while the reference stands
    i     = load.current(a_cmd / accel_per_amp, w)                      (limits, sim/load.py)
    w    <- load.step(i, w, theta, dt);  x += v dt                     (semi-implicit Euler)

``feed_forward`` 1 (`servo_bandwidth`, docs/log.md): the velocity reference is fed forward, so at speed the
motor tracks its profile and a step shows the loop. ``feed_forward`` 0 with damping 1 is the same model
as a first-order lag: the motor trails its profile by 2 zeta / wn = tau s at speed (`lag: tau`,
docs/diffdrive.md; wn = 2 / tau). Torque mode (UM=1) bypasses the loop: the current is TC, limited the
same way.

The drive's gains act on this loop as on a cascade of a P position loop (KP[3]) into a PI speed loop
(KP[2], KI[2]): the bandwidth and damping above (or the lag) are the loop *at the reference gains*
(``REFERENCE_GAINS``, the simulated drive's factory values), and with the gains the drive holds

    kv = KP[2] / KP[2]0          the speed term          2 zeta wn (ff v_ref - v)  x kv
    kp = KP[3] / KP[3]0          the position term       wn^2 e                    x kv kp
    ki = KI[2] / KI[2]0          the standing integrator  ki integral(e)            x ki kp

so the loop's bandwidth is wn sqrt(kv kp), its damping zeta sqrt(kv / kp), and a lag tau becomes
tau / kp. Scaling KP[2] and KP[3] alike by s (and KI[2] by s^2) scales the bandwidth by s at the same
damping: what `diffdrive match` proposes (ops/pair_match.py). This is the simulator's model, not
Elmo's control law (whose exact form and units the sources do not give).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

from sherpa_cli.sim.load import Load
from sherpa_cli.sim.motor import Motor

# the gains at which a drive's configured servo_bandwidth / servo_damping / lag hold (sim/params.py's factory values)
REFERENCE_GAINS = {"KP[2]": 0.5, "KI[2]": 200.0, "KP[3]": 30.0}


@dataclass
class ServoMotor(Motor):
    wn: float = 2 * math.pi * 20.0  # rad/s
    zeta: float = 0.5
    feed_forward: float = 1.0  # share of the reference velocity fed forward (0: a lag)
    integral_gain: float = 0.2  # ki = integral_gain * wn^3, at standstill: removes the error friction leaves
    ref: Motor = field(default_factory=Motor)
    # the gains as ratios to REFERENCE_GAINS (set_gains); 1, 1, 1: the configured loop
    kv: float = 1.0
    kp: float = 1.0
    ki: float = 1.0
    _integral: float = 0.0  # counts s

    def __post_init__(self) -> None:
        if self.load is None:
            self.load = Load()

    def set_gains(self, gains: Mapping[str, float]) -> None:
        """The drive's KP[2], KI[2], KP[3] (RAM): the loop follows them from its next step."""
        self.kv = float(gains["KP[2]"]) / REFERENCE_GAINS["KP[2]"]
        self.kp = float(gains["KP[3]"]) / REFERENCE_GAINS["KP[3]"]
        self.ki = float(gains["KI[2]"]) / REFERENCE_GAINS["KI[2]"]

    def _sync_ref(self) -> None:
        self.ref.counts, self.ref.frac, self.ref.v, self.ref.a = self.counts, self.frac, self.v, 0.0
        self._integral = 0.0

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

    def torque(self, amps: float) -> None:
        super().torque(amps)
        self.ref.off()

    @property
    def rounded(self) -> int:
        """The count the encoder shows: the nearest (a loop settles on its target from either side)."""
        return math.floor(self.position + 0.5)

    def step(self, dt: float) -> None:
        load = self.load or Load()
        k = self.counts_per_rad
        if self.mode == "torque":
            amps = self.torque_amps
            self._sync_ref()
        else:
            self.ref.step(dt)
            e = self.ref.position - self.position
            if self.ref.v == 0:  # the integrator holds a standing target against friction; no wind-up in motion
                self._integral += e * dt
            ki = self.integral_gain * self.wn ** 3 * self.ki * self.kp
            a_cmd = self.wn * self.wn * self.kv * self.kp * e \
                + 2 * self.zeta * self.wn * self.kv * (self.feed_forward * self.ref.v - self.v) + ki * self._integral
            amps = a_cmd / (load.accel_per_amp * k)
            if abs(amps) > load.peak_current and self.ref.v == 0:
                self._integral -= e * dt  # saturated: no wind-up
            self.mode, self.at_target = self.ref.mode, self.ref.at_target and abs(e) < 1.0
            self.x_target, self.v_target = self.ref.x_target, self.ref.v_target
        self._drive_load(amps, dt, midpoint=False)
