"""`sherpa diffdrive move` (ops/diffdrive.py): the pure planning and coupling maths, the simulator's
group id (0x2040) and start skew, and moves on the simulated mismatched pair
(tests/data/diffdrive-arm.yaml: motor b 10 % faster, motor a's separately received BG 40 ms late).

The moves run in real time like tests/test_jog_pair.py (the guard's heartbeat thread is wall-clock).
"""

from __future__ import annotations

import itertools
import time
from pathlib import Path

import pytest
from motion_helpers import stepped_session

from sherpa_cli.bus.session import ArmSession
from sherpa_cli.config import load_config
from sherpa_cli.elmo.codec import encode_execute, encode_set
from sherpa_cli.errors import SafetyError, SherpaError, UsageError
from sherpa_cli.motion import pair_start
from sherpa_cli.motion.axis import resolve_axis
from sherpa_cli.motion.request import parse_request
from sherpa_cli.ops import diffdrive
from sherpa_cli.ops.diffdrive import PairTarget
from sherpa_cli.sim import ManualClock, SimSettings
from sherpa_cli.sim.arm import SimArm
from sherpa_cli.sim.drive import SimDrive
from sherpa_cli.sim.od import ODError

DATA = Path(__file__).resolve().parent / "data"
MISMATCHED = DATA / "diffdrive-arm.yaml"
FAST = DATA / "jog-fast-arm.yaml"


@pytest.fixture
def cfg():
    return load_config(MISMATCHED)


# --------------------------------------------------------------------------- pure

def test_equal_duration_profiles_scale_every_motor_by_its_share():
    p = diffdrive.profiles({"a": 400, "b": -100}, 1000, 8000, 6000)
    assert p["a"] == diffdrive.Profile(1000, 8000, 6000)
    assert p["b"] == diffdrive.Profile(250, 2000, 1500)
    naive = diffdrive.profiles({"a": 400, "b": -100}, 1000, 8000, 6000, scaled=False)
    assert naive["a"] == naive["b"] == diffdrive.Profile(1000, 8000, 6000)


def test_plan_converts_sigma_delta_to_motor_targets_and_holds_the_other(cfg):
    pair = cfg.pairs["diff"]
    p = diffdrive.plan_move(cfg, pair, PairTarget(sigma="200counts"), {"left": 50, "right": 10})
    assert p.start == (60, 40) and p.target == (200, 40)
    assert p.motor_targets == {"left": 120, "right": 80}
    both = diffdrive.plan_move(cfg, pair, PairTarget(sigma="100counts", delta="-300counts", relative=True),
                               {"left": 0, "right": 0})
    assert both.target == (100, -300) and both.motor_targets == {"left": -100, "right": 200}
    # the longer motor gets the full profile, the other its share
    assert both.profiles["right"].sp * 100 // both.profiles["left"].sp in (199, 200, 201)


def test_plan_in_rad_and_deg(cfg):
    pair = cfg.pairs["diff"]
    p = diffdrive.plan_move(cfg, pair, PairTarget(sigma="1", delta="-6deg"), {"left": 0, "right": 0})
    # 1 rad = 955 counts and 6° = -100 counts of cpr 6000: different parity, so one gives way a count
    assert abs(p.target[0] - 955) + abs(p.target[1] + 100) == 1 and (p.target[0] - p.target[1]) % 2 == 0


@pytest.mark.parametrize("req, text", [
    (PairTarget(sigma="3000counts"), "normal range [-2800, 2800]"),
    (PairTarget(delta="-1950counts"), "roll target -1950 counts is outside"),
    (PairTarget(delta="2000counts", relative=True), "outside the joint's normal range"),
    (PairTarget(), "give --sigma, --delta or both"),
    (PairTarget(sigma="10furlong"), "--sigma"),
    (PairTarget(sigma="100counts", velocity="2000counts"), "above its speed limit"),
])
def test_plan_refusals(cfg, req, text):
    with pytest.raises(UsageError, match=None) as exc:
        diffdrive.plan_move(cfg, cfg.pairs["diff"], req, {"left": 0, "right": 0})
    assert text in str(exc.value)


def test_coupling_of_a_sigma_move_measures_the_held_delta():
    # Σ 0 -> 100 with Δ wandering up to 6 counts and back
    samples = [(0.0, 0, 0), (0.1, 28, 22), (0.2, 53, 47), (0.3, 50, 50)]
    c = diffdrive.measure_coupling(samples, (0, 0), (100, 0), sigma_name="s", delta_name="d",
                                   sigma_cpr=6000, delta_cpr=6000)
    assert c.held == "d" and c.held_peak == 6 and c.peak_delta == 6 and c.peak_sigma == 0
    assert c.fraction(c.held_peak) == pytest.approx(0.06)
    assert c.as_dict()["held_excursion"]["rad"] == pytest.approx(6 * 2 * 3.141592653589793 / 6000, rel=1e-4)


