"""motion/force_watch.py on a fake reader and a fake clock: the limit names the axis and value,
a bad status stops, a silent sensor stops only after its bound, a command may only tighten."""

from __future__ import annotations

import dataclasses

import pytest

from sherpa_cli.config import load_config
from sherpa_cli.devices.ft_sensor import FtReader, StatusWord, Wrench
from sherpa_cli.errors import CommunicationError, DriveTimeoutError, SafetyError, UsageError
from sherpa_cli.motion.force_watch import (
    ForceLimitError,
    ForceWatch,
    SensorSilentError,
    SensorStatusError,
    WrenchSource,
    tightened,
)
from tests.test_ft_sensor import BASE, CAL, FakeClock, ScriptedPort

ARM = "tests/data/ft-arm.yaml"


class FakeReader:
    """Plays a script: a Wrench is a sample, None is no answer; each read takes 10 ms of fake time."""

    def __init__(self, clock: FakeClock, script: list[Wrench | None]) -> None:
        self.clock, self.script = clock, list(script)

    def read(self) -> Wrench:
        self.clock.t += 0.01
        item = self.script.pop(0)
        if item is None:
            raise DriveTimeoutError("F/T sensor: no reply within 10 ms of the request")
        return item


def w(fx=0.0, fy=0.0, fz=0.0, tx=0.0, ty=0.0, tz=0.0, status=0, sample=0) -> Wrench:
    return Wrench(fx, fy, fz, tx, ty, tz, StatusWord(status), sample)


def watch(script, clock=None, **kw) -> tuple[ForceWatch, FakeClock]:
    clock = clock or FakeClock()
    kw.setdefault("force_limit", 20.0)
    kw.setdefault("torque_limit", 2.0)
    kw.setdefault("silent_s", 0.05)
    return ForceWatch(FakeReader(clock, script), clock=clock, name="F/T sensor wrist_ft", **kw), clock


def test_under_the_limits_nothing_stops():
    fw, _ = watch([w(fz=-9.8), w(fx=19.9), w(tx=1.99)])
    assert [fw.check() for _ in range(3)] == [None, None, None]
    assert fw.last is not None and fw.last.tx == 1.99


def test_the_force_limit_names_the_axis_and_the_value():
    fw, _ = watch([w(fz=-9.8), w(fx=3.0, fz=-21.5, sample=42)])
    assert fw.check() is None
    err = fw.check()
    assert isinstance(err, ForceLimitError) and isinstance(err, SafetyError)
    assert (err.axis, err.value, err.limit) == ("Fz", -21.5, 20.0)
    assert err.message == ("force limit: F/T sensor wrist_ft read |F| 21.71 N > 20 N (mostly Fz -21.50 N) "
                           "in sample 42")


def test_the_torque_limit_on_its_own():
    fw, _ = watch([w(), w(ty=-2.5, tz=0.5)], force_limit=None)
    assert fw.check() is None
    err = fw.check()
    assert isinstance(err, ForceLimitError) and err.axis == "Ty" and "|T| 2.55 N·m > 2 N·m" in err.message
    assert watch([w(fx=100.0)], force_limit=None)[0].check() is None  # no force limit: forces are not watched


def test_a_status_word_not_zero_stops():
    err = watch([w(status=0x8001, sample=5)])[0].check()
    assert isinstance(err, SensorStatusError) and "status 0x8001 (bits 0,15) in sample 5" in err.message


def test_a_silent_sensor_stops_only_after_its_bound():
    fw, _ = watch([w(), None, None, None, None, None, None, w()], silent_s=0.045)
    assert fw.check() is None  # t = 0.01: a sample
    results = [fw.check() for _ in range(6)]  # t = 0.02 .. 0.07: silent
    assert results[:4] == [None] * 4  # silent 10..40 ms: within the 45 ms bound
    err = results[4]
    assert isinstance(err, SensorSilentError) and isinstance(err, CommunicationError)
    assert err.message.startswith("F/T sensor wrist_ft silent for 50 ms, 5 requests unanswered (bound 45 ms): the "
                                  "force limit cannot be watched; last: F/T sensor: no reply within 10 ms")
    assert fw.misses == 6


def test_the_bound_counts_from_the_start_of_the_watch():
    clock = FakeClock()
    clock.t = 5.0
    fw, _ = watch([None] * 10, clock=clock)
    errors = [fw.check() for _ in range(6)]
    assert errors[:4] == [None] * 4 and isinstance(errors[5], SensorSilentError)


def test_a_command_may_only_tighten_the_configured_limit():
    assert tightened(20.0, None, "--force-limit") == 20.0
    assert tightened(20.0, 5.0, "--force-limit") == 5.0
    assert tightened(20.0, 50.0, "--force-limit") == 20.0
    assert tightened(None, 5.0, "--force-limit") == 5.0
    with pytest.raises(UsageError, match="--force-limit -1: expected a force in N, > 0"):
        tightened(20.0, -1.0, "--force-limit")
    dev = load_config(ARM).devices["wrist_ft"]
    fw = ForceWatch.for_device(FakeReader(FakeClock(), []), dev, silent_s=0.1, force_limit=8.0, clock=FakeClock())
    assert (fw.force_limit, fw.torque_limit, fw.name) == (8.0, 2.0, "F/T sensor wrist_ft")


