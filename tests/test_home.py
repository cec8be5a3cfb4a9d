"""`sherpa home` on the simulated arm (tests/data/home-arm.yaml): each kind homes to within one count of
its calibration position (checked against the simulated joint's real position, which starts away from
it while PX reads 0), a pair leaves Σ and Δ at theirs, a missing switch stops at the bound, a drive in
fault is refused, jog refuses a position move before `home` and accepts it after, an absolute-encoder
joint gets no motion command, and the wiring check finds a swapped and an inverted input."""

from __future__ import annotations

from pathlib import Path

import pytest

from sherpa_cli.bus.session import ArmSession, resolve_target
from sherpa_cli.config import load_config
from sherpa_cli.errors import SafetyError, UsageError
from sherpa_cli.motion.axis import resolve_axis
from sherpa_cli.ops import home
from sherpa_cli.sim.arm import SimArm

ROOT = Path(__file__).resolve().parent.parent
ARM = ROOT / "tests" / "data" / "home-arm.yaml"
WIRING = ROOT / "tests" / "data" / "home-wiring-arm.yaml"
MOTION_LETTERS = (b"BG", b"MO", b"PA", b"PR", b"JV", b"TC")  # sets/executes that could move a motor


def variant(tmp_path: Path, *replace: tuple[str, str], src: Path = ARM):
    text = src.read_text(encoding="utf-8")
    for old, new in replace:
        assert old in text
        text = text.replace(old, new)
    path = tmp_path / "arm.yaml"
    path.write_text(text, encoding="utf-8")
    return load_config(path)


def physical(session, drive: str) -> float:
    with session.sim.lock:
        return session.sim.drives[drive].position


def px(session, drive: str) -> int:
    with session.sim.lock:
        return session.sim.drives[drive].px


def homed(cfg, names, **kw):
    plan = home.plan_home(cfg, names, **kw)
    session = ArmSession.open(cfg, sim=SimArm.in_process(cfg))
    return plan, session


# -- the plan ---------------------------------------------------------------------------------------

def test_plan_picks_the_kind_from_the_config():
    cfg = load_config(ARM)
    plan = home.plan_home(cfg)
    assert [(u.name, u.kind) for u in plan.units] == [("yaw", "home_switch"), ("stiff", "end_switches"),
                                                      ("twist", "abs_encoder"), ("elbow", "abs_encoder"),
                                                      ("diff", "pair")]
    yaw = plan.units[0]
    # bounded search toward the switch at cal_speed: the full range plus the margin, never open-ended
    assert yaw.moves[0] == home.HomeMove("yaw", "search", 1, 1000, 800 + 20)
    assert [m.what for m in yaw.moves] == ["search", "back off", "slow re-approach", "return"]
    assert yaw.moves[2].speed == 250  # cal_speed / homing.slow_divisor
    assert plan.units[2].moves == ()  # the absolute encoder moves nothing


def test_plan_names_a_pair_by_its_sigma_joint_and_refuses_a_joint_it_cannot_home(tmp_path):
    cfg = load_config(ARM)
    assert [u.name for u in home.plan_home(cfg, ["roll"]).units] == ["diff"]
    bad = variant(tmp_path, ("    calibration: {speed: 1000, position: 0}\n", ""))
    with pytest.raises(UsageError, match="yaw: cannot be homed: no calibration speed"):
        home.plan_home(bad, ["yaw"])
    assert ("yaw", "no calibration speed (calibration: {speed: ...})") in home.plan_home(bad).skipped


# -- each kind --------------------------------------------------------------------------------------

def test_home_switch_sets_the_calibration_position_at_the_switch_and_reports_the_repeat():
    cfg = load_config(ARM)
    plan, ctx = homed(cfg, ["yaw"])
    with ctx as s:
        assert px(s, "yaw_drive") == 0 and physical(s, "yaw_drive") == -150  # powered up away from the switch
        report = home.run_home(s, plan)
        (u,) = report.units
        assert u.kind == "home_switch" and u.set_to == {"yaw": 0}
        assert u.repeat_difference is not None and abs(u.repeat_difference) <= 1
        # the counter now means the joint: PX matches the real position to within a count
        assert abs(px(s, "yaw_drive") - physical(s, "yaw_drive")) <= 1
        assert u.positions == {"yaw": 0} and abs(physical(s, "yaw_drive")) <= 1
        with s.sim.lock:
            assert s.sim.drives["yaw_drive"].ram["UI[3]"] == 1  # the calibration mark
            assert any(text.startswith("home event") for _, text in s.sim.drives["yaw_drive"].events)
        assert s.sim.errors == []


