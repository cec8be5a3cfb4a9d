"""The Python API: :class:`Arm` and the result types its methods return (docs/api.md).

It sits above the procedures (ops) and below the CLI, whose commands are thin layers over it;
it may wire in the simulator (``Arm.open(..., sim=True)``), as the CLI does.
"""

from sherpa_cli.api.arm import Arm
from sherpa_cli.api.programming import ProgramReport
from sherpa_cli.ops.scan import ScanReport
from sherpa_cli.ops.stop import StopReport, StopResult

__all__ = ["Arm", "ProgramReport", "ScanReport", "StopReport", "StopResult"]
