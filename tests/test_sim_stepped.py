"""sim/stepped.py SteppedTime on its own: the clock moves only in sleeps; while a SYNC source is
registered it stops only on SYNC instants, sends each SYNC and waits for its answers before moving
on; it never runs ahead of wall time; a SYNC nobody answers is a CommunicationError, not a hang."""

from __future__ import annotations

import time

import pytest

from sherpa_cli.errors import CommunicationError
from sherpa_cli.sim.clock import ManualClock
from sherpa_cli.sim.stepped import PACED_SLICE_S, SteppedTime


class Bus:
    def __init__(self, clock) -> None:
        self.clock, self.sent = clock, []

    def send(self, msg) -> None:
        assert msg.arbitration_id == 0x080 and not msg.data
        self.sent.append(round(self.clock.now(), 9))


def test_without_sync_a_sleep_is_one_step_of_the_clock():
    st = SteppedTime(pace=False)
    st.sleep(0.123)
    st.sleep(0)
    assert st.now() == pytest.approx(0.123)


def test_with_sync_the_clock_stops_on_sync_instants_and_each_sync_is_answered_first():
    st = SteppedTime(pace=False)
    st.clock.advance(1.0)
    bus = Bus(st.clock)
    source = st.sync_factory("can0", bus, 0.002)
    asked: list[int] = []
    st.follow(lambda n: asked.append(n) or True)
    st.sleep(0.005)  # SYNC 0 at 1.000 (t = 0 of the recording), then 1.002, 1.004, 1.006 >= 1.005
    assert bus.sent == [1.0, 1.002, 1.004, 1.006]
    assert st.now() == pytest.approx(1.006)
    assert asked == [1, 2, 3, 4]
    st.sleep(0.002)
    assert bus.sent[-1] == 1.008 and st.now() == pytest.approx(1.008)
    source.stop()
    st.sleep(0.0005)  # no SYNC source: plain time again
    assert len(bus.sent) == 5 and st.now() == pytest.approx(1.0085)


def test_it_never_runs_ahead_of_wall_time():
    st = SteppedTime()
    t = time.monotonic()
    st.sleep(0.15)
    assert time.monotonic() - t >= 0.15


class FakeWall:
    """Wall time that moves only when pacing sleeps on it."""

    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t

    def sleep(self, seconds: float) -> None:
        self.t += seconds


class WatchedClock(ManualClock):
    """Notes, at each step, how far simulated time got ahead of the (fake) wall since it began."""

    def __init__(self, wall: FakeWall) -> None:
        super().__init__()
        self.wall = wall
        self.lead: list[float] = []

    def advance(self, dt: float) -> float:
        now = super().advance(dt)
        self.lead.append(now - self.wall())
        return now


@pytest.mark.parametrize("sync", [False, True])
def test_a_long_wait_never_puts_simulated_time_a_slice_ahead_of_the_wall(sync):
    # A wait of 0.3 s moved in one jump put simulated time 0.3 s ahead of the wall-time host heartbeat:
    # a drive's consumer of less than that tripped though no beat was missed. Each step starts only once
    # the wall has caught up with the last one (a fake wall: pacing is what moves it).
    wall = FakeWall()
    clock = WatchedClock(wall)
    st = SteppedTime(clock, wall=wall, wall_sleep=wall.sleep)
    if sync:
        st.sync_factory("can0", Bus(clock), 0.01)
        st.follow(lambda n: True)
    st.sleep(0.3)
    assert len(clock.lead) >= 0.3 / max(PACED_SLICE_S, 0.01) - 1
    assert max(clock.lead) <= max(PACED_SLICE_S, 0.01) + 1e-9, max(clock.lead)
    assert wall.t == pytest.approx(clock.now())


def test_an_unanswered_sync_is_a_communication_error():
    st = SteppedTime(pace=False, answer_timeout=0.05)
    st.sync_factory("can0", Bus(st.clock), 0.01)
    st.follow(lambda n: False)
    with pytest.raises(CommunicationError, match="simulated SYNC 1"):
        st.sleep(0.01)


def test_a_client_wait_is_charged_what_unheard_requests_cost_the_host():
    st = SteppedTime(pace=False)
    lost = [(3, 9.0)]  # before the client existed: not its waits
    options = st.client_overrides(0.1, retries=1, unheard=lambda: lost[0])
    assert options["retries"] >= 4 and options["timeout"] > 0
    options["sleep"](0.01)
    assert st.now() == pytest.approx(0.01)
    lost[0] = (4, 9.02)  # one request unheard, 20 ms of the drive's settle window left: the host waited that
    options["sleep"](0.01)
    assert st.now() == pytest.approx(0.01 + 0.02 + 0.01)
    lost[0] = (6, 10.02)  # two more with 1 s left: at most a reply timeout each
    options["sleep"](0.01)
    assert st.now() == pytest.approx(0.04 + 0.2 + 0.01)
    options["sleep"](0.01)
    assert st.now() == pytest.approx(0.26)
    assert options["clock"]() == st.now()


def test_a_wait_shorter_than_the_rounding_still_moves_the_clock():
    # a loop "until the deadline, sleep what is left" would spin for ever on a clock that stood still
    st = SteppedTime()
    st.sleep(1e-12)
    assert st.now() == 1e-12


def test_a_paced_wait_ends_where_one_step_would():
    # ten slices of 20 ms summed to 0.19999999999999998, and a test asking for 0.2 s between two
    # snapshots failed: each slice ends at an instant reckoned from the start
    st = SteppedTime()
    st.sleep(0.2)
    assert st.now() == 0.2
    st.sleep(0.1)
    assert st.now() == 0.2 + 0.1