def test_a_second_home_starting_on_the_switch_moves_off_it_first():
    # After a home the joint stands at the switch, its input pressed: a search from there would see
    # no edge and run to its bound. The home moves off the switch (bounded) and searches again.
    cfg = load_config(ARM)
    plan, ctx = homed(cfg, ["yaw"])
    with ctx as s:
        home.run_home(s, plan)
        with s.sim.lock:
            s.sim.drives["yaw_drive"]._px_offset += 37  # the counter drifted: the second home must fix it
        (u,) = home.run_home(s, plan).units
        assert abs(px(s, "yaw_drive") - physical(s, "yaw_drive")) <= 1
        assert u.positions == {"yaw": 0} and abs(physical(s, "yaw_drive")) <= 1
        assert u.repeat_difference is not None and abs(u.repeat_difference) <= 1
        assert s.sim.errors == []


def test_end_switches_set_the_low_end_and_measure_the_range():
    cfg = load_config(ARM)
    plan, ctx = homed(cfg, ["stiff"], measure_range=True)
    with ctx as s:
        (u,) = home.run_home(s, plan).units
        assert u.set_to == {"stiff": -300}
        assert abs(px(s, "stiff_drive") - physical(s, "stiff_drive")) <= 1
        assert u.positions == {"stiff": 280}  # measured to the high switch, then back to the normal high edge
        assert u.configured_travel == 600 and abs(u.measured_travel - 600) <= 2


def test_end_switches_starting_past_the_switch_move_off_it_first(tmp_path):
    # A home interrupted just after its search met the end switch (the return had begun) leaves the
    # joint past the switch edge, its input pressed: a search from there sees no edge and pushed into
    # the end stop until the stall watch called it blocked (a flaky cross-process test in CI).
    # The home moves off the switch first, as for a home switch, and finds the edge.
    cfg = variant(tmp_path, ("stiff: 120", "stiff: -308"))
    plan, ctx = homed(cfg, ["stiff"])
    with ctx as s:
        c = s.client(resolve_target(cfg, "stiff_drive"))
        c.nmt_start()
        assert home._pins(c)[3], "the low end switch (input 3) must read pressed at the start"
        (u,) = home.run_home(s, plan).units
        assert u.set_to == {"stiff": -300} and u.positions == {"stiff": -280}
        assert abs(px(s, "stiff_drive") - physical(s, "stiff_drive")) <= 1
        assert abs(physical(s, "stiff_drive") + 280) <= 1


def test_end_switches_return_into_the_normal_range():
    cfg = load_config(ARM)
    plan, ctx = homed(cfg, ["stiff"])
    with ctx as s:
        (u,) = home.run_home(s, plan).units
        assert u.positions == {"stiff": -280}
        assert abs(physical(s, "stiff_drive") + 280) <= 1


def test_pair_leaves_sigma_and_delta_at_their_calibration_positions():
    cfg = load_config(ARM)
    plan, ctx = homed(cfg, ["diff"])
    with ctx as s:
        (u,) = home.run_home(s, plan).units
        a, b = physical(s, "pair_a"), physical(s, "pair_b")
        pa, pb = px(s, "pair_a"), px(s, "pair_b")
        # the counters mean Σ and Δ through the pair transform, to within a count
        assert abs((pa + pb) - (a + b)) <= 1 and abs((pa - pb) - (a - b)) <= 1
        assert u.set_to == {"pitch": -500, "roll": -500}
        assert u.positions == {"pitch": pa + pb, "roll": pa - pb}
        assert -470 <= pa + pb <= 470 and -470 <= pa - pb <= 470  # back inside both normal ranges
        with s.sim.lock:
            assert s.sim.drives["pair_a"].ram["UI[3]"] == 1 and s.sim.drives["pair_b"].ram["UI[3]"] == 1


