"""`Arm`: the SHERPA arm from Python, with the same rules as the CLI (which is a thin layer over it).

One :class:`Arm` is one session: its buses open (or the in-process simulated arm), drive clients
on demand, every temporary drive change put back when it closes. Results are the same dataclasses
the commands render; a refusal or failure raises the same :class:`~sherpa_cli.errors.SherpaError`
the command exits with (its ``exit_code`` says which), unless the call passes ``check=False`` and
looks at the report itself. Writes are dry runs unless ``apply=True``; a save needs ``save=True``
and a ``confirm_save`` that says yes -- as ``--apply``, ``--save`` and ``--yes`` on the command line.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

from sherpa_cli.api import programming
from sherpa_cli.api.programming import ConfirmSave, ProgramReport, refuse_unconfirmed

if TYPE_CHECKING:
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.config.model import ArmConfig
    from sherpa_cli.ops.program import DrivePlan
    from sherpa_cli.ops.scan import ScanReport
    from sherpa_cli.ops.stop import StopReport

#: per-bus scan progress: (bus, phase, done, total)
ScanProgress = Callable[[str, str, int, int], None]


class Arm:
    """An open session with the arm. Build it with :meth:`open` (or wrap a session the caller owns)."""

    def __init__(self, session: ArmSession) -> None:
        self._session = session

    @classmethod
    @contextmanager
    def open(cls, config: str | Path | ArmConfig, *, sim: bool = False, bus_map: Sequence[str] = (),
             buses: Iterable[str] | None = None, best_effort: bool = False) -> Iterator[Arm]:
        """Open the arm described by ``config`` (a YAML file or a loaded config).

        ``sim``: the in-process simulated arm instead of the buses (its drives' flash and RAM live in
        the state directory, as with ``sherpa --sim``). ``bus_map``: entries as ``--bus-map`` takes them
        (``"can0=socketcan:can0"``). ``buses``: open only these. ``best_effort``: a bus that cannot be
        opened does not keep the others closed (what :meth:`stop` wants).
        """
        from sherpa_cli.bus.busmap import apply_bus_map, parse_bus_map
        from sherpa_cli.bus.session import ArmSession
        from sherpa_cli.config import load_config
        from sherpa_cli.errors import UsageError

        cfg = load_config(config) if isinstance(config, str | Path) else config
        mapping = parse_bus_map(list(bus_map))
        if mapping and sim:
            raise UsageError("sim and bus_map exclude each other: sim already maps every bus to the simulator")
        if mapping:
            cfg = apply_bus_map(cfg, mapping)
        arm = None
        if sim:
            from sherpa_cli.sim.arm import SimArm

            arm = SimArm.in_process(cfg)
        with ArmSession.open(cfg, sim=arm, buses=buses, best_effort=best_effort) as session:
            yield cls(session)

    @property
    def session(self) -> ArmSession:
        """The open session (buses, drive clients): the seam to the lower layers."""
        return self._session

    @property
    def config(self) -> ArmConfig:
        return self._session.cfg

    @staticmethod
    def buses_of(cfg: ArmConfig, targets: Sequence[str] | None) -> list[str]:
        """The buses the drives of ``targets`` sit on (none: every drive), in config order."""
        from sherpa_cli.bus.targets import drive_refs

        refs = drive_refs(cfg, targets)
        return sorted({r.bus for r in refs}, key=list(cfg.buses).index)

    # ------------------------------------------------------------------ looking

    def scan(self, buses: Sequence[str] | None = None, *, reset: bool = False,
             progress: ScanProgress | None = None) -> ScanReport:
        """Which node ids answer on each bus (default: every open bus), checked against the config.

        ``reset=True`` first sends NMT reset communication to every node (their unsaved RAM is lost):
        the API's explicit form of ``sherpa scan --reset --apply``. Findings (missing, unexpected,
        duplicate) are in the report, not raised; a bus that failed is in ``report.bus_errors``.
        """
        from sherpa_cli.ops.scan import scan

        return scan(self._session, buses, reset=reset, progress=progress)

    # ------------------------------------------------------------------ stopping

    def stop(self, targets: Sequence[str] | None = None, *, check: bool = True) -> StopReport:
        """Stop the named drives (joints, pairs, drives; none: every drive) now: ST, standstill, MO=0.

        Best effort: a drive or bus that cannot be reached never keeps the others from being stopped.
        ``check``: raise "partly stopped" (SafetyError, exit 1) after every drive was tried.
        """
        from sherpa_cli.bus.targets import drive_refs
        from sherpa_cli.motion.settings import MotionSettings
        from sherpa_cli.ops.stop import StopReport, stop_drives

        cfg = self.config
        refs = drive_refs(cfg, targets)  # a pair or Σ/Δ joint means both motors
        settings = MotionSettings.from_config(cfg, self.buses_of(cfg, targets))
        report = StopReport(stop_drives(self._session, refs, settings))
        problem = report.problem()
        if check and problem is not None:
            raise problem
        return report

    # ------------------------------------------------------------------ writing parameters

    def program_limits(self, targets: Sequence[str] | None = None, *, apply: bool = False, save: bool = False,
                       verify_flash: bool = False, motor_off: bool = False,
                       confirm_save: ConfirmSave = refuse_unconfirmed,
                       on_plan: Callable[[Sequence[DrivePlan]], None] | None = None,
                       check: bool = True) -> ProgramReport:
        """Program the Appendix C limits the config derives (`sherpa program-limits`).

        A dry run unless ``apply``: the report's plans say, per drive and parameter, now / target /
        change. ``save``: SV after read-back, only where something changed, counted in the save
        ledger, and only if ``confirm_save(drives, proof)`` returns True. ``check``: raise the
        problem the run ended with (KeyboardInterrupt if it was interrupted).
        """
        from sherpa_cli.bus.targets import drive_names
        from sherpa_cli.joints.limits import derive_checked
        from sherpa_cli.ops.program import DriveTarget

        programming.check_options(apply, save)
        cfg = self.config
        derived, warnings = derive_checked(cfg, drive_names(cfg, targets))
        drives = [DriveTarget(d.drive, d.bus, d.node, d.params) for d in derived]
        warnings = programming.check(drives, warnings)
        report = programming.run(self._session, drives, apply=apply, save=save, motor_off=motor_off,
                                 need_serial=save, verify_flash=verify_flash, warnings=warnings,
                                 confirm_save=confirm_save, on_plan=on_plan)
        if check:
            report.check()
        return report