def test_a_planned_parity_give_way_of_the_held_joint_is_not_coupling():
    """Σ 0 -> 101 with Δ held: whole motor positions need Σ and Δ of equal parity, so the plan moves Δ
    to -1. That count is planned: it used to be reported as the held joint's measured coupling."""
    samples = [(0.0, 0, 0), (0.1, 25, 25), (0.2, 50, 51), (0.3, 50, 51)]  # (Σ, Δ) (0,0) (50,0) (101,-1)
    c = diffdrive.measure_coupling(samples, (0, 0), (101, -1), sigma_name="s", delta_name="d",
                                   sigma_cpr=6000, delta_cpr=6000, held="d")
    assert c.held == "d" and c.held_planned == -1 and c.held_peak == 0
    assert c.as_dict()["held_planned_counts"] == -1 and c.as_dict()["held_excursion"]["counts"] == 0
    beyond = diffdrive.measure_coupling([*samples, (0.4, 52, 51)], (0, 0), (101, -1), sigma_name="s",
                                        delta_name="d", sigma_cpr=6000, delta_cpr=6000, held="d")
    assert beyond.held_peak == 1  # Δ 0 -> -1 planned; +1 is one count beyond it, the other way
    overshoot = diffdrive.measure_coupling([*samples, (0.4, 49, 52)], (0, 0), (101, -1), sigma_name="s",
                                           delta_name="d", sigma_cpr=6000, delta_cpr=6000, held="d")
    assert overshoot.held_peak == 2  # Δ -3: two counts past the planned -1


def test_feedback_slows_the_motor_ahead_within_its_bound(cfg):
    p = diffdrive.plan_move(cfg, cfg.pairs["diff"], PairTarget(sigma="400counts"), {"left": 0, "right": 0})
    planned = p.profiles
    new = diffdrive.Feedback(p, gain=8.0, limit=0.5).profiles(0.0, {"left": 20, "right": 60})  # b ahead
    # only the motor ahead slows: no motor ever runs faster than planned
    assert new["left"] == planned["left"] and new["right"].sp < planned["right"].sp
    # e = 0.1 - 0.3: c = 8 * -0.2 = -1.6, bounded to -0.5: k = max(1 - 0.5, 0.5 / 1.5) = 0.5
    assert new["right"] == diffdrive.Profile(*(round(v * 0.5) for v in (planned["right"].sp, planned["right"].ac,
                                                                         planned["right"].dc)))
    ahead_a = diffdrive.Feedback(p, gain=8.0, limit=0.5).profiles(0.0, {"left": 11, "right": 10})
    c = 8.0 * (11 - 10) / 200
    assert ahead_a["right"] == planned["right"] and ahead_a["left"].sp == round(planned["left"].sp * (1 - c) / (1 + c))


def test_feedback_velocity_term_sees_a_faster_motor_before_the_positions_drift():
    cfg = load_config(MISMATCHED)
    p = diffdrive.plan_move(cfg, cfg.pairs["diff"], PairTarget(sigma="400counts"), {"left": 0, "right": 0})
    fb = diffdrive.Feedback(p, gain=8.0, limit=0.5)
    sp = p.profiles["left"].sp
    same = {"left": 50, "right": 50}
    slower = fb.profiles(0.0, same, {"left": sp, "right": round(sp * 1.1)})  # b 10 % faster
    assert slower["left"] == p.profiles["left"] and slower["right"].sp < p.profiles["right"].sp
    # v = (1 - 1.1) / 1.05: c = 0.2 v
    c = abs(diffdrive.Feedback.VELOCITY_GAIN * (sp - round(sp * 1.1)) / ((sp + round(sp * 1.1)) / 2))
    assert slower["right"].sp == round(p.profiles["right"].sp * (1 - c) / (1 + c))
    # below the velocity floor (starting, stopping) the term is off
    creeping = diffdrive.Feedback(p, gain=8.0, limit=0.5).profiles(0.0, same, {"left": 5, "right": 10})
    assert creeping == dict(p.profiles)


def test_feedback_after_a_stalled_cycle_corrects_less():
    cfg = load_config(MISMATCHED)
    p = diffdrive.plan_move(cfg, cfg.pairs["diff"], PairTarget(sigma="400counts"), {"left": 0, "right": 0})
    on_time, stalled = diffdrive.Feedback(p, gain=8.0, limit=0.5), diffdrive.Feedback(p, gain=8.0, limit=0.5)
    ahead = {"left": 100, "right": 96}
    for fb in (on_time, stalled):
        fb.profiles(0.0, ahead)
    k_on = on_time.profiles(diffdrive.Feedback.CYCLE_S, ahead)["left"].sp
    k_stalled = stalled.profiles(10 * diffdrive.Feedback.CYCLE_S, ahead)["left"].sp
    assert k_on < k_stalled < p.profiles["left"].sp  # both slow the motor ahead, the stalled one less