def test_absolute_encoder_sets_px_from_the_encoder_without_any_motion_command():
    cfg = load_config(ARM)
    plan, ctx = homed(cfg, ["twist"])
    with ctx as s:
        (u,) = home.run_home(s, plan).units
        assert u.encoder == {"twist_drive": 321} and u.set_to == {"twist": 321} and px(s, "twist_drive") == 321
        with s.sim.lock:
            frames = [bytes(data) for _, can_id, data in s.sim.drives["twist_drive"].received
                      if 0x300 < can_id < 0x380]
        sets = [f for f in frames if len(f) == 8 and not f[3] & 0x40]  # interpreter sets/executes, not queries
        assert frames and not [f for f in sets if f[:2] in MOTION_LETTERS]
        assert not [f for f in frames if f[:2] in (b"BG",)]


def test_absolute_encoder_offset_is_added(tmp_path):
    cfg = variant(tmp_path, ('abs_encoder: {source: "drive:PY", offset: 0}', 'abs_encoder: {source: "drive:PY", offset: 50}'))
    plan, ctx = homed(cfg, ["twist"])
    with ctx as s:
        (u,) = home.run_home(s, plan).units
        # the simulated encoder reads the joint minus the configured offset, so PX = the real position
        assert u.encoder == {"twist_drive": 271} and px(s, "twist_drive") == 321


# -- the simulator's default power-up: away from the calibration position, PX = 0 -----------------------

def test_default_power_up_is_away_from_the_switch_and_tells_a_wrong_home_from_a_right_one(tmp_path):
    """Without `sim: power_up:` every joint without absolute feedback powers up a quarter of the way
    from its calibration switch toward the far edge of its normal range (a pair through Σ/Δ), while
    PX reads 0. A wrong home that only zeroes PX where the joint stands is then off by that much;
    `home` brings every kind to within a count."""
    from sherpa_cli.sim.arm import default_power_up, power_up_positions

    cfg = variant(tmp_path, ("  power_up: {yaw: -150, stiff: 120, pitch: 200, roll: -100, twist: 321, elbow: -444}\n", ""))
    assert not cfg.sim_power_up
    # yaw: home switch at 0, search upward from the normal range's low edge -380: 0 + (-380 - 0) / 4
    # stiff: low end switch at -300, search downward from the high edge 280: -300 + 580 / 4
    # pitch, roll: low end switches at -500, from the high edge 470: -500 + 970 / 4 = -257.5 -> -257
    assert {j: default_power_up(cfg.joints[j]) for j in ("yaw", "stiff", "pitch", "roll", "twist", "elbow")} == {
        "yaw": -95, "stiff": -155, "pitch": -257, "roll": -257, "twist": 0, "elbow": 0}
    start = power_up_positions(cfg)
    assert (start["pair_a"], start["pair_b"]) == (-257, 0)  # Σ = a + b = -257, Δ = a - b = -257
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        assert {d: px(s, d) for d in ("yaw_drive", "stiff_drive", "pair_a", "pair_b")} == dict.fromkeys(
            ("yaw_drive", "stiff_drive", "pair_a", "pair_b"), 0)
        assert physical(s, "yaw_drive") == -95 and physical(s, "stiff_drive") == -155
        # a wrong home: PX := the calibration position where the joint stands, marked calibrated --
        # the counter is then off by the power-up distance, which a test of PX against the joint sees
        from sherpa_cli.bus.targets import drive_ref
        from sherpa_cli.motion import calibration

        c = s.client(drive_ref(cfg, "yaw_drive"))
        c.nmt_start()
        for key, value in ((3, cfg.homing.event_immediate), (4, cfg.homing.after_nothing),
                           (5, cfg.homing.px_absolute), (2, 0), (1, 1)):
            c.set("HM", key, value)
        calibration.mark_calibrated(cfg, c)
        assert px(s, "yaw_drive") == 0 and abs(px(s, "yaw_drive") - physical(s, "yaw_drive")) == 95
        # the right home of every kind: the counters mean the joints to within a count
        report = home.run_home(s, home.plan_home(cfg, ["yaw", "stiff", "diff"]))
        assert [u.kind for u in report.units] == ["home_switch", "end_switches", "pair"]
        assert abs(report.units[0].repeat_difference or 0) <= 1
        for d in ("yaw_drive", "stiff_drive"):
            assert abs(px(s, d) - physical(s, d)) <= 1, d
        a, b = physical(s, "pair_a"), physical(s, "pair_b")
        pa, pb = px(s, "pair_a"), px(s, "pair_b")
        assert abs((pa + pb) - (a + b)) <= 1 and abs((pa - pb) - (a - b)) <= 1
        assert report.units[2].set_to == {"pitch": -500, "roll": -500}


