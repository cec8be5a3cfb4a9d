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
    from collections.abc import Mapping

    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.config.model import ArmConfig
    from sherpa_cli.motion.axis import Axis
    from sherpa_cli.motion.request import MoveRequest, Value
    from sherpa_cli.motion.settings import MotionSettings
    from sherpa_cli.ops import jog as plain_jog
    from sherpa_cli.ops import joint_jog
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

    # ------------------------------------------------------------------ moving

    def jog(self, name: str, *, to: Value = None, by: Value = None, velocity: Value = None, torque: Value = None,
            duration: float | None = None, uncalibrated: bool = False,
            on_progress: Callable[[object], None] | None = None) -> plain_jog.JogResult | joint_jog.JogResult:
        """Move one joint, Σ/Δ joint, pair motor or drive (`sherpa jog NAME ... --apply`).

        Exactly one of ``to``/``by`` (position), ``velocity`` (with ``duration`` for a pair) or
        ``torque`` (with ``duration``); numbers are rad, rad/s and A, text takes units as the
        command line does (``"10deg"``, ``"300counts/s"``, ``"800mA"``). It runs inside the motion
        guard: fault check, the dead-man armed, the joint's limits watched, and the motor stopped
        from standstill and switched off on every way out. A limit breach is a result (``breach``
        set, the joint brought back), not an exception; a refusal raises.
        """
        from sherpa_cli.motion.axis import resolve_axis
        from sherpa_cli.motion.request import parse_request

        given = [v for v in (to, velocity, torque) if v is not None] + ([by] if by is not None and to is None else [])
        if len(given) != 1:
            from sherpa_cli.errors import UsageError

            raise UsageError("give exactly one of to, by, velocity or torque")
        mode = "position" if to is not None or by is not None else "velocity" if velocity is not None else "torque"
        axis = resolve_axis(self.config, name)
        req = parse_request(axis, mode, to=to, by=by, velocity=velocity, torque=torque, duration=duration,
                            uncalibrated=uncalibrated)
        return self.move(axis, req, on_progress=on_progress)

    def move(self, axis: Axis, request: MoveRequest, *, settings: MotionSettings | None = None,
             on_progress: Callable[[object], None] | None = None,
             clock: Callable[[], float] | None = None, sleep: Callable[[float], None] | None = None
             ) -> plain_jog.JogResult | joint_jog.JogResult:
        """Run one parsed request on one axis (motion/axis.py, motion/request.py): what :meth:`jog`
        and the `jog` command both end in. A pair's axis (Σ/Δ joint, pair motor) moves both motors.
        ``clock``/``sleep``: the time the move runs on (default wall time; tests step it)."""
        import time

        from sherpa_cli.motion.settings import MotionSettings
        from sherpa_cli.ops import jog as plain_jog
        from sherpa_cli.ops import joint_jog

        now, wait = clock or time.monotonic, sleep or time.sleep
        if axis.pair is not None:
            return joint_jog.run(self._session, axis, request, on_progress=_typed_progress(on_progress),
                                 clock=now, sleep=wait)
        plain_jog.check_request(axis, request, max_torque_for=self.config.motion.max_torque_for)
        if settings is None:
            settings = MotionSettings.from_config(self.config, [axis.ref.bus])
        return plain_jog.run_jog(self._session, axis, request, settings=settings, on_progress=on_progress,
                                 clock=now, sleep=wait)

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


def _typed_progress(on_progress: Callable[[object], None] | None) -> Callable[[Mapping[str, int]], None] | None:
    """A pair jog reports the watched joints' positions (counts): handed on as they are."""
    if on_progress is None:
        return None
    return lambda joints: on_progress(joints)
