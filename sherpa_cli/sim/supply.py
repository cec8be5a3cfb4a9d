"""A bench supply whose voltage sags: the supply charges the drive's bus capacitor with at most its
current limit, the motor's power drains it.

    C dV/dt = I_s - P / V        I_s = the supply's current: enough to hold V at its set voltage,
                                        at most its limit (less by V0 - V over its source resistance)
    P       = i (R i + Ke w)     what the motor takes from the bus (regeneration charges it back, up
                                 to the set voltage: the drive's shunt burns the rest)
    R |i| + Ke |w| <= V          the drive cannot put more than the bus across the motor (sim/load.py)

A fast move first draws on the capacitor's charge; once that is spent the bus falls until the motor's
voltage bound leaves it no more power than the supply gives, and the speed drops with it (seed Fig.
9.1: "during the fast movements the voltage drops down as it is unable to provide enough energy";
Figs. 9.4/9.5: the 1 A supply's speed "is dropping after around 100ms"). Without a capacitance the
supply is stiff and sim/load.py's quasi-static power bound applies instead.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from sherpa_cli.sim.load import Load

BUS_FLOOR_V = 0.1  # the bus never reaches 0 V in the model: P / V stays finite


@dataclass
class Supply:
    voltage: float  # V the supply is set to (and the bus starts at)
    current_limit: float | None  # A; None: no limit (the bus stays at the set voltage)
    capacitance: float  # F between supply and drive, > 0
    resistance: float = 0.0  # ohm, the supply's source resistance: its voltage falls with its current
    bus: float = field(init=False)  # V now

    def __post_init__(self) -> None:
        if not (math.isfinite(self.voltage) and self.voltage > 0 and math.isfinite(self.capacitance)
                and self.capacitance > 0 and math.isfinite(self.resistance) and self.resistance >= 0):
            raise ValueError("Supply: voltage and capacitance must be > 0, resistance >= 0")
        if self.current_limit is not None and not (math.isfinite(self.current_limit) and self.current_limit > 0):
            raise ValueError("Supply.current_limit must be a finite number > 0 (or None)")
        self.bus = self.voltage

    def current(self, load: Load, amps: float, omega: float) -> float:
        """What the drive can put through the motor from the bus as it stands."""
        return load.current(amps, omega, bus=self.bus)

    def drain(self, load: Load, amps: float, omega: float, dt: float) -> None:
        """The bus ``dt`` s on, with ``amps`` through the motor at ``omega`` rad/s."""
        power = amps * (load.resistance * amps + load.back_emf * omega)
        limit = math.inf if self.current_limit is None else self.current_limit
        if self.resistance > 0:
            limit = min(limit, max(0.0, (self.voltage - self.bus) / self.resistance))
        drawn = power / max(self.bus, BUS_FLOOR_V)
        if self.resistance == 0 and self.bus >= self.voltage and drawn <= limit:
            return  # the supply holds its voltage: the capacitor stays charged
        if not math.isfinite(limit):  # an unlimited stiff supply refills the bus at once
            self.bus = self.voltage
            return
        self.bus = min(self.voltage, max(BUS_FLOOR_V, self.bus + (limit - drawn) * dt / self.capacitance))