# -- refusals and failures --------------------------------------------------------------------------

def test_a_switch_that_never_triggers_stops_at_the_bound(tmp_path):
    cfg = variant(tmp_path, ("power_up: {yaw: -150,", "power_up: {yaw: -400,"),
                  ("buses:", "  wiring: {yaw_drive: {swap: [[1, 2]]}}\nbuses:"))
    plan, ctx = homed(cfg, ["yaw"])
    with ctx as s:
        with pytest.raises(SafetyError, match=r"yaw: the switch on input 1 never triggered: stopped at the "
                                              r"search bound \(820 counts up at 1000 counts/s\)") as refused:
            home.run_home(s, plan)
        # a newcomer whose home was cut short past the switch read "where the joint stands" and did not
        # know which way: the hint says the search goes up only, and the jog that brings it back
        assert "goes up only" in refused.value.hint and "jog yaw --by -820counts --uncalibrated" in refused.value.hint
        with s.sim.lock:
            d = s.sim.drives["yaw_drive"]
            assert not d.motor_on and d.ram.get("UI[3]", 0) == 0  # stopped, switched off, not marked
        assert abs(physical(s, "yaw_drive") - 420) <= 1


def test_homing_is_refused_while_the_drive_is_in_fault(tmp_path):
    cfg = variant(tmp_path, ("buses:", "  drives: {yaw_drive: {limit_trip_at: 0.0}}\nbuses:"))
    plan, ctx = homed(cfg, ["yaw"])
    with ctx as s:
        with pytest.raises(SafetyError, match="yaw_drive"):
            home.run_home(s, plan)
        with s.sim.lock:
            d = s.sim.drives["yaw_drive"]
            assert not [f for _, i, f in d.received if 0x300 < i < 0x380 and bytes(f)[:2] in (b"BG", b"PR")]


def test_an_encoder_joint_is_refused_in_fault_before_the_encoder_is_read_or_px_set(tmp_path):
    cfg = variant(tmp_path, ("buses:", "  drives: {elbow_drive: {limit_trip_at: 0.0}}\nbuses:"))
    plan, ctx = homed(cfg, ["elbow"])
    with ctx as s:
        with pytest.raises(SafetyError, match=r"elbow_drive.*refusing to home: the drive is in fault"):
            home.run_home(s, plan)
        with s.sim.lock:
            frames = [bytes(f) for _, i, f in s.sim.drives["elbow_drive"].received if 0x300 < i < 0x380]
            encoder_frames = [i for _, i, _ in s.sim.extras["elbow_encoder"][1].received]
        assert not [f for f in frames if len(f) == 8 and not f[3] & 0x40 and f[:2] == b"HM"]  # no HM[] write
        assert not [i for i in encoder_frames if 0x600 < i < 0x680]  # the encoder was not even asked


