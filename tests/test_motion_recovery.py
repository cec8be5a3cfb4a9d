"""The one recovery (motion/recovery.py): breach -> stop -> standstill -> move back, and its one
outcome when standstill does not come. Fakes with a stepped clock: no bus."""

from __future__ import annotations

import pytest

from sherpa_cli.bus.targets import DriveRef
from sherpa_cli.errors import SafetyError
from sherpa_cli.motion import limit_watch, recovery
from sherpa_cli.motion.axis import Axis
from sherpa_cli.motion.settings import MotionSettings

JOINT = Axis("yaw", "plain", "m1", full=(-1000, 1000), normal=(-900, 900), vel_limit=400)


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t

    def sleep(self, s: float) -> None:
        self.t += max(s, 0.001)


class FakeDrive:
    """A drive that coasts: VX stays at ``vx`` until ``stops_after`` reads, then 0; a PA move is
    done at once."""

    label = "m1 (can0:1)"

    def __init__(self, px: int, vx: int, stops_after: int | None) -> None:
        self.px, self.vx, self.stops_after = px, vx, stops_after
        self.sent: list[str] = []
        self.reads = 0

    def get(self, letters: str, index: int = 0) -> int:
        if letters == "VX":
            self.reads += 1
            return 0 if self.stops_after is not None and self.reads > self.stops_after else self.vx
        return {"MO": 1, "PX": self.px, "MS": 0}[letters]

    def set(self, letters: str, index: int, value: float) -> None:
        self.sent.append(f"{letters}={value}")
        if letters == "PA":
            self.px = int(value)

    def execute(self, letters: str) -> None:
        self.sent.append(letters)


class FakeGuard:
    def __init__(self) -> None:
        self.enabled: list[int] = []

    def check(self) -> None:
        pass

    def enable(self, ref: DriveRef, um: int) -> None:
        self.enabled.append(um)

    def query(self, ref: DriveRef, letters: str, index: int = 0) -> int:
        return {"MO": 1, "MS": 0}[letters]


def _run(drive: FakeDrive, clock: Clock) -> dict[str, int]:
    breaches = limit_watch.check([JOINT], {"m1": drive.px})
    assert breaches
    settings = MotionSettings(standstill_timeout=0.5, poll_interval=0.01, recovery_speed=0.5)
    return recovery.recover(FakeGuard(), {"m1": DriveRef("m1", "can0", 1)}, {"m1": drive}, [JOINT], breaches,  # type: ignore[arg-type]
                            lambda: {"m1": drive.px}, settings=settings, clock=clock, sleep=clock.sleep,
                            speed=recovery.recovery_speed(settings, [JOINT]))


def test_the_move_back_starts_only_from_standstill_at_the_recovery_speed():
    drive, clock = FakeDrive(px=1010, vx=300, stops_after=5), Clock()
    back = _run(drive, clock)
    assert back == {"m1": 900}  # the nearest edge of the normal range
    stop, pa = drive.sent.index("ST"), drive.sent.index("PA=900")
    assert stop < pa
    assert drive.reads > 5  # the PA came after VX read standstill
    assert "SP=200" in drive.sent  # motion.recovery_speed (0.5) of the joint's 400 counts/s, never the drive's SP


def test_no_standstill_is_one_typed_outcome_and_no_move_back():
    drive, clock = FakeDrive(px=-1010, vx=300, stops_after=None), Clock()
    with pytest.raises(recovery.RecoveryFailed) as info:
        _run(drive, clock)
    err = info.value
    assert isinstance(err.cause, recovery.StandstillTimeout) and err.cause.moving == ("m1",)
    assert str(err).startswith("joint yaw at -1010 counts left its full range")  # the breach first
    assert "not at standstill 0.5 s after the stop" in str(err)
    assert not any(x.startswith("PA=") for x in drive.sent) and "BG" not in drive.sent
    assert clock.t == pytest.approx(0.5, abs=0.02)  # bounded by motion.standstill_timeout
    assert isinstance(err, SafetyError)


def test_a_motion_error_carries_the_guard_report_as_a_typed_field():
    from sherpa_cli.motion.report import GuardReport, MotionInterrupted, report_of, with_report

    report = GuardReport()
    err = SafetyError("boom")
    assert report_of(err) is None
    assert with_report(err, report) is err and report_of(err) is report  # the same error, now with the report
    ctrl_c = with_report(KeyboardInterrupt(), report)
    assert isinstance(ctrl_c, MotionInterrupted) and isinstance(ctrl_c, KeyboardInterrupt)  # still exit 130
    assert report_of(ctrl_c) is report
    bug = ValueError("a bug")
    assert with_report(bug, report) is bug and report_of(bug) is None
    assert report_of(SafetyError("x", motion_report=report)) is report  # a constructor field


def test_a_position_move_whose_motor_is_switched_off_from_elsewhere_names_that_not_its_time_bound():
    """`sherpa stop` from another terminal during home's back-off (ST, standstill, MO=0): the drive
    stands short of its target, so the wait ran out its bound and said "the back-off did not finish in
    time" instead of who stopped it."""
    from motion_helpers import JOG_CONFIG, stepped_session

    from sherpa_cli.bus.targets import drive_ref
    from sherpa_cli.config import load_config
    from sherpa_cli.motion.guard import MotionGuard

    cfg = load_config(JOG_CONFIG)
    with stepped_session(cfg) as (s, stepped):
        ref = drive_ref(cfg, "elbow")
        settings = MotionSettings.from_config(cfg)
        switched_off = []

        def sleep(dt: float) -> None:
            with s.sim.lock:
                drive = s.sim.drives["elbow"]
                if not switched_off and drive.motor_on and drive.px > 300:
                    # the move under way: MO=0, as another node's `sherpa stop` leaves it
                    drive.write_param("MO", 0)
                    switched_off.append(drive.px)
            stepped.sleep(dt)

        with (pytest.raises(SafetyError, match=r"^elbow .*the motor was switched off during j2: the back-off: "
                                                r"MO=0 from elsewhere"),
              MotionGuard(s, [ref], settings=settings, clock=stepped.now, sleep=sleep) as g):
            c = g.client(ref)
            c.nmt_start()
            assert int(c.get("PX")) < 300
            recovery.move_to(g, {"elbow": ref}, {"elbow": c}, {"elbow": 1500}, 500, settings,
                             stepped.now, sleep, "j2: the back-off")
        assert switched_off
