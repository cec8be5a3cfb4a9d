"""ops/live_jog.py on the simulated arm, in-process on stepped time (sim/stepped.py through
motion_helpers.stepped_session): the live jog's clock and waits are the stepped clock's, so the
simulated drives move only while a test waits (``run_for``, the stepped clock's ``sleep``) and how far they get, when a
command expires and when the stall watch calls a joint blocked do not depend on the host's load."""

from __future__ import annotations

import pytest
from motion_helpers import JOG_CONFIG, calibrate, motors_off, stepped_session

from sherpa_cli.config import load_config
from sherpa_cli.errors import DriveRefusedError
from sherpa_cli.ops.live_jog import LiveJog, resolve_axes

CONFIG = JOG_CONFIG


@pytest.fixture
def cfg():
    return load_config(CONFIG)


def jog_on(stepped, session, axes, **kw):
    """A LiveJog whose clock and waits are the stepped session's."""
    return LiveJog(session, axes, clock=stepped.now, sleep=stepped.sleep, **kw)


def run_for(live, seconds, every=0.03, until=None):
    """Tick for ``seconds`` of simulated time (or, with ``until``, until it holds: at most ``seconds``)."""
    end = live.clock() + seconds
    while live.clock() < end:
        live.tick()
        if until is not None and until():
            break
        live.sleep(every)
    return live.tick()


def test_velocity_expires_without_a_new_command_and_exit_stops_everything(cfg):
    with stepped_session(cfg) as (s, stepped):
        with jog_on(stepped, s, resolve_axes(cfg, ["j1"]), keepalive=0.3) as live:
            start = live.state["j1"].counts
            live.set_velocity("j1", 2000)
            assert "j1" in live.running
            state = run_for(live, 0.6)
            assert "j1" not in live.running  # expired: no new command within keepalive
            moved = state["j1"].counts - start
            assert 200 < moved < 2000
            at = run_for(live, 0.2)["j1"].counts
            assert abs(at - state["j1"].counts) < 60  # standing
        assert motors_off(s)
        assert [d.stopped_by for d in live.report.drives] and s.sim.errors == []


def test_step_refused_uncalibrated_then_moves_a_pair_joint_and_the_other_holds(cfg):
    with stepped_session(cfg) as (s, stepped):
        with jog_on(stepped, s, resolve_axes(cfg, ["diff"])) as live:
            assert set(live.axes) == {"pitch", "roll"}
            assert "not sent" not in live.step("pitch", 300) and "calibrated" in live.state["pitch"].note
            assert "pitch" not in live.running
        calibrate(s, "left", "right")
        with jog_on(stepped, s, resolve_axes(cfg, ["pitch", "roll"])) as live:
            roll0 = live.state["roll"].counts
            live.step("pitch", 300)
            state = run_for(live, 0.5)
            assert abs(state["pitch"].counts - 300) <= 1 and abs(state["roll"].counts - roll0) <= 1
            assert "outside the normal range" in live.step("pitch", 10_000)
        assert motors_off(s)


def test_a_command_further_out_than_the_normal_edge_is_not_sent(cfg):
    with stepped_session(cfg) as (s, stepped):
        with jog_on(stepped, s, resolve_axes(cfg, ["j1"]), keepalive=5.0) as live:
            live.set_velocity("j1", 4000)  # toward +1900 (normal high edge: 2000 - 100)
            state = run_for(live, 0.6)
            assert "j1" not in live.running and "edge" in state["j1"].note
            hi = cfg.joints["j1"].normal_range[1]
            assert 1000 < state["j1"].counts <= hi  # stopped early by its stopping distance, never past
            assert "not sent" in live.set_velocity("j1", 4000)
            assert "j1" not in live.running
            assert live.set_velocity("j1", -1000).startswith("j1: JV=")  # inward is fine
        assert motors_off(s)


def test_the_full_range_watch_stops_everything_and_brings_the_joint_back(cfg):
    with stepped_session(cfg) as (s, stepped):
        with jog_on(stepped, s, resolve_axes(cfg, ["j1"]), keepalive=5.0, tick_period=0.0) as live:
            live.cfg = cfg.__class__(**{**cfg.__dict__, "joints": {**cfg.joints, "j1": cfg.joints["j1"].__class__(
                **{**cfg.joints["j1"].__dict__, "decel": None})}})  # no stopping distance: the edge hold is late
            live.set_velocity("j1", 1000)
            # The edge hold would normally stop the joint first; which layer a real-time tick meets first
            # depends on the machine's load, so the breach is made at once: an encoder jump past the
            # full range (2000) while the velocity command runs.
            drive = cfg.joints["j1"].drive
            with s.sim.lock:
                s.sim.drives[drive].motor.counts += 2100
            state = run_for(live, 5.0, until=lambda: any(m.startswith("limit:") for m in live.messages))
            assert any(m.startswith("limit: j1 left its full range") for m in live.messages)
            assert state["j1"].counts == cfg.joints["j1"].normal_range[1] and not live.running
        assert motors_off(s)