def test_a_watch_without_limits_is_refused():
    with pytest.raises(UsageError, match="needs a force_limit or a torque_limit"):
        watch([], force_limit=None, torque_limit=None)


def test_the_real_reader_is_a_wrench_source():
    clock = FakeClock()
    reader: WrenchSource = FtReader(ScriptedPort(clock, []), BASE, CAL, wait_s=0.02, clock=clock)
    fw = ForceWatch(reader, force_limit=20.0, torque_limit=None, silent_s=0.03, clock=clock)
    assert fw.check() is None  # 20 ms without a reply: inside the bound
    assert isinstance(fw.check(), SensorSilentError)


def test_a_count_of_unanswered_requests_in_a_row_is_silence_on_any_clock():
    """Each unanswered request waits on the bus in wall time while the command's clock may stand
    (stepped time): ``max_misses`` in a row is silence, whatever the clock says; a sample resets it."""
    fw, _clock = watch([None, None, w(), None, None, None], silent_s=100.0, max_misses=3)
    assert [fw.check() for _ in range(5)] == [None] * 5
    error = fw.check()
    assert isinstance(error, SensorSilentError) and "3 requests unanswered" in error.message


def test_a_saturated_axis_is_taken_as_past_the_limit_at_the_start_and_during_the_motion():
    """A count at the end of INT16 says only "at least this much": 86 N on an axis that saturates at
    32.77 N read 32.77 N, under a 40 N limit, and the jog pressed on."""
    top = 32767 / 1000
    for script in ([w(fx=top, sample=3)], [w(), w(fx=-32768 / 1000, sample=3)]):
        fw, _ = watch([dataclasses.replace(x, saturated=("Fx",) if abs(x.fx) >= top else ()) for x in script],
                      force_limit=40.0)
        errors = [fw.check() for _ in script]
        err = errors[-1]
        assert isinstance(err, ForceLimitError) and err.axis == "Fx", errors
        assert "reads Fx at the end of its range" in err.message and "taken as over 40 N" in err.message
    fw, _ = watch([dataclasses.replace(w(tx=32.767), saturated=("Tx",))], torque_limit=None)
    assert fw.check() is None  # torque is not watched: its saturation is no stop


def test_the_real_reader_marks_the_saturated_axes():
    from sherpa_cli.devices.ft_sensor import RawSample, to_wrench

    got = to_wrench(RawSample(fx=32767, tx=5, fy=-32767, ty=0, fz=-32768, tz=0, status=0, sample=1), CAL)
    assert got.saturated == ("Fx", "Fz")


def test_a_watch_that_begins_past_its_limit_lets_the_arm_move_away_and_stops_it_pressing_harder():
    """After a force stop the arm still presses where it stopped: every motion was refused, the
    one that moves it away included."""
    fw, _ = watch([w(fz=-22.0), w(fz=-21.0), w(fz=-22.9), w(fz=-23.2)], force_limit=20.0)
    assert fw.check() is None and fw.past_at_start == {"force": 22.0}
    assert fw.check() is None and fw.limit_now("force", 20.0) == pytest.approx(23.0)  # lowest 21 + 2
    assert fw.check() is None  # 22.9: under the lowest reading + 10 % of the limit
    err = fw.check()
    assert isinstance(err, ForceLimitError) and err.limit == pytest.approx(23.0)
    assert "|F| 23.20 N > 23.00 N (it began past its 20 N limit: lowest reading + 10%)" in err.message


def test_once_clear_of_the_contact_the_configured_limit_holds_again():
    fw, _ = watch([w(fz=-25.0), w(fz=-19.0), w(fz=-20.5)], force_limit=20.0)
    assert fw.check() is None and fw.check() is None
    assert fw.past_at_start == {}
    err = fw.check()
    assert isinstance(err, ForceLimitError) and "> 20 N (mostly Fz" in err.message


def test_silence_counts_from_the_first_unanswered_request_not_from_the_last_sample():
    """The guard's entry takes longer than the silence bound between its first sample and the
    loop's first check: one missed reply then ended the move."""
    fw, clock = watch([w(), None, None, None, None, None, None], silent_s=0.045)
    assert fw.check() is None
    clock.t += 0.7  # the command's own steps: no check meanwhile
    results = [fw.check() for _ in range(6)]
    assert results[:4] == [None] * 4
    assert isinstance(results[4], SensorSilentError) and "silent for 50 ms" in results[4].message


def test_a_torque_limit_is_refused_in_its_own_unit():
    from sherpa_cli.motion.force_watch import tightened

    with pytest.raises(UsageError, match="--torque-limit -1: expected a torque in N·m, > 0"):
        tightened(None, -1.0, "--torque-limit")
    assert tightened(2.0, 1.0, "--torque-limit") == 1.0