# --------------------------------------------------------------------------- simulator

def _drive(clock, node, **settings):
    d = SimDrive(node, clock=clock, settings=SimSettings(mo_settle_s=0.0, **settings))
    d.receive(0x000, bytes([0x01, node]))
    for frame in (encode_set("SP", 0, 1000), encode_set("AC", 0, 100000), encode_set("DC", 0, 100000),
                  encode_set("PA", 0, 500), encode_set("MO", 0, 1)):
        d.receive(0x300 + node, frame)
    d.pop_frames()
    return d


def test_sim_group_id_runs_one_bg_on_both_drives_without_skew():
    clock = ManualClock()
    a, b = _drive(clock, 10, start_skew_s=0.05), _drive(clock, 11)
    for d in (a, b):
        d.od_write(0x2040, 0, 125)
    for d in (a, b):
        d.receive(0x000, bytes([0x82, d.node]))  # Elmo's guide: the group id takes effect after reset comm
        d.receive(0x000, bytes([0x01, d.node]))
        d.pop_frames()
    for d in (a, b):
        assert d.receive(0x300 + 125, encode_execute("BG"))
    assert [f[0] for f in a.pop_frames()] == [0x280 + 10]  # each answers with its own id
    clock.advance(0.2)
    a.tick(), b.tick()
    assert a.px == b.px > 0


def test_sim_start_skew_delays_a_separately_received_bg():
    clock = ManualClock()
    a, b = _drive(clock, 10, start_skew_s=0.05), _drive(clock, 11)
    a.receive(0x30A, encode_execute("BG"))
    b.receive(0x30B, encode_execute("BG"))
    clock.advance(0.04)
    a.tick(), b.tick()
    assert a.px == 0 and b.px > 0
    clock.advance(1.0)
    a.tick(), b.tick()
    assert a.px == b.px == 500


@pytest.mark.parametrize("needs_reset", [True, False], ids=["as-documented", "at-once"])
def test_sim_group_id_takes_effect_after_reset_communication_unless_set_otherwise(needs_reset):
    """`group_id_needs_reset_comm` (default true, Elmo's guide 13-10): a group BG reaches no motor
    until a reset communication, which keeps the application's RAM (the motor stays on, PA kept)."""
    clock = ManualClock()
    d = _drive(clock, 10, group_id_needs_reset_comm=needs_reset)
    d.od_write(0x2040, 0, 125)
    assert d.group_id_written == 125
    assert bool(d.receive(0x300 + 125, encode_execute("BG"))) is not needs_reset
    assert d.group_id == (0 if needs_reset else 125)
    d.receive(0x000, bytes([0x82, 10]))
    d.receive(0x000, bytes([0x01, 10]))
    assert d.group_id == 125 and d.motor_on


def test_sim_group_id_is_ram_and_ignored_when_zero():
    clock = ManualClock()
    a = _drive(clock, 10)
    assert not a.receive(0x300 + 125, encode_execute("BG"))
    a.od_write(0x2040, 0, 125)
    a.receive(0x000, bytes([0x81, 10]))  # reset node: RAM from flash
    assert a.group_id == 0


# --------------------------------------------------------------------------- moves

def _run(cfg, **kw):
    """A move on stepped time (motion_helpers.stepped_session): the coupling it reports is the simulated
    pair's, not the host's load (on wall time a stalled feedback loop let the held joint run)."""
    with stepped_session(cfg) as (s, stepped):
        r = diffdrive.run_move(s, cfg.pairs["diff"], PairTarget(**kw), timebase=stepped)
        with s.sim.lock:
            groups = [d.group_id_written for d in s.sim.drives.values()]
            saves = [d.save_count for d in s.sim.drives.values()]
            on = [d.motor_on for d in s.sim.drives.values()]
        assert s.sim.errors == []
    return r, groups, saves, on


def test_naive_group_and_feedback_moves_end_on_target_and_report_the_coupling(cfg):
    results = {}
    for name, kw in (("naive", {"naive": True}), ("group", {}), ("feedback", {"feedback": True})):
        r, groups, saves, on = _run(cfg, sigma="1", **kw)
        assert r.ok and abs(r.end[0] - r.target[0]) <= 1 and abs(r.end[1] - r.target[1]) <= 1, r.as_dict()
        assert groups == [0, 0] and saves == [0, 0] and on == [False, False]  # 0x2040 put back, nothing saved
        assert r.coupling.held == "roll" and len(r.samples) > 10
        results[name] = r.coupling.held_peak
    # the seed's shape: the held joint moves during a naive move; feedback shrinks it
    assert results["naive"] >= 20
    assert results["feedback"] < results["naive"] / 2, results


