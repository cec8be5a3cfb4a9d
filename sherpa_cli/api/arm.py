"""`Arm`: the SHERPA arm from Python, with the same rules as the CLI (which is a thin layer over it).

One :class:`Arm` is one session: its buses open (or the in-process simulated arm), drive clients
on demand, every temporary drive change put back when it closes. Results are the same dataclasses
the commands render; a refusal or failure raises the same :class:`~sherpa_cli.errors.SherpaError`
the command exits with (its ``exit_code`` says which), unless the call passes ``check=False`` and
looks at the report itself. Writes are dry runs unless ``apply=True``; a save needs ``save=True``
and a ``confirm_save`` that says yes -- as ``--apply``, ``--save`` and ``--yes`` on the command line.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

from sherpa_cli.api import programming
from sherpa_cli.api.programming import ConfirmSave, ProgramReport, refuse_unconfirmed

if TYPE_CHECKING:
    from datetime import datetime

    from sherpa_cli.api.joint import JointHandle
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.config.model import ArmConfig, JoystickConfig
    from sherpa_cli.devices.ft_sensor import Wrench
    from sherpa_cli.joints.trajectory import Trajectory
    from sherpa_cli.log.foxglove_live import LiveView
    from sherpa_cli.log.record_run import RecordPlan, RecordResult, RecordTime, Wait
    from sherpa_cli.motion.axis import Axis
    from sherpa_cli.motion.request import MoveRequest, Value
    from sherpa_cli.motion.run import MotionOutcome
    from sherpa_cli.motion.settings import MotionSettings
    from sherpa_cli.ops.diffdrive import MoveResult
    from sherpa_cli.ops.doctor import DoctorReport
    from sherpa_cli.ops.drive_record import DriveRecordResult
    from sherpa_cli.ops.drive_step import DriveStep
    from sherpa_cli.ops.ft import BiasResult
    from sherpa_cli.ops.home import HomeReport, UnitResult
    from sherpa_cli.ops.identify import IdentifyReport
    from sherpa_cli.ops.jog_result import JogResult
    from sherpa_cli.ops.joystick import EventSource, JoystickRun
    from sherpa_cli.ops.live_jog import LiveJog
    from sherpa_cli.ops.monitor import MonitorStream
    from sherpa_cli.ops.motion_session import MotionSession
    from sherpa_cli.ops.move import PoseTargets, PreparedMove
    from sherpa_cli.ops.pair_match import MatchResult
    from sherpa_cli.ops.params_file import ParamDump
    from sherpa_cli.ops.play import PlayResult, PreparedPlay
    from sherpa_cli.ops.poses import PoseDiff, SavedPose
    from sherpa_cli.ops.program import DrivePlan, DriveTarget
    from sherpa_cli.ops.raw import RawRun
    from sherpa_cli.ops.recover import RecoverReport
    from sherpa_cli.ops.scan import ScanReport
    from sherpa_cli.ops.state import ArmState
    from sherpa_cli.ops.step import StepResult, StepTime
    from sherpa_cli.ops.stop import StopReport
    from sherpa_cli.ops.tune import GainReading
    from sherpa_cli.ops.tune_step import TuneStepResult

#: per-bus scan progress: (bus, phase, done, total)
ScanProgress = Callable[[str, str, int, int], None]


def gain_texts(gains: Mapping[str, object] | Sequence[str] | str) -> list[str]:
    """Gains as `tune set` reads them (``KP[2]=0.8``): a mapping's values may be any real number
    (a numpy float, a Fraction), written as the float they are; text stays as it is."""
    import numbers

    from sherpa_cli.errors import UsageError

    if isinstance(gains, str):
        return [gains]
    if not isinstance(gains, Mapping):
        return list(gains)
    out = []
    for key, value in gains.items():
        if isinstance(value, str):
            out.append(f"{key}={value}")
        elif isinstance(value, numbers.Real) and not isinstance(value, bool):
            try:
                out.append(f"{key}={float(value)!r}")
            except OverflowError:
                raise UsageError(f"{key}: {value!r} is too large for a gain") from None
        else:
            raise UsageError(f"{key}: {value!r} is not a number")
    return out

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

        ``reset=True`` first sends NMT reset communication to every node (their communication objects --
        PDOs, heartbeat consumer and producer -- back to their saved values; CiA 301 keeps the
        application's RAM, a drive that reboots instead loses it):
        the API's explicit form of ``sherpa scan --reset --apply``. Findings (missing, unexpected,
        duplicate) are in the report, not raised; a bus that failed is in ``report.bus_errors``.
        """
        from sherpa_cli.ops.scan import scan

        return scan(self._session, buses, reset=reset, progress=progress)

    def state(self, targets: Sequence[str] | None = None, *,
              clock: Callable[[], float] | None = None) -> ArmState:
        """Where the joints are and what their drives are doing, in joint units: one snapshot.

        ``targets``: joints, pairs or drives (none: every joint); a drive means the joints its motor
        moves, a Σ/Δ joint is computed from both motors of its pair. Per joint: position (rad),
        velocity (rad/s), current (A), calibrated, motor on, unit mode and the faults decoded
        (``state["elbow_pitch"].position``; ``state.drives`` holds each drive in counts). The drives
        are NMT-started first, as the commands do; nothing is written. A drive that does not answer
        raises CommunicationError. ``clock``: what ``state.at`` is read from (default monotonic).
        """
        import time

        from sherpa_cli.ops.state import read_state

        return read_state(self._session, targets, clock=clock or time.monotonic)

    def joint(self, name: str) -> JointHandle:
        """A handle on one joint (a plain or Σ/Δ joint): ``.position`` (rad), ``.velocity`` (rad/s),
        ``.status`` (its :class:`~sherpa_cli.ops.state.JointState`) and ``.limits`` (the configured
        limits in joint units). Each read asks the drives again."""
        from sherpa_cli.api.joint import JointHandle

        return JointHandle(self, name)

    def pose_diff(self, name: str) -> PoseDiff:
        """How far the joints of pose ``name`` (config ``poses:``) stand from it, in rad and counts; a
        joint that is not calibrated has no known position (``None``). Only reads."""
        from sherpa_cli.ops.poses import diff_pose, pose_named

        pose = pose_named(self.config, name)
        return diff_pose(self.config, pose, self.state(list(pose.counts)))

    def save_pose(self, name: str, joints: Sequence[str] | None = None, *, replace: bool = False) -> SavedPose:
        """Teach pose ``name``: where ``joints`` (default: every joint) stand now, written into the
        config file this arm was opened with (its comments and layout kept; the new text checked as
        a config before it replaces the file). Every joint must be calibrated; an existing pose only
        with ``replace``. Moves nothing; reads the drives only. The config in memory is not reloaded:
        open the arm again to move to the new pose."""
        from sherpa_cli.ops.poses import save_pose

        return save_pose(self.config, name, self.state(joints), replace=replace)

    def identify(self, targets: Sequence[str] | None = None, *,
                 progress: Callable[[str, str], None] | None = None) -> IdentifyReport:
        """Who each drive is and what state it is in (`sherpa identify`): identity over SDO (0x1000,
        0x1008-0x100A, 0x1018), MO, UM, SR, MF, PX and PS, each drive's joint position, and findings
        (a device name that is not the config's model, firmware or product code that differs from the
        other drives of that model). ``targets``: drives, joints or pairs (none: every drive). A drive
        that does not answer is in ``report.errors`` (and its row's ``error``), not raised."""
        from sherpa_cli.bus.targets import drive_names
        from sherpa_cli.ops.identify import identify

        return identify(self._session, drive_names(self.config, targets, elmo_only="identify"), progress)

    def dump_params(self, path: str | Path | None = None, targets: Sequence[str] | None = None, *,
                    progress: Callable[[str, str], None] | None = None,
                    now: Callable[[], datetime] | None = None) -> ParamDump:
        """Read the parameters commissioning touches and the identity of each drive (`sherpa
        dump-params`); with ``path`` also write the YAML file (atomically; the file `params restore`
        and `params diff` read). ``targets``: drives, joints or pairs (none: every drive). A drive
        that does not answer raises before anything is written. ``now``: the dump's date (UTC;
        ``$SHERPA_DUMP_DATE`` wins, as on the command line)."""
        from sherpa_cli.bus.targets import drive_names
        from sherpa_cli.ops.params_file import write_dump
        from sherpa_cli.ops.params_read import dump_params

        dump = dump_params(self._session, drive_names(self.config, targets, elmo_only="dump-params"), progress, now)
        if path is not None:
            write_dump(Path(path), dump, "path")
        return dump

    def record(self, targets: Sequence[str] | None = None, rate: float = 100.0, duration: float = 1.0, *,
               current: bool | None = None, poll: bool = False, status: bool = True,
               stream_to: str | Path | None = None, view: LiveView | None = None,
               timebase: RecordTime | None = None, wait: Wait | None = None,
               plan: RecordPlan | None = None, check: bool = True) -> RecordResult:
        """Record position and velocity (and current) of ``targets`` (joints, pairs, drives, an encoder
        device; none: every drive) at ``rate`` Hz for ``duration`` s, into memory (`sherpa log record`
        without the files): TPDOs on SYNC, the drives' PDO settings RAM only and put back on every way
        out, never saved. A rate the bus cannot carry is refused (UsageError) before anything is sent.

        The result holds the samples with their timestamps (``result.recording``: ``.times`` in s,
        ``.joint(name)`` in rad, rad/s and A, ``.drive(name)`` in counts) and what arrived per drive;
        ``result.write_csv(path)`` and ``result.write_mcap(path)`` write the files the command writes.
        ``current``: also sample the current (None: when the bus budget allows). ``poll``: through the
        interpreter instead (changes nothing on the drives, slow). ``status``: the drives' status read
        before and after, the EMCYs heard (the MCAP's). ``stream_to``: a CSV file the rows go to as they
        come instead of memory. ``view``: a Foxglove live view to feed. ``timebase``: the clock, sleep
        and SYNC source (default wall time; sim/stepped.py steps it). ``wait``: how to wait for the end
        (default: sleep on the timebase; Ctrl-C ends it early, ``result.interrupted``). ``plan``: the
        plan a caller already made with ``log.record_run.plan_record`` for these arguments.
        Another SYNC producer on the bus ends the recording early: raised (CommunicationError) after the
        drives are restored, unless ``check=False`` (then ``result.failure``, the samples so far kept).
        """
        from sherpa_cli.log.record_run import check_budget, check_record_values, plan_record, run_record

        check_record_values(duration, rate)
        if plan is None:
            plan = plan_record(self.config, targets, rate, current=current, poll=poll)
            check_budget(plan)
        result = run_record(self._session, plan, duration, wait=wait, status=status, view=view, timebase=timebase,
                            stream_to=None if stream_to is None else Path(stream_to))
        if check:
            result.check()
        return result

    def record_drives(self, targets: Sequence[str] | None = None, duration: float = 0.5, *, trigger: str = "now",
                      clock: Callable[[], float] | None = None,
                      sleep: Callable[[float], None] | None = None) -> DriveRecordResult:
        """Record with the drives' own recorders at the servo rate (`sherpa log record --source drive`):
        position, velocity, active current, position error and speed command of every drive of
        ``targets`` (both motors of a pair with the same settings), started now or (``trigger="bg"``)
        at the next BG of a move started elsewhere. The recorder settings are RAM only and put back on
        every way out. A time the recorder cannot hold is refused before anything is sent. The result's
        ``recording`` is in joint units with counts beside, as :meth:`record`'s."""
        import time

        from sherpa_cli.bus.targets import drive_refs
        from sherpa_cli.elmo.recorder import RecorderSettings, plan_recording
        from sherpa_cli.errors import UsageError
        from sherpa_cli.ops.drive_record import record_drives

        if trigger not in ("now", "bg"):
            raise UsageError(f"--trigger {trigger}: expected now or bg")
        plan_recording(duration, RecorderSettings())  # a time the recorder cannot hold: refused before the bus
        refs = drive_refs(self.config, targets, configured_only=True)
        return record_drives(self._session, refs, duration, trigger="bg" if trigger == "bg" else "now",
                             clock=clock or time.monotonic, sleep=sleep or time.sleep)

    def monitor(self, targets: Sequence[str] | None = None, *, interval: float = 0.5, count: int | None = None,
                duration: float | None = None, heartbeat_ms: int | None = None, apply: bool = False,
                wait_for_heartbeats: bool = False, clock: Callable[[], float] | None = None,
                sleep: Callable[[float], None] | None = None) -> MonitorStream:
        """What the drives are doing, as `sherpa monitor` shows it: an iterator of
        :class:`~sherpa_cli.ops.monitor.MonitorSnapshot`, one per poll, ``interval`` s apart.

        ``targets``: drives, joints or pairs (none: every drive). Each snapshot holds per drive the NMT
        state and heartbeat, MO, UM, PX (counts) and its joint's position (rad), SR and MF decoded and
        the last EMCY; a drive that does not answer is ``answering=False``, never its old values.
        Bounded by ``count`` snapshots or ``duration`` s on ``clock`` (the first at once, none started
        after that); with neither it runs until the caller stops. Use it in a ``with`` (or exhaust it):
        leaving stops the polling. The drives are NMT-started, then only read, unless
        ``heartbeat_ms`` with ``apply=True`` sets their producer heartbeat (0x1017, RAM only, put back
        at the end). ``wait_for_heartbeats``: the first snapshot waits until each drive that produces a
        heartbeat was heard. ``clock``/``sleep``: the time it runs on (default wall time).
        """
        import time

        from sherpa_cli.bus.targets import drive_refs
        from sherpa_cli.errors import UsageError
        from sherpa_cli.ops.monitor import MonitorStream

        if heartbeat_ms is not None and not apply:
            raise UsageError(f"heartbeat_ms={heartbeat_ms} writes 0x1017: give apply=True to write it",
                             hint="without it the monitor only listens to the heartbeat the drives already send")
        return MonitorStream(self._session, drive_refs(self.config, targets), interval=interval, count=count,
                             duration=duration, heartbeat_ms=heartbeat_ms, clock=clock or time.monotonic,
                             sleep=sleep or time.sleep, first_waits_for_heartbeats=wait_for_heartbeats)

    def doctor(self, buses: Sequence[str] | None = None, *, report: DoctorReport | None = None,
               window: float = 1.0, clock: Callable[[], float] | None = None,
               sleep: Callable[[float], None] | None = None) -> DoctorReport:
        """The drive checks of `sherpa doctor` on ``buses`` (default: every open bus): every configured
        drive answers, model and firmware, heartbeats, nobody else on the host's node id (listened to
        for ``window`` s on ``clock``/``sleep``), user programs, calibration. Each check is a row of the
        report (``report.failed`` lists what failed, with its fix); ``report``: add to this one. Only
        reads."""
        import time

        from sherpa_cli.ops import doctor

        out = report if report is not None else doctor.DoctorReport()
        doctor.check_drives(out, self._session, list(buses) if buses is not None else list(self._session.links),
                            window=window, clock=clock or time.monotonic, sleep=sleep or time.sleep)
        return out

    def wrench(self, name: str | None = None, *, wait_s: float | None = None) -> Wrench:
        """One reading of the F/T sensor ``name`` (None: the arm's only one): force in N and torque in
        N·m in the sensor frame, with the sample's status word and number. Only reads (one request frame).

        Raises UsageError when the arm has no such sensor and DriveTimeoutError (a CommunicationError)
        when it does not answer within ``wait_s`` (default: the sensor's ``reply_ms``).
        """
        from sherpa_cli.devices.ft_sensor import open_reader, sensor_named

        dev = sensor_named(self.config, name)
        self._session.open_bus(dev.bus)  # an arm opened on other buses: its bus too, as the guard does
        with open_reader(self._session, dev, wait_s=wait_s) as reader:
            return reader.read()

    def wrenches(self, name: str | None = None, *, count: int | None = None, rate: float = 10.0,
                 sleep: Callable[[float], None] | None = None) -> Iterator[Wrench]:
        """Readings of the F/T sensor ``name`` (None: the arm's only one), one every 1/``rate`` s on
        ``sleep`` (`sherpa ft show`): ``count`` of them, or until the caller stops. Only reads."""
        import time

        from sherpa_cli.devices.ft_sensor import sensor_named
        from sherpa_cli.ops.ft import MAX_RATE_HZ, stream

        if not (0 < rate <= MAX_RATE_HZ):
            from sherpa_cli.errors import UsageError

            raise UsageError(f"--rate {rate}: expected samples per second > 0 and <= {MAX_RATE_HZ:g}")
        return stream(self._session, sensor_named(self.config, name), count=count, period=1 / rate,
                      sleep=sleep or time.sleep)

    def ft_bias(self, name: str | None = None, *, apply: bool = False) -> BiasResult:
        """Zero the F/T sensor ``name`` (None: the arm's only one) at its present load (`sherpa ft
        bias`): a reading, then with ``apply`` the bias command and a reading after it. Without
        ``apply`` a dry run: the result says the frame that would be sent."""
        from sherpa_cli.devices.ft_sensor import sensor_named
        from sherpa_cli.ops.ft import bias

        return bias(self._session, sensor_named(self.config, name), apply=apply)

    def command(self, target: str, exprs: Sequence[str], *, apply: bool = False, raw_save: bool = False,
                check: bool = True) -> RawRun:
        """Raw interpreter commands to one drive (`sherpa cmd DRIVE EXPR...`): queries (``"PX"``) are
        sent; sets and executes (``"LL[3]=-240"``, ``"BG"``) only with ``apply`` (else the result says
        the frame that would go). Every expression is parsed before anything is sent. MO=1 or BG with
        ``apply`` run inside the motion guard (dead-man armed, the motor stopped and off at the end);
        SV only with ``apply`` and ``raw_save``, once, counted in the save ledger. ``check``: raise the
        error that ended the run (else ``run.error``, with the results up to it)."""
        from sherpa_cli.bus.targets import single_drive
        from sherpa_cli.errors import SherpaError
        from sherpa_cli.joints.limits import il_roles
        from sherpa_cli.motion.settings import MotionSettings
        from sherpa_cli.ops.raw import (
            RawResult,
            RawRun,
            check_raw_save,
            parse_all,
            run_raw,
            run_raw_guarded,
            starts_motion,
        )

        cfg = self.config
        ref = single_drive(cfg, target, elmo_only="cmd")
        parse_all(exprs)  # a typo must not reach the bus, not even the NMT start
        saving = check_raw_save(exprs, apply=apply, raw_save=raw_save)  # before anything is sent
        run = RawRun(ref.name, apply)
        session = self._session
        client = session.client(ref)
        try:
            on_save: Callable[[RawResult], None] | None = None
            if saving:
                from sherpa_cli.ops.program import DriveTarget, read_serial
                from sherpa_cli.ops.save_ledger import SaveLedger

                # the serial number is read before SV goes out (a save that cannot be counted is not sent)
                serial = read_serial(session, DriveTarget(ref.name, ref.bus, ref.node, {}))
                ledger = SaveLedger()

                def counted(result: RawResult) -> None:
                    record = ledger.record(serial, ref.name)
                    result.decoded = [f"saved (save {record.count} of this drive by this tool)"]
                    if record.warning:
                        run.warnings.append(record.warning)

                on_save = counted
            client.nmt_start()
            if apply and starts_motion(exprs):
                run_raw_guarded(session, ref, exprs, MotionSettings.from_config(cfg, [ref.bus]),
                                query_long=cfg.protocol.query_long, results=run.results, on_save=on_save,
                                il_roles=il_roles(cfg), on_exit=run.stopped)
            else:
                run_raw(client, ref.node, exprs, apply=apply, query_long=cfg.protocol.query_long,
                        results=run.results, on_save=on_save, il_roles=il_roles(cfg))
        except SherpaError as exc:
            run.error = exc
        if check and run.error is not None:
            raise run.error
        return run

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

    def recover(self, targets: Sequence[str] | None = None, *, apply: bool = False,
                check_drives: bool = False, check: bool = True) -> RecoverReport:
        """Put back what commands that did not finish left on the drives (`sherpa recover`): every
        temporary change the journal in the state directory notes (UM, SP/AC/DC, the dead-man objects,
        the pair's group id, TPDO settings, ...), last change first, and a tripped dead-man cleared
        under a dead-man of its own. A dry run (NMT start and reads only) unless ``apply``.
        ``check_drives``: also read every other target drive for what a command leaves (a journal
        deleted by hand, another host's command); with ``apply`` a drive with a finding is reset.
        ``report.not_recovered`` names the drives still not as they should be; with ``check`` (the
        default) they raise SafetyError, the error `sherpa recover` exits with, after the report."""
        from sherpa_cli.errors import SafetyError
        from sherpa_cli.ops.recover import plan_recover, recover

        report = recover(self._session, plan_recover(self.config, targets), apply=apply, check_drives=check_drives)
        if check and report.not_recovered:
            raise SafetyError(f"not recovered: {', '.join(report.not_recovered)}",
                              hint="report.results and report.checks name the problems")
        return report

    # ------------------------------------------------------------------ moving

    def jog(self, name: str, *, to: Value = None, by: Value = None, velocity: Value = None, torque: Value = None,
            duration: float | None = None, uncalibrated: bool = False, hold: bool = False,
            on_progress: Callable[[object], None] | None = None, force_limit: float | None = None) -> JogResult:
        """Move one joint, Σ/Δ joint, pair motor or drive (`sherpa jog NAME ... --apply`).

        Exactly one of ``to``/``by`` (position), ``velocity`` (with ``duration`` for a pair) or
        ``torque`` (with ``duration``); numbers are rad, rad/s and A, text takes units as the
        command line does (``"10deg"``, ``"300counts/s"``, ``"800mA"``). It runs inside the motion
        guard: fault check, the dead-man armed, the joint's limits watched, and the motor stopped
        from standstill and switched off on every way out. A limit breach is a result (``ok``
        False, ``breaches`` set, the joint brought back), not an exception; a refusal raises.
        ``hold``: afterwards the motors hold where they ended, the dead-man armed, until Ctrl-C
        (KeyboardInterrupt, a normal end then: ``ended_by`` / ``held_until`` say so) or `sherpa stop`.
        Every kind of axis returns the one :class:`~sherpa_cli.ops.jog_result.JogResult`: counts as
        the drives count them (``start_counts``, ``end_counts``) and rad beside them (``start_rad``,
        ``end_rad``). ``force_limit`` (N): tighter than the F/T sensor's own for this move
        (`--force-limit`); crossing it raises ForceLimitError with every motor stopped (docs/motion.md).
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
                            uncalibrated=uncalibrated, hold=hold)
        return self.move(axis, req, on_progress=on_progress, force_limit=force_limit)

    def move(self, axis: Axis, request: MoveRequest, *, settings: MotionSettings | None = None,
             on_progress: Callable[[object], None] | None = None,
             clock: Callable[[], float] | None = None, sleep: Callable[[float], None] | None = None,
             force_limit: float | None = None) -> JogResult:
        """Run one parsed request on one axis (motion/axis.py, motion/request.py): what :meth:`jog`
        and the `jog` command both end in. A pair's axis (Σ/Δ joint, pair motor) moves both motors.
        ``clock``/``sleep``: the time the move runs on (default wall time; tests step it).
        ``force_limit``: as :meth:`jog`'s."""
        with self._force_limit(force_limit):
            return self._move(axis, request, settings=settings, on_progress=on_progress, clock=clock, sleep=sleep)

    @contextmanager
    def _force_limit(self, value: float | None) -> Iterator[None]:
        """The session's F/T force limit for one call (every motion guard of the session watches it);
        None leaves the session's as it is (the `--force-limit` of a command)."""
        if value is None:
            yield
            return
        from sherpa_cli.motion.force_watch import check_force_limit

        check_force_limit(value, "force_limit")
        before, self._session.force_limit = self._session.force_limit, value
        try:
            yield
        finally:
            self._session.force_limit = before

    def _move(self, axis: Axis, request: MoveRequest, *, settings: MotionSettings | None,
              on_progress: Callable[[object], None] | None,
              clock: Callable[[], float] | None, sleep: Callable[[float], None] | None) -> JogResult:
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

    def home(self, joints: Sequence[str] | None = None, *, measure_range: bool = False,
             settings: MotionSettings | None = None, on_unit: Callable[[UnitResult], None] | None = None,
             on_step: Callable[[str], None] | None = None, report: HomeReport | None = None,
             clock: Callable[[], float] | None = None, sleep: Callable[[float], None] | None = None
             ) -> HomeReport:
        """Calibrate joints (`sherpa home JOINT... --yes`): find their switches or read their absolute
        encoder, set the drive's counter and mark it calibrated. ``joints``: joints, pairs, Σ/Δ joints
        or drives; none: every joint that can be homed (a named one that cannot is a UsageError).

        Calling it is the confirmation the command asks for: it moves at once, unit by unit, each
        inside the motion guard, and stops at the first failure (raised). ``on_unit`` sees each
        unit's result as it is done, ``on_step`` the running step; pass ``report`` to read, after
        an exception, which unit did not finish, the joints it left un-homed and how it stopped.
        ``measure_range``: end-switch joints also drive to the other switch and report the travel.
        """
        import time

        from sherpa_cli.errors import UsageError
        from sherpa_cli.ops.home import plan_home, run_home

        plan = plan_home(self.config, joints or None, measure_range=measure_range)
        if not plan.units:
            raise UsageError("nothing to home: no configured joint has a switch or an absolute encoder to home with")
        return run_home(self._session, plan, settings=settings, clock=clock or time.monotonic,
                        sleep=sleep or time.sleep, on_unit=on_unit, on_step=on_step, report=report)

    def diffdrive_move(self, pair: str, *, sigma: Value = None, delta: Value = None, relative: bool = False,
                       velocity: Value = None, feedback: bool = False, naive: bool = False,
                       uncalibrated: bool = False, poll: bool = False, source: str = "can", hold: bool = False,
                       on_event: Callable[[str], None] | None = None,
                       on_progress: Callable[[Mapping[str, int]], None] | None = None,
                       timebase: StepTime | None = None, force_limit: float | None = None) -> MoveResult:
        """Move the Σ and Δ joints of a pair together (`sherpa diffdrive move PAIR ... --apply`).

        ``pair``: the pair, or one of its joints or motors. ``sigma``/``delta``: targets (offsets with
        ``relative``); a joint left out holds; numbers are rad, text takes units (``"10deg"``,
        ``"200counts"``). ``velocity``: the speed of the joint that moves farthest (default: the
        joints' limits). Both motors start together, are recorded (``poll``: PX polled; ``source=
        "drive"``: the drives' own recorders) and the coupling is measured. A limit breach is a
        result (``result.ok`` False), a refusal raises. ``hold``: afterwards both motors hold where
        they ended, the dead-man armed, until Ctrl-C (KeyboardInterrupt, a normal end then) or
        `sherpa stop`; ``on_progress`` sees Σ and Δ (counts) meanwhile. ``timebase``: the clock, waits
        and SYNC source the move runs on (default wall time; tests step it, sim/stepped.py).
        ``force_limit``: as :meth:`jog`'s.
        """

        from sherpa_cli.bus.targets import pair_of
        from sherpa_cli.ops import diffdrive

        def text(v: Value) -> str | None:
            return None if v is None else v if isinstance(v, str) else repr(float(v))

        req = diffdrive.PairTarget(sigma=text(sigma), delta=text(delta), relative=relative, velocity=text(velocity),
                                   naive=naive, feedback=feedback, uncalibrated=uncalibrated, poll=poll,
                                   source=source, hold=hold)
        p = pair_of(self.config, pair)
        with self._force_limit(force_limit):
            return diffdrive.run_move(self._session, p, req, on_event=on_event, timebase=timebase,
                                      on_progress=on_progress)

    def plan_pose(self, pose: str | PoseTargets, *, joints: Sequence[str] | None = None, speed_scale: float = 1.0,
                  uncalibrated: bool = False) -> PreparedMove:
        """The plan of :meth:`move_pose` without moving (`sherpa move POSE` without --apply): where
        each joint stands (read from the drives; NMT start is all that is sent), where it goes, at
        what speed, and the move's time (``prepared.plan``). Refuses what :meth:`move_pose` refuses."""
        from sherpa_cli.ops.move import prepare

        return prepare(self._session, pose, joints=joints, speed_scale=speed_scale, uncalibrated=uncalibrated)

    def run_pose(self, prepared: PreparedMove, *, hold: bool = False,
                 on_event: Callable[[str], None] | None = None,
                 on_progress: Callable[[Mapping[str, int]], None] | None = None,
                 clock: Callable[[], float] | None = None, sleep: Callable[[float], None] | None = None
                 ) -> MotionOutcome:
        """Run a plan from :meth:`plan_pose` (what :meth:`move_pose` does after planning)."""
        import time

        from sherpa_cli.ops.move import run_move

        return run_move(self._session, prepared, hold=hold, on_event=on_event, on_progress=on_progress,
                        clock=clock or time.monotonic, sleep=sleep or time.sleep)

    def move_pose(self, pose: str | PoseTargets, *, joints: Sequence[str] | None = None, speed_scale: float = 1.0,
                  uncalibrated: bool = False, hold: bool = False, force_limit: float | None = None,
                  on_event: Callable[[str], None] | None = None,
                  on_progress: Callable[[Mapping[str, int]], None] | None = None,
                  clock: Callable[[], float] | None = None, sleep: Callable[[float], None] | None = None
                  ) -> MotionOutcome:
        """Move several joints together (`sherpa move POSE --apply`): ``pose`` is a pose of the config
        by name, or a mapping joint -> position (rad, or text with a unit: ``"10deg"``); ``joints``
        keeps only those of the pose. Every joint starts and arrives together: the joint that needs
        the most time at its speed limit (times ``speed_scale``) sets the time. One motion guard
        over every motor, the limit watch on every joint; a breach is a result (``ok`` False, every
        joint stopped, the joint brought back), a refusal or fault raises. The result has, per
        joint, from/to/end/error in counts and rad and its arrival time. ``hold``: afterwards every
        motor holds until Ctrl-C (a normal end) or `sherpa stop`. ``force_limit``: as :meth:`jog`'s."""
        with self._force_limit(force_limit):
            prepared = self.plan_pose(pose, joints=joints, speed_scale=speed_scale, uncalibrated=uncalibrated)
            return self.run_pose(prepared, hold=hold, on_event=on_event, on_progress=on_progress, clock=clock,
                                 sleep=sleep)

    def plan_play(self, trajectory: str | Path | Trajectory, *, uncalibrated: bool = False) -> PreparedPlay:
        """The checks of :meth:`play` without moving (`sherpa move --trajectory FILE` without --apply):
        the path read (a `log record` CSV or MCAP, a planner's CSV; or a :class:`Trajectory`), checked
        against every joint's limits, resampled to the stream's period, and found to start where the
        arm stands (read from the drives; NMT start is all that is sent)."""
        from sherpa_cli.joints.trajectory import Trajectory
        from sherpa_cli.ops.play import prepare_play

        return prepare_play(self._session, trajectory if isinstance(trajectory, Trajectory) else Path(trajectory),
                            uncalibrated=uncalibrated)

    def play(self, trajectory: str | Path | Trajectory | PreparedPlay, *, uncalibrated: bool = False,
             force_limit: float | None = None, on_event: Callable[[str], None] | None = None,
             clock: Callable[[], float] | None = None, sleep: Callable[[float], None] | None = None) -> PlayResult:
        """Play a time-stamped multi-joint path (`sherpa move --trajectory FILE --apply`; docs/trajectory.md):
        checked as :meth:`plan_play` does, then streamed to the drives (Elmo PVT) in one motion guard.
        Every joint is watched while it plays: one outside its full range or farther than
        ``motion.tracking_bound`` from the path stops every joint (raised); so do a starved stream,
        an underflow, a fault and Ctrl-C. The result has the stream's periods on time and, per joint,
        the largest tracking error seen and where it ended."""
        import time

        from sherpa_cli.ops.play import PreparedPlay, run_play

        with self._force_limit(force_limit):
            prepared = trajectory if isinstance(trajectory, PreparedPlay) else \
                self.plan_play(trajectory, uncalibrated=uncalibrated)
            return run_play(self._session, prepared, on_event=on_event, clock=clock or time.monotonic,
                            sleep=sleep or time.sleep)

    def motion(self, joints: str | Sequence[str], *, uncalibrated: bool = False,
               on_event: Callable[[str], None] | None = None,
               clock: Callable[[], float] | None = None, sleep: Callable[[float], None] | None = None
               ) -> MotionSession:
        """One motion guard for several moves: ``with arm.motion(["elbow_pitch", "wrist_1"]) as m:``
        checks the joints' calibration (``uncalibrated`` allows joints not homed), arms the guard over
        every motor of the joints (fault check, the dead-man on every bus, the lock), then
        ``m.move_to({"elbow_pitch": 0.5, "wrist_1": 0.05})`` (a session of one joint also takes
        ``m.move_to(0.5)``), ``m.velocity({...}, for_=1.0)``, ``m.hold()``, ``m.stop()`` and
        ``m.positions()``. Each move returns a :class:`~sherpa_cli.motion.run.MotionOutcome`.
        Leaving the block stops every motor from standstill and switches it off; ``m.report`` says how."""
        import time

        from sherpa_cli.ops.motion_session import MotionSession

        return MotionSession(self._session, [joints] if isinstance(joints, str) else list(joints),
                             uncalibrated=uncalibrated, on_event=on_event, clock=clock or time.monotonic,
                             sleep=sleep or time.sleep)

    def log_step(self, name: str, mode: str, value: float, *, duration: float = 2.0, rate: float = 1000.0,
                 uncalibrated: bool = False, mode_first: bool = False, hold: float = 0.0,
                 settings: MotionSettings | None = None, on_event: Callable[[str], None] | None = None,
                 timebase: StepTime | None = None, from_mode: str | None = None) -> StepResult:
        """The seed's Section 9 step experiment (`sherpa log step NAME --MODE VALUE --apply`, without
        the files): record, command the step at t = 0 inside the motion guard, record until settled
        (or ``duration`` s after the step), stop, and compute the step metrics.

        ``name``: a plain joint or its drive (a Σ/Δ joint is refused: that is :meth:`diffdrive_move`).
        ``mode``: ``"position"`` (a step of ``value`` rad from where the joint stands),
        ``"velocity"`` (rad/s) or ``"torque"`` (A). ``rate``: samples per second. ``mode_first``,
        ``hold``, ``from_mode``: as ``--mode-first``, ``--hold``, ``--from-mode``. ``timebase``: the clock, waits and SYNC source
        (default wall time; `sherpa --sim log step` runs on the simulator's stepped time). The result
        holds the recording (``result.recording``) and the metrics; a limit breach is a result
        (``breach`` set), a refusal raises.
        """
        from sherpa_cli.motion.settings import MotionSettings
        from sherpa_cli.ops.step import resolve_step_target, run_step

        cfg = self.config
        if mode == "torque":
            from sherpa_cli.motion.settings import check_torque_for

            check_torque_for(duration, cfg.motion.max_torque_for)  # no drive limit acts in torque mode
        target = resolve_step_target(cfg, name)
        if settings is None:
            settings = MotionSettings.from_config(cfg, [target.ref.bus])
        return run_step(self._session, target, mode, value, duration=duration, rate=rate, settings=settings,
                        on_event=on_event, uncalibrated=uncalibrated, timebase=timebase, mode_first=mode_first,
                        hold=hold, from_mode=from_mode)

    def log_step_with_drive(self, name: str, mode: str, value: float, *, duration: float = 2.0, rate: float = 1000.0,
                            uncalibrated: bool = False, settings: MotionSettings | None = None,
                            timebase: StepTime | None = None) -> tuple[StepResult, DriveStep]:
        """:meth:`log_step` recorded twice at once (`sherpa log step --source drive`): over the bus at
        ``rate`` and by the drive's own recorder at the servo rate (armed just before the command, read
        once the guard has stopped the motor; its settings RAM only and put back on every way out).
        Returns the bus's step result and the drive's (``DriveStep``: its recording and metrics)."""
        import time

        from sherpa_cli.motion.settings import MotionSettings
        from sherpa_cli.ops.drive_step import DriveTrace
        from sherpa_cli.ops.step import resolve_step_target, run_step

        cfg = self.config
        target = resolve_step_target(cfg, name)
        if settings is None:
            settings = MotionSettings.from_config(cfg, [target.ref.bus])
        clock, sleep = (timebase.now, timebase.sleep) if timebase is not None else (time.monotonic, time.sleep)
        with DriveTrace(self._session, target.ref, duration, clock=clock, sleep=sleep) as trace:
            result = run_step(self._session, target, mode, value, duration=duration, rate=rate, settings=settings,
                              uncalibrated=uncalibrated, timebase=timebase, drive_trace=trace)
        drive = trace.result
        assert drive is not None  # run_step collects it or raises
        return result, drive

    # ------------------------------------------------------------------ moving live

    def live_jog(self, joints: Sequence[str] | None = None, *, uncalibrated: bool = False,
                 keepalive: float | None = None, tick_period: float = 0.1, settings: MotionSettings | None = None,
                 on_event: Callable[[str], None] | None = None, clock: Callable[[], float] | None = None,
                 sleep: Callable[[float], None] | None = None) -> LiveJog:
        """The engine of `sherpa jog --interactive` (ops/live_jog.py), for a program that commands
        joints continuously: ``with arm.live_jog(["elbow_pitch"]) as live:`` arms one motion guard over
        every drive of ``joints`` (none: every joint; a pair: both its joints), then
        ``live.set_velocity(name, counts_per_s)``, ``live.set_torque``, ``live.step``, ``live.stop``,
        ``live.stop_all`` command them, and ``live.tick()`` (call it every ``tick_period`` s) watches
        the limits and stops a velocity or torque command not refreshed within ``keepalive`` s.
        Leaving the ``with`` stops every motor from standstill; ``live.report`` says how.
        """
        import time

        from sherpa_cli.ops.live_jog import KEEPALIVE_S, LiveJog, resolve_axes

        return LiveJog(self._session, resolve_axes(self.config, joints), settings=settings,
                       keepalive=KEEPALIVE_S if keepalive is None else keepalive, allow_uncalibrated=uncalibrated,
                       tick_period=tick_period, clock=clock or time.monotonic, sleep=sleep or time.sleep,
                       on_event=on_event)

    def joystick_joints(self, mapping: JoystickConfig | None = None) -> list[str]:
        """The joints a joystick mapping drives (default: the config's ``joystick:``): what to open
        :meth:`live_jog` on before :meth:`joystick`."""
        from sherpa_cli.ops.joystick import joints_of

        return joints_of(self.config, mapping or self.config.joystick)

    def joystick(self, live: LiveJog, source: EventSource, *, mapping: JoystickConfig | None = None,
                 duration: float | None = None, on_status: Callable[[str], None] | None = None,
                 clock: Callable[[], float] | None = None, sleep: Callable[[float], None] | None = None
                 ) -> JoystickRun:
        """The loop of `sherpa jog --joystick` on an entered :meth:`live_jog`: read ``source``'s events
        (``ops.joystick.EvdevSource`` for a device, ``ScriptedSource`` for a script) and, while the
        dead-man is held, command each mapped joint (``mapping``, default the config's ``joystick:``)
        at its rate; a release stops every joint at once. Ends after ``duration`` s, when the device
        is gone, or at Ctrl-C (raised; the live jog's guard stops the motors)."""
        import time

        from sherpa_cli.ops.joystick import run_joystick

        return run_joystick(live, self.config, mapping or self.config.joystick, source,
                            clock=clock or time.monotonic, sleep=sleep or time.sleep, duration=duration,
                            on_status=on_status)

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
        derived, warnings = derive_checked(cfg, drive_names(cfg, targets, elmo_only="program-limits"))
        drives = [DriveTarget(d.drive, d.bus, d.node, d.params) for d in derived]
        warnings = programming.check(drives, warnings)
        report = programming.run(self._session, drives, apply=apply, save=save, motor_off=motor_off,
                                 need_serial=save, verify_flash=verify_flash, warnings=warnings,
                                 confirm_save=confirm_save, on_plan=on_plan)
        if check:
            report.check()
        return report

    def restore(self, path: str | Path, *, apply: bool = False, save: bool = False, motor_off: bool = False,
                other_serial: bool = False, verify_flash: bool = False,
                confirm_save: ConfirmSave = refuse_unconfirmed,
                on_plan: Callable[[Sequence[DrivePlan]], None] | None = None, check: bool = True) -> ProgramReport:
        """Write a parameter dump (:meth:`dump_params`' file) back into its drives (`sherpa params
        restore`): every writable setting of the dump, never the identity block, read-only values or
        moment state. A dump from a drive with another serial number is refused unless
        ``other_serial``. Plan, dry run unless ``apply``, read-back, ``save`` only with
        ``confirm_save`` saying yes and counted in the save ledger, as :meth:`program_limits`."""
        from sherpa_cli.errors import Location
        from sherpa_cli.ops.params_file import read_dump
        from sherpa_cli.ops.restore import restore_targets

        programming.check_options(apply, save)
        file = Path(path)
        drives, warnings = restore_targets(self.config, read_dump(file), file, other_serial=other_serial)
        warnings = programming.check(drives, warnings, allow_disabled=True,
                                     where=lambda drive: Location(str(file), None, f"drives.{drive}.params"))
        report = programming.run(self._session, drives, apply=apply, save=save, motor_off=motor_off,
                                 need_serial=True, verify_flash=verify_flash, warnings=warnings,
                                 confirm_save=confirm_save, on_plan=on_plan)
        if check:
            report.check()
        return report

    # ------------------------------------------------------------------ tuning

    def tune_show(self, target: str) -> list[GainReading]:
        """The loop gains of the drives of ``target`` (a joint, pair or drive; `sherpa tune show`):
        KP[], KI[], FF[] per drive as the drive holds them (``reading.values["KP[2]"]``). What each one
        means, and which meanings the sources do not confirm, is ``ops.tune.GAINS``. Only reads."""
        from sherpa_cli.bus.targets import drive_refs
        from sherpa_cli.ops.tune import read_gains

        return read_gains(self._session, drive_refs(self.config, [target], configured_only=True, elmo_only="tune"))

    def tune_set(self, target: str, gains: Mapping[str, float] | Sequence[str], *, apply: bool = False,
                 save: bool = False, motor_off: bool = False, confirm_save: ConfirmSave = refuse_unconfirmed,
                 on_plan: Callable[[Sequence[DrivePlan]], None] | None = None, check: bool = True) -> ProgramReport:
        """Write loop gains to the drives of ``target`` (`sherpa tune set`): ``gains`` as
        ``{"KP[2]": 0.8}`` or ``["KP[2]=0.8"]``, each checked against its bounds (the config's
        ``tuning:``) before anything is sent. A dry run unless ``apply`` (the report's plans say now /
        target per drive); ``apply`` writes and reads back; ``save`` (with ``apply``) saves with SV once
        every value is verified, counted in the save ledger, and only if ``confirm_save`` says yes --
        the path of :meth:`program_limits`. ``check``: raise the problem the run ended with."""
        from sherpa_cli.bus.targets import drive_refs
        from sherpa_cli.ops.program import DriveTarget
        from sherpa_cli.ops.tune import parse_assignments

        programming.check_options(apply, save)
        cfg = self.config
        texts = gain_texts(gains)
        values = parse_assignments(cfg, texts)
        refs = drive_refs(cfg, [target], configured_only=True, elmo_only="tune")
        return self._program([DriveTarget(r.name, r.bus, r.node, values) for r in refs], apply=apply, save=save,
                             motor_off=motor_off, confirm_save=confirm_save, on_plan=on_plan, check=check)

    def _program(self, drives: Sequence[DriveTarget], *, apply: bool, save: bool, motor_off: bool,
                 confirm_save: ConfirmSave, on_plan: Callable[[Sequence[DrivePlan]], None] | None,
                 check: bool) -> ProgramReport:
        warnings = programming.check(drives)
        report = programming.run(self._session, drives, apply=apply, save=save, motor_off=motor_off,
                                 need_serial=save, warnings=warnings, confirm_save=confirm_save, on_plan=on_plan)
        if check:
            report.check()
        return report

    def tune_step(self, joint: str, mode: str, value: float, gains: Mapping[str, float] | Sequence[str], *,
                  duration: float = 2.0, rate: float = 500.0, uncalibrated: bool = False,
                  settings: MotionSettings | None = None, timebase: StepTime | None = None) -> TuneStepResult:
        """Step ``joint`` (a plain joint or its drive) with the gains its drive holds, then with the
        trial ``gains`` (RAM only, journaled, put back on every way out), and return both steps with
        their metrics (`sherpa tune step ... --apply`). ``mode``: ``"position"`` (``value`` rad, then
        back by -``value`` with the trial gains) or ``"velocity"`` (rad/s). Each step runs in the
        motion guard as :meth:`log_step`'s; nothing is saved. ``timebase``: as :meth:`log_step`'s."""
        from sherpa_cli.errors import UsageError
        from sherpa_cli.motion.settings import MotionSettings
        from sherpa_cli.ops.step import resolve_step_target, run_step, step_request
        from sherpa_cli.ops.tune import parse_assignments
        from sherpa_cli.ops.tune_step import run_tune_step

        if mode not in ("position", "velocity"):
            raise UsageError(f"mode {mode!r}: expected position or velocity")
        cfg = self.config
        texts = gain_texts(gains)
        trial = parse_assignments(cfg, texts)
        target = resolve_step_target(cfg, joint)
        step_request(target, mode, value, duration=duration, uncalibrated=uncalibrated)
        chosen = settings or MotionSettings.from_config(cfg, [target.ref.bus])
        session = self._session

        def one(m: str, v: float) -> StepResult:
            return run_step(session, target, m, v, duration=duration, rate=rate, settings=chosen,
                            uncalibrated=uncalibrated, timebase=timebase)

        return run_tune_step(session, target, mode, value, trial, one)

    def match_pair(self, pair: str, *, speed: int | None = None, rounds: int = 5, uncalibrated: bool = False,
                   tolerance: float | None = None, clock: Callable[[], float] | None = None,
                   sleep: Callable[[float], None] | None = None) -> MatchResult:
        """Make both speed loops of a differential pair equally fast (`sherpa diffdrive match PAIR
        --measure`): small Σ velocity steps of both motors from one common BG, inside the motion guard,
        recorded by the drives' own recorders; each loop's delay identified; the faster motor's KP[2],
        KP[3] x s and KI[2] x s² proposed and tried in RAM (put back on every way out) until both delays
        agree within ``tolerance`` (default 5 %) or ``rounds`` trials. Moves the motors, writes nothing
        lasting: the result's ``proposal.changes`` (drive -> gains) is what to write with
        :meth:`tune_set`. ``speed``: counts/s per motor (default a quarter of the Σ joint's limit).
        ``clock``/``sleep``: the time the steps run on (default wall time; tests step it)."""
        import time

        from sherpa_cli.bus.targets import pair_of
        from sherpa_cli.ops import pair_match
        from sherpa_cli.ops.tune import bounds

        cfg = self.config
        p = pair_of(cfg, pair)
        settings = pair_match.MatchSettings(speed=pair_match.step_speed(cfg, p, speed), uncalibrated=uncalibrated)
        if tolerance is not None:
            settings.tolerance = tolerance
        return pair_match.run_match(self._session, p, settings, rounds=rounds, bounds=bounds(cfg),
                                    clock=clock or time.monotonic, sleep=sleep or time.sleep)



def _typed_progress(on_progress: Callable[[object], None] | None) -> Callable[[Mapping[str, int]], None] | None:
    """A pair jog reports the watched joints' positions (counts): handed on as they are."""
    if on_progress is None:
        return None
    return lambda joints: on_progress(joints)
