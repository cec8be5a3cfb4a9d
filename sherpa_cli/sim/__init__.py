"""The simulated arm, beside the stack: Elmo SimplIQ Whistle drives at frame level (drive.py, the
interpreter through a small Protocol in interpreter.py), their object dictionary, PDOs and SDO server,
motor and servo models, the arm around them (arm.py: buses, switches, pair coupling, hard stops),
flash state, a stepped clock, and python-can-remote servers (serve.py).

May import elmo, joints, config, errors and paths only; never bus, devices, motion, log, ops,
recipes or cli (import-linter checks it). Only the CLI wires it in (--sim, `sherpa sim`).
"""

from sherpa_cli.sim.clock import Clock, ManualClock, RealClock, StallMeter
from sherpa_cli.sim.settings import SimSettings

__all__ = ["Clock", "ManualClock", "RealClock", "SimSettings", "StallMeter"]