def test_jog_refuses_an_uncalibrated_position_move_and_accepts_it_after_home():
    from sherpa_cli.motion.request import parse_request
    from sherpa_cli.motion.settings import MotionSettings
    from sherpa_cli.ops.jog import run_jog

    cfg = load_config(ARM)
    target = resolve_axis(cfg, "yaw")
    req = parse_request(target, mode="position", to=100 * 2 * 3.141592653589793 / 3600)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        with pytest.raises(SafetyError, match="not homed since power-up"):
            run_jog(s, target, req, settings=MotionSettings.from_config(cfg))
        home.run_home(s, home.plan_home(cfg, ["yaw"]))
        result = run_jog(s, target, req, settings=MotionSettings.from_config(cfg))
        assert result.end_counts == 100 and abs(physical(s, "yaw_drive") - 100) <= 1


def test_a_pair_jog_is_refused_uncalibrated_and_accepted_after_homing_the_pair():
    from sherpa_cli.motion.request import parse_request
    from sherpa_cli.ops import joint_jog

    cfg = load_config(ARM)
    axis = resolve_axis(cfg, "pitch")
    req = parse_request(axis, mode="position", to="-400counts")
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        with pytest.raises(SafetyError, match="not homed since power-up"):
            joint_jog.run(s, axis, req)
        home.run_home(s, home.plan_home(cfg, ["diff"]))
        r = joint_jog.run(s, axis, req)
        assert r.ok and abs(r.end_counts + 400) <= 1
        a, b = physical(s, "pair_a"), physical(s, "pair_b")
        assert abs((a + b) + 400) <= 2  # Σ where it was sent, in the real joint (not only in PX)


# -- the wiring check -------------------------------------------------------------------------------

def wiring(cfg, name):
    prompts = []
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        def ask(p):
            prompts.append((p.action, p.input))
            for d in p.drives:
                s.sim.press_switch(d, p.input, p.action == "press")
        report = home.check_wiring(s, name, ask)
        with s.sim.lock:
            writes = [bytes(f) for _, i, f in s.sim.drives[cfg.joints[name].drive or "pair_a"].received
                      if 0x300 < i < 0x380 and len(f) == 8]
    return report, prompts, writes


def test_wiring_check_detects_a_swapped_input():
    report, prompts, writes = wiring(load_config(WIRING), "stiff")
    assert prompts == [("press", 3), ("release", 3), ("press", 4), ("release", 4)]
    assert [(f.input, f.verdict, f.seen_input) for f in report.findings] == [(3, "wrong input", 4),
                                                                           (4, "wrong input", 3)]
    assert not report.ok and writes == []  # the check writes nothing
    assert report.live == {"stiff_drive": {3: False, 4: False}}


def test_wiring_check_detects_an_inverted_switch():
    report, _, _ = wiring(load_config(WIRING), "yaw")
    assert [(f.input, f.verdict) for f in report.findings] == [(1, "inverted")]
    assert report.live == {"yaw_drive": {1: True}}  # active while nobody presses it
    assert "inverted" in report.findings[0].line()


def test_wiring_check_passes_a_healthy_pair_joint_on_both_drives():
    report, _, _ = wiring(load_config(ARM), "roll")
    assert report.ok and [(f.drive, f.input) for f in report.findings] == [
        ("pair_a", 3), ("pair_b", 3), ("pair_a", 4), ("pair_b", 4)]


def test_wiring_check_reports_a_switch_that_changes_nothing():
    cfg = load_config(ARM)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        report = home.check_wiring(s, "stiff", lambda p: None)  # nobody presses: a broken wire looks the same
    assert [(f.input, f.verdict) for f in report.findings] == [(3, "no change"), (4, "no change")]
    assert "no input changed" in report.findings[0].line()


def test_wiring_check_of_a_joint_standing_on_its_switch_says_not_checked_not_broken_wire():
    """After `home` the joint stands on its home switch: the input is active before the press and
    stays so. That is no broken wire (the newcomer's run said FAULT); the check cannot tell, and says so."""
    cfg = load_config(ARM)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        drive = cfg.joints["stiff"].drive
        s.sim.press_switch(drive, 3, True)  # the joint stands on input 3
        report = home.check_wiring(s, "stiff", lambda p: None)
    assert [(f.input, f.verdict) for f in report.findings] == [(3, "already active"), (4, "no change")]
    assert report.findings[0].line().startswith("NOT CHECKED: ") and "jog it off the switch" in report.findings[0].line()
    assert not report.ok