def test_delta_move_with_relative_and_the_plot(cfg, tmp_path):
    import matplotlib.pyplot as plt

    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        r = diffdrive.run_move(s, cfg.pairs["diff"], PairTarget(delta="-10deg", relative=True))
    assert abs(r.end[1] - r.target[1]) <= 1 and r.coupling.held == "pitch"
    out = tmp_path / "move.png"
    diffdrive.plot(r, str(out))
    image = plt.imread(out)
    assert image.shape[0] > 100 and image.shape[1] > 100


def test_uncalibrated_pair_is_refused_before_anything_moves():
    cfg = load_config(FAST)  # no abs encoder, not homed
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        with pytest.raises(SafetyError, match=r"not|calibrat"):
            diffdrive.run_move(s, cfg.pairs["diff"], PairTarget(sigma="100counts"))
        with s.sim.lock:
            assert all(not d.motor_on and not d.od_writes for d in s.sim.drives.values())
        r = diffdrive.run_move(s, cfg.pairs["diff"], PairTarget(sigma="100counts", uncalibrated=True))
        assert abs(r.end[0] - 100) <= 1


def _pitch_to_300(s: ArmSession, cfg):
    """A position jog of the pair's Σ joint to 300 counts (one group start)."""
    from sherpa_cli.ops import joint_jog

    return joint_jog.run(s, resolve_axis(cfg, "pitch"),
                         parse_request(resolve_axis(cfg, "pitch"), mode="position", to="300counts", uncalibrated=True))


def _nmt_reset_comms(drive) -> list[float]:
    return [t for t, can_id, data in drive.received if can_id == 0x000 and data[:2] == bytes([0x82, drive.node])]


def _consumer_writes(drive) -> list[float]:
    return [t for t, can_id, data in drive.received
            if can_id == 0x600 + drive.node and data[:4] == bytes([0x23, 0x16, 0x10, 0x01])]


def test_a_group_start_resets_communication_with_the_motors_off_and_arms_the_dead_man_again():
    """Elmo's guide (13-10): 0x2040 acts after a reset communication, which also puts back the
    heartbeat consumer the guard armed. So: group id on both drives, reset communication (motors
    off), the dead-man written again and read back, then MO=1 and the one group BG."""

    cfg = load_config(FAST)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        r = _pitch_to_300(s, cfg)
        assert abs(r.end_counts - 300) <= 1
        with s.sim.lock:
            for d in (s.sim.drives["left"], s.sim.drives["right"]):
                resets = _nmt_reset_comms(d)
                on = [t for t, text in d.events if text.startswith("motor on")]
                assert len(resets) == 1 and on and resets[0] < on[0], (resets, on)
                assert [t for t in _consumer_writes(d) if resets[0] < t < on[0]], "not armed again before MO=1"
                assert d.unguarded_motor_on == 0
                assert d.group_id == 125 and d.group_id_written == 0  # in effect until the next reset


def test_without_the_reset_communication_a_group_start_on_a_documented_drive_moves_nothing(tmp_path):
    """`motion.pair_group_reset_comm: false` on a drive that needs it (the simulator's default): the
    group BG reaches no motor. The setting is for a drive on which 0x2040 acts at once."""

    text = FAST.read_text(encoding="utf-8").replace("motion: {consumer_time_ms: 1000}",
                                                    "motion: {consumer_time_ms: 1000, pair_group_reset_comm: false}")
    assert "pair_group_reset_comm: false" in text
    path = tmp_path / "arm.yaml"
    path.write_text(text, encoding="utf-8")
    cfg = load_config(path)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        with pytest.raises(SherpaError):
            _pitch_to_300(s, cfg)
        with s.sim.lock:
            assert all(not _nmt_reset_comms(d) and d.px == 0 for d in s.sim.drives.values())


def test_jog_of_a_pair_joint_starts_both_motors_with_one_group_bg():

    cfg = load_config(FAST)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        r = _pitch_to_300(s, cfg)
        assert abs(r.end_counts - 300) <= 1
        with s.sim.lock:
            left, right = s.sim.drives["left"], s.sim.drives["right"]
            group_bg = [f[1:] for f in left.received if f[1] == 0x300 + 125]
            own_bg = [f for f in left.received if f[1] == 0x30A and f[2] == encode_execute("BG")]
            assert group_bg == [(0x300 + 125, encode_execute("BG"))]
            assert group_bg == [f[1:] for f in right.received if f[1] == 0x300 + 125]
            assert not own_bg  # the move's begin went to the group only
            assert left.group_id_written == right.group_id_written == 0  # put back (RAM)
            writes = [w for w in left.od_writes if w[1] == 0x2040]
            assert [w[3] for w in writes] == [125, 0]


