"""The Python API: :class:`Arm` and the result types its methods return (docs/api.md).

It sits above the procedures (ops) and below the CLI, whose commands are thin layers over it;
it may wire in the simulator (``Arm.open(..., sim=True)``), as the CLI does.

Each name is imported on first use: `sherpa scan` reaches ``Arm`` through here, and should not pay
for the programming engine or the stop procedure it never runs (benchmark ``scan``).
"""

from typing import TYPE_CHECKING

__all__ = [
    "Arm",
    "ArmState",
    "DriveState",
    "GainReading",
    "IdentifyReport",
    "JogResult",
    "JointHandle",
    "JointLimits",
    "JointState",
    "MatchResult",
    "MonitorSnapshot",
    "ParamDump",
    "ProgramReport",
    "RecordResult",
    "Recording",
    "ScanReport",
    "StopReport",
    "StopResult",
]

if TYPE_CHECKING:
    from sherpa_cli.api.arm import Arm as Arm
    from sherpa_cli.api.joint import JointHandle as JointHandle
    from sherpa_cli.api.programming import ProgramReport as ProgramReport
    from sherpa_cli.log.record_run import RecordResult as RecordResult
    from sherpa_cli.log.recording import Recording as Recording
    from sherpa_cli.ops.identify import IdentifyReport as IdentifyReport
    from sherpa_cli.ops.jog_result import JogResult as JogResult
    from sherpa_cli.ops.monitor import MonitorSnapshot as MonitorSnapshot
    from sherpa_cli.ops.pair_match import MatchResult as MatchResult
    from sherpa_cli.ops.params_file import ParamDump as ParamDump
    from sherpa_cli.ops.scan import ScanReport as ScanReport
    from sherpa_cli.ops.state import ArmState as ArmState
    from sherpa_cli.ops.state import DriveState as DriveState
    from sherpa_cli.ops.state import JointLimits as JointLimits
    from sherpa_cli.ops.state import JointState as JointState
    from sherpa_cli.ops.stop import StopReport as StopReport
    from sherpa_cli.ops.stop import StopResult as StopResult
    from sherpa_cli.ops.tune import GainReading as GainReading

#: public name -> the module that defines it
_HOME = {"Arm": "sherpa_cli.api.arm", "ProgramReport": "sherpa_cli.api.programming",
         "ScanReport": "sherpa_cli.ops.scan", "StopReport": "sherpa_cli.ops.stop", "StopResult": "sherpa_cli.ops.stop",
         "JointHandle": "sherpa_cli.api.joint", "IdentifyReport": "sherpa_cli.ops.identify",
         "JogResult": "sherpa_cli.ops.jog_result",
         "ParamDump": "sherpa_cli.ops.params_file", "MonitorSnapshot": "sherpa_cli.ops.monitor",
         "MatchResult": "sherpa_cli.ops.pair_match", "GainReading": "sherpa_cli.ops.tune", "RecordResult": "sherpa_cli.log.record_run",
         "Recording": "sherpa_cli.log.recording", "ArmState": "sherpa_cli.ops.state",
         "DriveState": "sherpa_cli.ops.state", "JointLimits": "sherpa_cli.ops.state", "JointState": "sherpa_cli.ops.state"}

if not TYPE_CHECKING:  # hidden from mypy, which then still refuses a name that is not exported above

    def __getattr__(name: str) -> object:
        home = _HOME.get(name)
        if home is None:
            raise AttributeError(f"module 'sherpa_cli.api' has no attribute {name!r}")
        import importlib

        value = getattr(importlib.import_module(home), name)
        globals()[name] = value  # once: later look-ups do not come back here
        return value

    def __dir__() -> list[str]:
        return sorted([*globals(), *__all__])
