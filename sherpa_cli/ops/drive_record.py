"""`log record --source drive`: servo-rate traces from the drives' own recorders (elmo/recorder.py).

Every drive of the command is configured alike (same signals, gap, length), then armed one after
the other: with ``trigger="bg"`` they all wait for the next BG (a pair's one group BG starts both
at once); with ``"now"`` each starts when its RR=2 arrives (a pair's two traces are then a few
milliseconds apart, one interpreter round trip). The recorder settings are RAM only: read first
and written back on every exit path (end, error, Ctrl-C); nothing is saved. A bad upload of any
signal of any drive fails the whole recording: no partial result, no file.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal

from sherpa_cli.bus import journal
from sherpa_cli.bus.session import ArmSession
from sherpa_cli.bus.targets import DriveRef
from sherpa_cli.config.model import ArmConfig
from sherpa_cli.elmo.recorder import SIGNALS, DriveRecorder, RecorderPlan, RecorderSettings, plan_recording
from sherpa_cli.errors import SherpaError
from sherpa_cli.joints.jointmap import joint_map
from sherpa_cli.joints.units import counts_per_s_to_rad_per_s, counts_to_rad
from sherpa_cli.log.recording import Recording

log = logging.getLogger(__name__)
JOURNAL_OWNER = "drive recorder"  # the journal's owner of the recorder settings (RV, RC, RG, RL, RP[3])

# recording column suffix per recorder signal (log/recording.py's drive columns, plus two)
COLUMNS = {"pos": "px", "vel": "vx", "cur": "iq_a", "pos_err": "pe", "vel_cmd": "vcmd"}
WAIT_MARGIN_S = 2.0  # beyond the recording time, for the drives to report data ready


@dataclass
class DriveRecordResult:
    recording: Recording
    plan: RecorderPlan
    period_s: float
    samples: dict[str, int]  # drive -> samples per signal


def record_drives(session: ArmSession, refs: Sequence[DriveRef], duration: float, *,
                  trigger: Literal["now", "bg"] = "now", wait_s: float | None = None,
                  settings: RecorderSettings | None = None, signals: Sequence[str] = SIGNALS,
                  clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep,
                  on_armed: Callable[[], None] | None = None,
                  on_ready: Callable[[], None] | None = None) -> DriveRecordResult:
    """Record ``duration`` s of ``signals`` on every drive of ``refs``. ``wait_s``: how long to wait
    for the data after arming (default: the recording time plus a margin; with ``trigger="bg"``
    this is also how long the drives wait for the BG). ``on_armed`` runs once every drive is armed
    (e.g. the BG of a step); ``on_ready`` once every drive has its data, before the uploads (e.g. the
    stop of a step: the motors do not run on through the uploads)."""
    settings = settings or RecorderSettings()
    plan = plan_recording(duration, settings, signals=signals, trigger=trigger)
    with DriveRecordings(session, refs, plan, settings, clock=clock, sleep=sleep) as recordings:
        recordings.arm()
        if on_armed is not None:
            on_armed()
        return recordings.collect(wait_s, on_ready=on_ready)


class DriveRecordings:
    """The recorders of several drives, in steps a moving command can place: :meth:`arm` inside its
    motion guard (after the guard's lock and checks, just before the BG), :meth:`collect` once the
    motors have stopped; the settings go back in :meth:`close` (the context's exit) on every path."""

    def __init__(self, session: ArmSession, refs: Sequence[DriveRef], plan: RecorderPlan,
                 settings: RecorderSettings, *, clock: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep) -> None:
        self.session, self.refs, self.plan, self.settings = session, list(refs), plan, settings
        self.recorders = {ref.name: DriveRecorder(session.client(ref), _uploader(session, ref), settings,
                                                  clock=clock, sleep=sleep) for ref in refs}
        self.saved: dict[str, list[tuple[str, int, int | float]]] = {}
        self.restored = True

    def __enter__(self) -> DriveRecordings:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def arm(self) -> None:
        """Read every drive's recorder settings, then configure and arm them all."""
        self.restored = False
        for rec in self.recorders.values():
            rec.client.nmt_start()  # the binary interpreter answers only in Operational
        for name, rec in self.recorders.items():
            self.saved[name] = rec.snapshot(self.plan)
        for ref in self.refs:  # on disk before anything changes: a killed recording leaves them to `recover`
            journal.note(ref, *(journal.interp(JOURNAL_OWNER, letters, index, value)
                                for letters, index, value in self.saved[ref.name]))
        for rec in self.recorders.values():
            rec.configure(self.plan)
        for rec in self.recorders.values():
            rec.arm(self.plan)

    def collect(self, wait_s: float | None = None, *, on_ready: Callable[[], None] | None = None) -> DriveRecordResult:
        """Wait for every drive's data (``wait_s``, default the recording time plus a margin), run
        ``on_ready``, upload it all, put the settings back. In memory: a bad upload of any signal of
        any drive fails the whole recording."""
        period = self.plan.period(self.settings)
        wait = wait_s if wait_s is not None else self.plan.length * period + WAIT_MARGIN_S
        data: dict[str, dict[str, list[float]]] = {}
        try:
            for rec in self.recorders.values():
                rec.wait_ready(wait)
            if on_ready is not None:
                on_ready()
            for name, rec in self.recorders.items():
                data[name] = rec.read(self.plan)
        finally:
            self.close()
        return DriveRecordResult(to_recording(self.session.cfg, self.refs, data, period), self.plan, period,
                                 {name: len(next(iter(d.values()))) for name, d in data.items()})

    def close(self) -> None:
        """Put the recorder settings back (once)."""
        if not self.restored:
            self.restored = True
            back = _restore(self.recorders, self.saved)
            for ref in self.refs:
                if ref.name in back:
                    journal.forget(ref, JOURNAL_OWNER)


def _uploader(session: ArmSession, ref: DriveRef) -> Callable[[int, int], bytes]:
    sdo = session.sdo(ref)
    return lambda index, sub: sdo.upload(index, sub, name="recorded data")


def _restore(recorders: dict[str, DriveRecorder], saved: dict[str, list[tuple[str, int, int | float]]]) -> set[str]:
    """Put every drive's recorder settings back; a silent drive is skipped, a failure is logged and
    does not keep the other drives from theirs. Returns the drives put back (their notes can go)."""
    back: set[str] = set()
    for name, rec in recorders.items():
        if rec.client.silent:
            log.warning("%s: silent, its recorder settings are not restored", rec.client.label)
            continue
        try:
            rec.restore(saved.get(name, []))
            back.add(name)
        except SherpaError as exc:
            log.warning("%s: recorder settings not restored: %s", rec.client.label, exc)
    return back


def to_recording(cfg: ArmConfig, refs: Sequence[DriveRef], data: dict[str, dict[str, list[float]]],
                 period: float) -> Recording:
    """The `log record` format: time = k x period, joint columns (Σ/Δ for a pair) and drive columns."""
    n = min((len(v) for d in data.values() for v in d.values()), default=0)
    rec = Recording(times=[k * period for k in range(n)])
    for joint in cfg.joints.values():
        if joint.drive is not None and joint.drive in data:
            d = data[joint.drive]
            if "pos" in d:
                rec.columns[f"{joint.name}.pos_rad"] = [counts_to_rad(v, joint.cpr) for v in d["pos"][:n]]
            if "vel" in d:
                rec.columns[f"{joint.name}.vel_rad_s"] = [counts_per_s_to_rad_per_s(v, joint.cpr) for v in d["vel"][:n]]
            if "cur" in d:
                rec.columns[f"{joint.name}.cur_a"] = list(d["cur"][:n])
        elif (m := joint_map(cfg, joint)) is not None and m.b is not None:
            a, b = data.get(m.a), data.get(m.b)
            if a is None or b is None:
                continue
            for signal, col, conv in (("pos", "pos_rad", counts_to_rad), ("vel", "vel_rad_s", counts_per_s_to_rad_per_s)):
                if signal in a and signal in b:
                    rec.columns[f"{joint.name}.{col}"] = [conv(m.value(x, y), m.cpr)
                                                          for x, y in zip(a[signal][:n], b[signal][:n], strict=True)]
    for ref in refs:
        d = data.get(ref.name, {})
        for signal in SIGNALS:
            if signal in d:
                rec.columns[f"{ref.name}.{COLUMNS[signal]}"] = list(d[signal][:n])
    return rec