def test_pair_start_sequential_setting_sends_two_bg(tmp_path):
    text = FAST.read_text().replace("motion: {consumer_time_ms: 1000}",
                                    "motion: {consumer_time_ms: 1000, pair_start: sequential}")
    path = tmp_path / "seq.yaml"
    path.write_text(text)
    cfg = load_config(path)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        r = diffdrive.run_move(s, cfg.pairs["diff"], PairTarget(delta="100counts", uncalibrated=True))
        assert r.mode == "sequential" and abs(r.end[1] - 100) <= 1
        with s.sim.lock:
            assert not s.sim.drives["left"].od_writes or all(w[1] != 0x2040 for w in s.sim.drives["left"].od_writes)
            assert any(f[1] == 0x30A and f[2] == encode_execute("BG") for f in s.sim.drives["left"].received)


def test_bad_pair_settings_are_refused(tmp_path):
    from sherpa_cli.errors import ConfigError

    for setting in ("pair_start: together", "pair_group_id: 126"):
        text = FAST.read_text().replace("motion: {consumer_time_ms: 1000}",
                                        "motion: {consumer_time_ms: 1000, " + setting + "}")
        path = tmp_path / "bad.yaml"
        path.write_text(text)
        with pytest.raises(ConfigError, match="pair_"):
            pair_start.pair_settings(load_config(path))


def test_sim_lag_makes_px_trail_the_profile_and_settle_on_target():
    clock = ManualClock()
    slow, fast = _drive(clock, 10, lag_s=0.02), _drive(clock, 11)
    for d in (slow, fast):
        d.receive(0x300 + d.node, encode_execute("BG"))
    clock.advance(0.1)
    slow.tick(), fast.tick()
    assert 0 < slow.px < fast.px - 5  # behind while moving
    clock.advance(1.0)
    slow.tick(), fast.tick()
    assert slow.px == fast.px == 500


def test_a_naive_move_whose_held_joint_leaves_its_full_range_is_stopped_and_brought_back(tmp_path):
    # Δ's normal range ends 10 counts inside its full range: the naive Σ move's coupling (~60) crosses it
    text = MISMATCHED.read_text().replace("range: {min: -2000, max: 2000, margin: 100, overshoot: 400}",
                                          "range: {min: -2000, max: 2000, margin: 10, overshoot: 400}")
    path = tmp_path / "tight.yaml"
    path.write_text(text)
    cfg = load_config(path)
    # on stepped time: on wall time a loaded machine let the first move end a count past 1990
    with stepped_session(cfg) as (s, stepped):
        first = diffdrive.run_move(s, cfg.pairs["diff"], PairTarget(delta="1990counts"), timebase=stepped)
        assert first.ok and abs(first.end[1] - 1990) <= 1, first.as_dict()
        r = diffdrive.run_move(s, cfg.pairs["diff"], PairTarget(sigma="-1", naive=True), timebase=stepped)
        assert not r.ok and r.outcome == "limit" and r.breaches[0].joint == "roll", r.as_dict()
        assert -1990 <= r.end[1] <= 1990  # back inside the normal range
        with s.sim.lock:
            assert all(not d.motor_on for d in s.sim.drives.values())


# --------------------------------------------------------------------------- recording

PDO_OBJECTS = [(0x1800, 1, 4), (0x1800, 2, 1), (0x1A00, 0, 1), (0x1A00, 1, 4), (0x1A00, 2, 4)]


def _pdo(session, cfg):
    refs = diffdrive._refs(cfg, ("left", "right"))
    return {r.name: [int.from_bytes(session.sdo(r).upload(i, s)[:n], "little") for i, s, n in PDO_OBJECTS]
            for r in refs}


class CountingSync:
    """A SYNC source for the recorder (its sync_factory seam): the real periodic one, remembered."""

    def __init__(self) -> None:
        self.periods: list[float] = []

    def factory(self, name, bus, period):
        from sherpa_cli.log.record import PeriodicSync

        self.periods.append(period)
        return PeriodicSync(bus, period)