def test_torque_runs_until_the_keepalive_and_is_refused_above_the_continuous_limit(cfg):
    with stepped_session(cfg) as (s, stepped):
        with jog_on(stepped, s, resolve_axes(cfg, ["j1"]), keepalive=0.4) as live:
            assert "above the continuous limit" in live.set_torque("j1", 2.5)  # j1: 2.0 A continuous
            assert live.running == {}
            live.set_mode("j1", "torque")
            assert live.set_torque("j1", -0.5).startswith("j1: TC=-0.5")
            state = run_for(live, 0.8)
            assert "j1" not in live.running and state["j1"].command == "-"
            assert state["j1"].counts < -20  # the current moved it backwards
        assert motors_off(s)
        kinds = [d.stopped_by for d in live.report.drives]
        assert kinds and all(k != "not stopped" for k in kinds)


def _refuse_bg(client):
    real = client.execute

    def refuse(letters, index=0):
        if letters == "BG":
            raise DriveRefusedError(f"{client.label}: BG refused (test)")
        return real(letters, index)
    client.execute = refuse
    return real


def _speed(session, drive):
    with session.sim.lock:
        return session.sim.drives[drive].motor.v


@pytest.mark.parametrize("how", ["stop_all", "stop", "expiry"])
def test_a_half_sent_velocity_command_is_still_stoppable(cfg, how):
    """Review R3: the second drive's BG of a pair is refused after the first motor started: the
    command is recorded before the first write, so stop, STOP ALL and the keepalive still stop it."""
    with stepped_session(cfg) as (s, stepped):
        calibrate(s, "left", "right")
        with jog_on(stepped, s, resolve_axes(cfg, ["pitch", "roll"]), keepalive=0.3) as live:
            right = live._client("right")
            real = _refuse_bg(right)
            with pytest.raises(DriveRefusedError):
                live.set_velocity("pitch", 2000)
            right.execute = real
            stepped.sleep(0.15)
            assert abs(_speed(s, "left")) > 500  # the first motor did start
            if how == "stop_all":
                live.stop_all()  # Space in the view, a joystick dead-man release
            elif how == "stop":
                live.stop("pitch")  # `s` in the view
            run_for(live, 0.5)  # expiry: the keepalive alone
            assert abs(_speed(s, "left")) < 50 and "pitch" not in live.running
        assert motors_off(s)


def test_stop_all_stops_every_guarded_motor_not_only_the_recorded_commands(cfg):
    """Review R3: STOP ALL sends a stop to every live drive of the session, so a motor running with
    no command on record (however it came to) stops too."""
    with stepped_session(cfg) as (s, stepped):
        with jog_on(stepped, s, resolve_axes(cfg, ["j1"]), keepalive=5.0) as live:
            live.set_velocity("j1", 2000)
            run_for(live, 0.3)
            live.running.clear()  # the record lost (the failure R3 was about)
            live.stop_all()
            stepped.sleep(0.3)
            assert abs(_speed(s, "yaw")) < 50
        assert motors_off(s)


def _shifted_range_config(tmp_path):
    """j1 with its range [1000, 5000]: uncalibrated at power-up it reads PX=0, outside its full range."""
    text = CONFIG.read_text().replace("range: {min: -2000, max: 2000, margin: 100, overshoot: 400}",
                                      "range: {min: 1000, max: 5000, margin: 100, overshoot: 400}", 1)
    p = tmp_path / "arm.yaml"
    p.write_text(text)
    return load_config(p)


def _begins(session, drive):
    with session.sim.lock:
        return [f for _, _, f in session.sim.drives[drive].received if bytes(f)[:2] == b"BG"]


