"""Simulated Elmo SimplIQ Whistle drives (and, later, the arm mechanics around them).

Speaks CAN like a real drive but owns no bus: see :class:`sherpa_cli.sim.drive.SimDrive`.
Imports only the pure ``elmo``, ``joints`` and ``config`` layers, never python-can.
"""

from sherpa_cli.sim.clock import Clock, ManualClock, RealClock
from sherpa_cli.sim.settings import SimSettings

__all__ = ["Clock", "ManualClock", "RealClock", "SimSettings"]