@pytest.mark.serial  # the real periodic SYNC thread on wall time (docs/testing.md): run alone by .ci/run
def test_the_move_records_both_motors_by_tpdo_on_sync_and_puts_the_pdo_settings_back(cfg):
    sync = CountingSync()
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        before = _pdo(s, cfg)
        r = diffdrive.run_move(s, cfg.pairs["diff"], PairTarget(sigma="0.5"),
                               recorder_kw={"sync_factory": sync.factory})
        after = _pdo(s, cfg)
        with s.sim.lock:
            syncs = {n: d.syncs for n, d in s.sim.drives.items()}
            saves = [d.save_count for d in s.sim.drives.values()]
    assert r.trace_source == "TPDO on SYNC at 500 Hz" and sync.periods == [pytest.approx(1 / 500)]
    assert after == before and saves == [0, 0]  # RAM only, put back
    assert min(syncs.values()) > 100
    # one sample per SYNC, both motors of the same SYNC: timestamps on the 2 ms grid from the begin
    times = [t for t, _, _ in r.samples]
    assert len(r.samples) > 0.5 * (times[-1] - times[0]) * 500
    steps = {round((b - a) * 500) for a, b in itertools.pairwise(times)}
    assert 1 in steps and all(k >= 1 for k in steps)
    assert r.samples[-1][1:] == (r.motors_end["left"], r.motors_end["right"])
    assert abs(r.end[0] - r.target[0]) <= 1 and r.coupling.held == "roll"


def test_poll_records_through_the_interpreter_and_changes_no_pdo(cfg):
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        r = diffdrive.run_move(s, cfg.pairs["diff"], PairTarget(sigma="0.3", poll=True))
        with s.sim.lock:
            pdo_writes = [w for d in s.sim.drives.values() for w in d.od_writes if 0x1800 <= w[1] <= 0x1AFF]
            syncs = [d.syncs for d in s.sim.drives.values()]
    assert r.trace_source == "polled PX (--poll)" and len(r.samples) > 5
    assert pdo_writes == [] and syncs == [0, 0]
    assert abs(r.end[0] - r.target[0]) <= 1


def test_a_recorder_that_cannot_start_falls_back_to_polling_and_restores_the_pdo(cfg):
    def no_sync(name, bus, period):
        raise OSError("no SYNC on this bus")

    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        before = _pdo(s, cfg)
        r = diffdrive.run_move(s, cfg.pairs["diff"], PairTarget(delta="100counts", relative=True),
                               recorder_kw={"sync_factory": no_sync})
        assert _pdo(s, cfg) == before
    assert r.trace_source == "polled PX (the recorder could not be set up: no SYNC on this bus)"
    assert abs(r.end[1] - r.target[1]) <= 1 and len(r.samples) > 5


def test_an_error_during_the_move_still_puts_the_pdo_settings_back(cfg):
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        before = _pdo(s, cfg)

        class Boom(Exception):
            pass

        def sleep(seconds):
            if s.sim.drives["left"].motor.v:  # the motors run: fail inside the move's loop
                raise Boom()
            time.sleep(seconds)

        with pytest.raises(Boom):
            diffdrive.run_move(s, cfg.pairs["diff"], PairTarget(sigma="0.5"), sleep=sleep)
        assert _pdo(s, cfg) == before
        with s.sim.lock:
            assert all(not d.motor_on and d.group_id_written == 0 for d in s.sim.drives.values())
            for d in s.sim.drives.values():
                # each motor got its stop before the recorder put its PDO settings back
                st = [t for t, i, f in d.received if i == 0x300 + d.node and f[:2] == b"ST"]
                bg = [t for t, i, f in d.received if i in (0x300 + d.node, 0x300 + 125) and f[:2] == b"BG"]
                pdo_back = [t for t, i, _, _ in d.od_writes if i in (0x1800, 0x1A00) and t > bg[-1]]
                assert st and pdo_back and st[0] < min(pdo_back)


def test_the_record_rate_is_capped_to_the_bus_budget(cfg, tmp_path):
    refs = diffdrive._refs(cfg, ("left", "right"))
    assert diffdrive.record_rate(cfg, refs) == (500.0, "")
    text = MISMATCHED.read_text().replace("can0: {interface: socketcan, channel: can0}",
                                          "can0: {interface: socketcan, channel: can0, bitrate: 125000}")
    text = text.replace("motion: {consumer_time_ms: 1000}", "motion: {consumer_time_ms: 1000, pair_record_rate: 1000}")
    path = tmp_path / "slow.yaml"
    path.write_text(text)
    slow = load_config(path)
    rate, note = diffdrive.record_rate(slow, refs)
    assert 100 < rate < 1000 and note == "capped from 1000 Hz by the bus budget"


def test_a_bad_record_rate_is_refused_by_the_config(tmp_path):
    from sherpa_cli.errors import ConfigError

    text = MISMATCHED.read_text().replace("motion: {consumer_time_ms: 1000}",
                                          "motion: {consumer_time_ms: 1000, pair_record_rate: 0}")
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match="pair_record_rate 0"):
        load_config(path)