def test_opening_a_session_moves_nothing_found_outside_its_range(tmp_path):
    """Review R4: a joint found outside its full range when the session opens is reported, not
    brought back (no MO=1, PA, BG nobody asked for); a command further out is not sent, one back
    inward is, and the watch does not take over the joint while it comes back."""
    cfg = _shifted_range_config(tmp_path)
    with stepped_session(cfg) as (s, stepped):
        stepped.sleep(0.01)  # the simulated arm's first step puts the joint against its hard stop (600)
        x0 = px_of(s, "yaw")
        with jog_on(stepped, s, resolve_axes(cfg, ["j1"]), keepalive=0.3) as live:
            state = run_for(live, 0.3)
            assert not _begins(s, "yaw") and abs(px_of(s, "yaw") - x0) < 1
            assert any("outside its full range" in m and "not brought back" in m for m in live.messages)
            assert "outside its full range" in state["j1"].note
            assert "not sent" in live.set_velocity("j1", -1000)  # further out
            assert "not sent" in live.set_torque("j1", -0.5)
            assert not _begins(s, "yaw")
            assert live.set_velocity("j1", 1000).startswith("j1: JV=")  # back inward: a key press
            run_for(live, 0.6)
            assert len(_begins(s, "yaw")) == 1  # that command's BG only: no recovery move
            assert not any(m.startswith("limit:") and "brought back to" in m for m in live.messages)
            assert px_of(s, "yaw") > x0 + 100
        assert motors_off(s)


def px_of(session, drive):
    with session.sim.lock:
        return session.sim.drives[drive].position


def _jam(motor):
    """The joint is blocked (a collision, a jammed gear): commanded motion makes no progress."""
    step = motor.step

    def jammed(dt):
        counts, frac = motor.counts, motor.frac
        step(dt)
        motor.counts, motor.frac, motor.v = counts, frac, 0.0
    motor.step = jammed


@pytest.mark.parametrize("mode", ["velocity", "torque"])
def test_a_blocked_command_is_stopped_named_and_not_sent_again_the_same_way(cfg, mode):
    with stepped_session(cfg) as (s, stepped):
        with jog_on(stepped, s, resolve_axes(cfg, ["j1"]), keepalive=0.3) as live:
            live.set_mode("j1", mode)
            send = (lambda sign: live.set_velocity("j1", sign * 1000)) if mode == "velocity" else \
                (lambda sign: live.set_torque("j1", sign * 0.5))
            with s.sim.lock:
                _jam(s.sim.drives[cfg.joints["j1"].drive].motor)
            end = live.clock() + 3 * live.settings.stall_time + 1.0
            while live.clock() < end and not any("blocked" in m for m in live.messages):
                send(1)  # the key held: the command refreshed
                live.tick()
                live.sleep(0.03)
            (text,) = [m for m in live.messages if "blocked" in m]
            assert text.startswith("j1: blocked: no progress for") and "no end switch active" in text
            assert "j1" not in live.running and live.state["j1"].note == text
            assert send(1) == text and "j1" not in live.running  # still held: refused
            assert send(-1).startswith("j1: ")  # the other way is sent
            assert "j1" in live.running
        assert motors_off(s)


def test_a_command_eased_back_the_same_way_asks_only_the_slower_speeds_progress(cfg):
    """Review: the watch kept the first command's threshold, so a stick eased back to a tenth of its
    speed was called blocked while the joint moved freely. A faster refresh does not raise it again."""
    from sherpa_cli.motion.blocked import min_progress_for

    with stepped_session(cfg) as (s, stepped):
        with jog_on(stepped, s, resolve_axes(cfg, ["j1"]), keepalive=0.3) as live:
            stall_time = live.settings.stall_time
            sign = -1 if live.state["j1"].counts > 0 else 1
            live.set_velocity("j1", sign * 3000)
            watch = live.stalls["j1"][1]
            assert watch.min_progress == min_progress_for(3000, stall_time)
            live.set_velocity("j1", sign * 100)
            assert live.stalls["j1"][1] is watch  # the same watch: its timer runs on
            assert watch.min_progress == min_progress_for(100, stall_time)
            live.set_velocity("j1", sign * 3000)
            assert watch.min_progress == min_progress_for(100, stall_time)
        assert motors_off(s)


def test_a_position_step_replacing_a_velocity_command_is_not_stall_watched(cfg):
    """Review: a step after a velocity command kept that command's stall watch, which a slow step
    (or a real drive's ~1 s mode switch) could trip as "blocked"."""
    with stepped_session(cfg) as (s, stepped):
        with jog_on(stepped, s, resolve_axes(cfg, ["j1"]), keepalive=0.5, allow_uncalibrated=True) as live:
            sign = -1 if live.state["j1"].counts > 0 else 1
            live.set_velocity("j1", sign * 1000)
            assert "j1" in live.stalls
            live.step("j1", sign * 5)
            assert live.running["j1"].mode == "position" and "j1" not in live.stalls
        assert motors_off(s)
