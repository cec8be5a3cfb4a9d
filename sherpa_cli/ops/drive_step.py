"""`log step --source drive`: the step recorded by the drive's own recorder, next to the CAN recording
of the same step (docs/log.md).

:class:`DriveTrace` hooks into ops/step.py's ``run_step``: just before the step's command it configures
the drive's recorder (RAM; what it changes is read first) and arms it -- for a position or velocity step
to start at the step's BG (RR=1), for a torque step (no BG) at once (RR=2); after the motion guard has
stopped the motor it waits for the data, uploads it (a bad upload fails the whole step: no partial
result) and puts the recorder settings back. :meth:`DriveTrace.close` puts them back on every other way
out. The drive's samples are placed on the CAN recording's time: sample k at t0 + k x period, t0 the
instant the BG (or the arming) was sent, measured on the step's clock from its t = 0.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

from sherpa_cli.elmo.recorder import DriveRecorder, RecorderPlan, RecorderSettings, plan_recording
from sherpa_cli.errors import SherpaError
from sherpa_cli.log.recording import Recording
from sherpa_cli.log.step_metrics import StepMetrics, step_metrics

if TYPE_CHECKING:
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.bus.targets import DriveRef

log = logging.getLogger(__name__)
WAIT_MARGIN_S = 2.0
# a step's signals: the three the CAN recording has, so the recorder's capacity gives the finest gap
STEP_SIGNALS = ("pos", "vel", "cur")
PRE_S = 0.1  # s a step records before its command (ops/step.py takes it from here: one number for both)
# each switch request also costs interpreter round trips and the read-back of MO; on a loaded bus
# a few tens of ms, so one allowance per request beside the drive's settle window
SWITCH_STEP_S = 0.05
# the step loop notices its end up to one poll later than the time it was given, and the stop is
# sent after that: the CAN recording ends there, so the drive's must reach it too
TAIL_S = 0.1
WORST_SWITCH = ("MO=0", "UM=1", "MO=1")  # a drive on in another unit mode: its motor off, UM, on again


def switch_time(steps: Sequence[str], mo_settle: float) -> float:
    """The longest a MO/UM switch of ``steps`` (ops/step.py ``switch_steps``) may take: the drive's
    settle window after every MO it is sent, plus an allowance per request."""
    return sum(mo_settle for s in steps if s.startswith("MO=")) + SWITCH_STEP_S * len(steps)


def record_length(trigger: str, duration: float, switch_s: float) -> float:
    """s the drive's recorder must hold for a step of ``duration`` s (``--for``, counted from the
    step itself): a ``"bg"`` recording starts at the step's BG, after the switch; a ``"now"`` one (a
    torque step, which has no BG) starts when armed, ``PRE_S`` before the command, and so must also
    hold the switch of up to ``switch_s`` before the step is sent."""
    lead = 0.0 if trigger == "bg" else PRE_S + switch_s
    return lead + duration + TAIL_S


@dataclass
class DriveStep:
    recording: Recording  # on the step's time (t = 0: the command), cut where the CAN recording ends
    metrics: StepMetrics
    period_s: float
    gap: int
    samples: int
    t0: float  # s from the command to the recorder's first sample


class DriveTrace:
    """The drive recorder of one step (module docstring). Use as a context manager around ``run_step``."""

    def __init__(self, session: ArmSession, ref: DriveRef, duration: float, *,
                 settings: RecorderSettings | None = None, signals: Sequence[str] = STEP_SIGNALS,
                 clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep) -> None:
        self.session, self.ref, self.duration = session, ref, duration
        self.settings = settings or RecorderSettings()
        self.signals = tuple(signals)
        self.clock, self.sleep = clock, sleep
        self.mo_settle = session.cfg.protocol.mo_settle
        # the longest recording the step may need, refused before anything moves
        plan_recording(record_length("now", duration, switch_time(WORST_SWITCH, self.mo_settle)), self.settings,
                       signals=self.signals)
        self._rec: DriveRecorder | None = None
        self._plan: RecorderPlan | None = None
        self._saved: list[tuple[str, int, int | float]] | None = None
        self.t0: float | None = None
        self.result: DriveStep | None = None

    def __enter__(self) -> DriveTrace:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def arm(self, trigger: str, switch_steps: Sequence[str] = ()) -> None:
        """Configure and arm, just before the command: ``"bg"`` for a BG step, ``"now"`` for a torque
        step; ``switch_steps``: what the MO/UM switch will send before the step (it may come after
        the arming, inside the recording)."""
        sdo = self.session.sdo(self.ref)
        client = self.session.client(self.ref)
        length = record_length(trigger, self.duration, switch_time(switch_steps, self.mo_settle))
        self._plan = plan_recording(length, self.settings, signals=self.signals,
                                    trigger="bg" if trigger == "bg" else "now")
        self._rec = DriveRecorder(client, lambda index, sub: sdo.upload(index, sub, name="recorded data"),
                                  self.settings, clock=self.clock, sleep=self.sleep)
        self._saved = self._rec.snapshot(self._plan)
        self._rec.configure(self._plan)
        self._rec.arm(self._plan)

    def started(self, t_from_command: float) -> None:
        """The instant (s from the command) the recorder's first sample was taken: the BG's or the arming's."""
        self.t0 = t_from_command

    def collect(self, cfg: object, joint: str, signal: str, until: float, target: float,
                initial: float | None = None) -> DriveStep:
        """Wait for the data, upload it, put the settings back; the joint's ``signal`` on the step's time."""
        from sherpa_cli.ops.drive_record import to_recording

        assert self._rec is not None and self._plan is not None and self.t0 is not None
        period = self._plan.period(self.settings)
        try:
            self._rec.wait_ready(self._plan.length * period + WAIT_MARGIN_S)
            data = self._rec.read(self._plan)
        finally:
            self.close()
        raw = to_recording(cfg, [self.ref], {self.ref.name: data}, period)  # type: ignore[arg-type]
        keep = [i for i, t in enumerate(raw.times) if self.t0 + t < until]  # cut where the CAN recording ends
        recording = Recording(times=[self.t0 + raw.times[i] for i in keep],
                              columns={name: [values[i] for i in keep] for name, values in raw.columns.items()})
        series = recording.series(joint, signal)
        if series is None or len(series[0]) < 2:
            raise SherpaError(f"{joint}: the drive recorded no {signal} samples")
        metrics = step_metrics(series[0], series[1], t_step=0.0, target=target, initial=initial)
        self.result = DriveStep(recording, metrics, period, self._plan.gap, len(raw.times), self.t0)
        return self.result

    def close(self) -> None:
        """Put the recorder settings back (once); a failure is logged, never raised over the step's error."""
        rec, saved = self._rec, self._saved
        self._saved = None
        if rec is None or saved is None:
            return
        if rec.client.silent:
            log.warning("%s: silent, its recorder settings are not restored", rec.client.label)
            return
        try:
            rec.restore(saved)
        except SherpaError as exc:
            log.warning("%s: recorder settings not restored: %s", rec.client.label, exc)