def test_recorder_latest_is_the_newest_sync_both_drives_answered():
    from sherpa_cli.log.record import Recorder

    cfg = load_config(MISMATCHED)
    clock = ManualClock()
    syncs = []
    tag = __import__("uuid").uuid4().hex[:8]
    arm = SimArm(cfg, {"can0": {"interface": "virtual", "channel": f"dd-{tag}"}}, clock=clock)
    with ArmSession.open(cfg, sim=arm) as s:
        refs = diffdrive._refs(cfg, ("left", "right"))
        with Recorder(s, refs, 100, clock=clock.now, sync_factory=lambda n, bus, p: syncs.append(bus) or
                      type("S", (), {"stop": lambda self: None})()) as rec:
            assert rec.latest() is None
            import can

            for k in range(3):
                if k:
                    clock.advance(0.01)
                syncs[0].send(can.Message(arbitration_id=0x80, data=b"", is_extended_id=False))
                deadline = time.monotonic() + 5
                while min(rec.counts().values()) < k + 1 and time.monotonic() < deadline:
                    time.sleep(0.001)
            t, values = rec.latest()
    assert t == pytest.approx(rec.t0 + 0.02) and values == {"left": (0, 0), "right": (0, 0)}


# --------------------------------------------------------------------------- pair_start: sync_rpdo

def test_sim_synchronous_rpdo2_runs_the_buffered_frame_at_the_next_sync_without_skew():
    clock = ManualClock()
    a, b = _drive(clock, 10, start_skew_s=0.05), _drive(clock, 11)
    assert a.od_read(0x1401, 2) == 255 and a.od_read(0x1401, 1) == 0x4000030A
    for d in (a, b):
        d.od_write(0x1401, 2, 1)
        assert d.receive(0x300 + d.node, encode_execute("BG"))
        d.pop_frames()
    clock.advance(0.02)
    a.tick(), b.tick()
    assert a.px == b.px == 0 and not a.pop_frames()  # buffered: nothing ran, nothing answered
    for d in (a, b):
        d.receive(0x080, b"")
    assert [f[0] for f in a.pop_frames()] == [0x28A]  # the BG's answer, at the SYNC
    clock.advance(0.2)
    a.tick(), b.tick()
    assert a.px == b.px > 0  # both started at the SYNC: the separately received BG has no skew here
    a.receive(0x000, bytes([0x81, 10]))  # reset node: RAM only
    assert a.od_read(0x1401, 2) == 255
    with pytest.raises(ODError):
        a.od_write(0x1401, 2, 250)  # no transmission type


def _sniff(channel):
    import can

    bus = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    frames = []

    class Listener(can.Listener):
        def on_message_received(self, msg):
            if not 0x700 <= msg.arbitration_id <= 0x77F:  # heartbeats come when they come
                frames.append(f"{msg.arbitration_id:03X} {bytes(msg.data).hex(' ')}".strip())
    notifier = can.Notifier(bus, [Listener()])
    return bus, notifier, frames


def test_sync_rpdo_start_frame_transcript(tmp_path):
    """Byte for byte: 0x1401:2 read on both drives, set to 1 (synchronous), BG to each drive
    (buffered), one SYNC, both BG answers, 0x1401:2 back to 255. Motors on beforehand."""
    import uuid

    cfg = load_config(FAST)
    channel = f"dd-sync-{uuid.uuid4().hex[:8]}"
    arm = SimArm(cfg, {"can0": {"interface": "virtual", "channel": channel}})
    with ArmSession.open(cfg, sim=arm) as s:
        refs = diffdrive._refs(cfg, ("left", "right"))
        clients = {r.name: s.client(r) for r in refs}
        for c in clients.values():
            c.nmt_start()
            c.set("UM", 0, 5)
            c.set("PA", 0, 100)
            c.motor_on()
        sniff, notifier, frames = _sniff(channel)
        try:
            with pair_start.CommonStart(s, refs, clients, "sync_rpdo", 125) as start:
                start.begin()
            deadline = time.monotonic() + 5
            while len(frames) < 17 and time.monotonic() < deadline:  # the sniffer's thread may lag
                time.sleep(0.01)
            time.sleep(0.05)  # and nothing more comes
        finally:
            notifier.stop()
            sniff.shutdown()
        with s.sim.lock:
            left, right = s.sim.drives["left"], s.sim.drives["right"]
            begins = [t for d in (left, right) for t, text in d.events if text.startswith("BG")]
            rpdo_types = (left.od_read(0x1401, 2), right.od_read(0x1401, 2))
        for c in clients.values():
            c.motor_off()
    assert frames == [
        "60A 40 01 14 02 00 00 00 00", "58A 4f 01 14 02 ff 00 00 00",
        "60B 40 01 14 02 00 00 00 00", "58B 4f 01 14 02 ff 00 00 00",
        "60A 2f 01 14 02 01 00 00 00", "58A 60 01 14 02 00 00 00 00",
        "60B 2f 01 14 02 01 00 00 00", "58B 60 01 14 02 00 00 00 00",
        "30A 42 47 00 00", "30B 42 47 00 00", "080",
        "28A 42 47 00 00 00 00 00 00", "28B 42 47 00 00 00 00 00 00",
        "60A 2f 01 14 02 ff 00 00 00", "58A 60 01 14 02 00 00 00 00",
        "60B 2f 01 14 02 ff 00 00 00", "58B 60 01 14 02 00 00 00 00",
    ]
    assert len(begins) == 2 and abs(begins[0] - begins[1]) < 0.02  # both at the one SYNC (sim time is wall time)
    assert rpdo_types == (255, 255)