# -- a second device type: the CANopen absolute encoder (CiA 406) -------------------------------------

def test_device_registry_matches_the_config_types():
    from sherpa_cli.config.model import DEVICE_TYPES
    from sherpa_cli.devices import REGISTRY, CanOpenEncoder, device_class

    assert tuple(REGISTRY) == DEVICE_TYPES and device_class("canopen-encoder") is CanOpenEncoder
    assert CanOpenEncoder.position_from_tpdo(bytes.fromhex("60fdffff")) == -672
    with pytest.raises(UsageError, match="unknown device type 'resolver'"):
        device_class("resolver")


def test_encoder_joint_is_homed_from_0x6004_by_sdo_with_no_motion_command():
    cfg = load_config(ARM)
    plan = home.plan_home(cfg, ["elbow"])
    assert plan.units[0].devices == ("elbow_encoder",) and plan.units[0].moves == ()
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        (u,) = home.run_home(s, plan).units
        # the encoder reads the joint's real position (-444) minus the configured offset (100)
        assert u.encoder == {"elbow_encoder": -544} and px(s, "elbow_drive") == -444
        with s.sim.lock:
            frames = [bytes(f) for _, i, f in s.sim.drives["elbow_drive"].received if 0x300 < i < 0x380]
        assert not [f for f in frames if len(f) == 8 and not f[3] & 0x40 and f[:2] in MOTION_LETTERS]


def test_encoder_config_errors(tmp_path):
    from sherpa_cli.errors import ConfigError

    with pytest.raises(ConfigError, match="unknown type 'resolver'"):
        variant(tmp_path, ("{type: canopen-encoder, bus: can0, node: 45}", "{type: resolver, bus: can0, node: 45}"))
    with pytest.raises(ConfigError, match="node can0:40 is already drive elbow_drive"):
        variant(tmp_path, ("{type: canopen-encoder, bus: can0, node: 45}", "{type: canopen-encoder, bus: can0, node: 40}"))
    with pytest.raises(ConfigError, match="'can0:46' names no configured device"):
        variant(tmp_path, ('source: "can0:45"', 'source: "can0:46"'))


def test_scan_and_identify_show_the_encoder(cli):
    scan = cli("--config", str(ARM), "--sim", "scan")
    assert scan.exit_code == 0, scan.transcript()
    row = next(line for line in scan.stdout.splitlines() if line.strip().startswith("45 "))
    assert "0x00010196" in row and "elbow_encoder" in row and "elbow" in row and "expected" in row
    ident = cli("--config", str(ARM), "--sim", "--json", "identify", "elbow_encoder")
    assert ident.exit_code == 0, ident.transcript()
    import json

    (dev,) = json.loads(ident.stdout)["devices"]
    assert dev["type"] == "canopen-encoder" and dev["position"] == -544 and dev["joint_position"] == -444
    assert dev["device_type"] == 0x00010196


def test_every_kind_homed_twice_leaves_an_empty_journal_and_the_encoder_joint_then_jogs():
    """A finished home puts back all it journaled: an encoder joint's immediate home event left its
    HM[1] entry behind, and every later command refused to move the joint ("a home that did not
    finish (killed?) left temporary changes")."""
    from sherpa_cli.bus import journal
    from sherpa_cli.motion.request import parse_request
    from sherpa_cli.motion.settings import MotionSettings
    from sherpa_cli.ops.jog import run_jog

    cfg = load_config(ARM)
    names = ["yaw", "stiff", "twist", "elbow", "diff"]
    plan = home.plan_home(cfg, names)
    assert {u.kind for u in plan.units} == set(home.KINDS)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        for _ in range(2):
            home.run_home(s, plan)
            assert not journal.journal_dir().exists() or sorted(journal.journal_dir().iterdir()) == []
        target = resolve_axis(cfg, "twist")
        start = px(s, "twist_drive")
        req = parse_request(target, mode="position", to=(start + 50) * 2 * 3.141592653589793 / target.cpr)
        result = run_jog(s, target, req, settings=MotionSettings.from_config(cfg))
        assert result.end_counts == start + 50