def test_pair_start_sync_rpdo_moves_the_mismatched_pair_and_restores_the_rpdo(tmp_path):
    text = MISMATCHED.read_text().replace("motion: {consumer_time_ms: 1000}",
                                          "motion: {consumer_time_ms: 1000, pair_start: sync_rpdo}")
    path = tmp_path / "sync.yaml"
    path.write_text(text)
    cfg = load_config(path)
    peaks = {}
    for name, kw in (("sync", {}), ("feedback", {"feedback": True})):
        with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
            r = diffdrive.run_move(s, cfg.pairs["diff"], PairTarget(sigma="1", **kw))
            with s.sim.lock:
                assert all(d.od_read(0x1401, 2) == 255 and d.save_count == 0 and not d.motor_on
                           for d in s.sim.drives.values())
                assert all(d.group_id_written == 0 for d in s.sim.drives.values())
        assert r.mode == "sync_rpdo" and abs(r.end[0] - r.target[0]) <= 1 and abs(r.end[1] - r.target[1]) <= 1
        peaks[name] = r.coupling.held_peak
    # no start skew (a separately received BG would start motor a 40 ms late: ~64 counts, naive);
    # what the feedback makes of it is the benchmark's business (its loop runs in wall time)
    assert peaks["sync"] < 55, peaks


def test_jog_of_a_pair_joint_with_sync_rpdo_starts_both_at_one_sync(tmp_path):

    text = FAST.read_text().replace("motion: {consumer_time_ms: 1000}",
                                    "motion: {consumer_time_ms: 1000, pair_start: sync_rpdo}")
    path = tmp_path / "sync.yaml"
    path.write_text(text)
    cfg = load_config(path)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        r = _pitch_to_300(s, cfg)
        assert abs(r.end_counts - 300) <= 1
        with s.sim.lock:
            left, right = s.sim.drives["left"], s.sim.drives["right"]
            writes = [w[3] for w in left.od_writes if w[1] == 0x1401]
            assert writes == [1, 255] and left.od_read(0x1401, 2) == right.od_read(0x1401, 2) == 255
            assert not any(f[1] == 0x300 + 125 for f in left.received)  # no group frame
            begins = [[t for t, text in d.events if text.startswith("BG")] for d in (left, right)]
            assert len(begins[0]) == len(begins[1]) == 1 and abs(begins[0][0] - begins[1][0]) < 0.02


def test_convert_takes_positions_with_their_unit_as_move_does(cli):
    """`diffdrive convert --sigma 10deg` was "not a valid float"; a bare number stays in --unit."""
    import json
    import math

    bare = cli("--json", "diffdrive", "convert", "shoulder_diff", "--sigma", "200", "--delta", "0")
    counts = cli("--json", "diffdrive", "convert", "shoulder_diff", "--sigma", "200counts", "--delta", "0counts")
    assert bare.exit_code == counts.exit_code == 0 and json.loads(bare.stdout) == json.loads(counts.stdout)
    deg = cli("--json", "diffdrive", "convert", "shoulder_diff", "--sigma", "10deg", "--delta", "0")
    assert deg.exit_code == 0, deg.stderr
    out = json.loads(deg.stdout)
    assert abs(out["sigma"]["rad"] - math.radians(10)) < 0.003  # to a count or two (the nearest reachable)
    assert "nearest reachable" in deg.stderr  # 10deg is an odd Σ with Δ=0: one count away, said


def test_convert_reads_a_bare_number_beside_one_with_its_unit_in_unit(cli):
    """`--unit rad --sigma 0.5rad --delta 1` gave Δ = 1 count (0.001 rad), exit 0: the bare number
    was read as counts once the other carried its unit."""
    import json

    def convert(*args: str) -> dict:
        result = cli("--json", "diffdrive", "convert", "shoulder_diff", *args)
        assert result.exit_code == 0, result.stderr
        return json.loads(result.stdout)

    mixed = convert("--sigma", "0.5rad", "--delta", "1", "--unit", "rad")
    assert mixed == convert("--sigma", "0.5rad", "--delta", "1rad")
    assert abs(mixed["delta"]["rad"] - 1.0) < 0.003, mixed
    assert convert("--sigma", "200counts", "--delta", "4")["delta"]["counts"] == 4  # --unit counts: 4 counts
