"""Appendix C derivation, software limits, pair explanation and the current/consistency checks.

Configs are built directly from the model dataclasses (no YAML loader involved).
"""

from __future__ import annotations

import dataclasses
import re

import pytest
from hypothesis import given
from hypothesis import strategies as st

from sherpa_cli.config.catalog import builtin_catalog
from sherpa_cli.config.model import (
    ArmConfig,
    BusConfig,
    CurrentLimits,
    DriveConfig,
    JointConfig,
    JointRole,
    PairConfig,
    SwitchConfig,
    SwitchKind,
)
from sherpa_cli.errors import ConfigError, Location, UsageError
from sherpa_cli.joints.currents import Finding, check_currents, validate_params
from sherpa_cli.joints.limits import (
    PARAM_ORDER,
    DriveParams,
    derive_all,
    derive_checked,
    derive_drive_params,
    explain_pair,
    software_limits,
)

# --------------------------------------------------------------------------- builders

def loc(path: str) -> Location:
    return Location(file="arm.yaml", line=1, path=path)


def stop(inp: int, pos: int, side: str | None = None, drives: tuple[str, ...] = ()) -> SwitchConfig:
    return SwitchConfig(input=inp, kind=SwitchKind.STOP, position=pos, side=side, drives=drives)


def home(inp: int, pos: int) -> SwitchConfig:
    return SwitchConfig(input=inp, kind=SwitchKind.HOME, position=pos)


def joint(name: str, drive: str | None = "d1", *, role: JointRole = JointRole.PLAIN, pair: str | None = None,
          cpr: int = 600, full: tuple[int, int] = (-220, 220), margin: int = 30, overshoot: int = 20,
          **kw) -> JointConfig:
    return JointConfig(name=name, role=role, drive=drive, pair=pair, cpr=cpr, pos_min=full[0],
                       pos_max=full[1], margin=margin, overshoot=overshoot, where=loc(f"joints.{name}"), **kw)


def drive(name: str, node: int, model: str | None = None, motor: str | None = None) -> DriveConfig:
    return DriveConfig(name=name, bus="can0", node=node, model=model, motor=motor, where=loc(f"drives.{name}"))


def arm(joints=(), pairs=(), drives=()) -> ArmConfig:
    return ArmConfig(name="test-arm", buses={"can0": BusConfig("can0")},
                     drives={d.name: d for d in drives}, joints={j.name: j for j in joints},
                     pairs={p.name: p for p in pairs}, catalog=builtin_catalog())


def example1(**kw) -> ArmConfig:
    j = joint("elbow", switches=(stop(3, -225, "low"), stop(4, 225, "high")), **kw)
    return arm([j], drives=[drive("d1", 10)])


def example2() -> ArmConfig:
    return arm([joint("elbow", switches=(home(1, 20),))], drives=[drive("d1", 10)])


def example3(sigma_kw=None, delta_kw=None, pair_kw=None, drives=None) -> ArmConfig:
    s = joint("pitch", None, role=JointRole.SIGMA, pair="wrist", full=(-220, 220), margin=30, overshoot=20,
              switches=(stop(1, -225, "low"), stop(2, 225, "high")), cal_pos=-220, **(sigma_kw or {}))
    d = joint("roll", None, role=JointRole.DELTA, pair="wrist", full=(-160, 160), margin=10, overshoot=10,
              switches=(stop(3, -165, "low"), stop(4, 165, "high")), **(delta_kw or {}))
    p = PairConfig(name="wrist", drive_a="wa", drive_b="wb", sigma="pitch", delta="roll",
                   where=loc("pairs.wrist"), **(pair_kw or {}))
    return arm([s, d], [p], drives or [drive("wa", 20), drive("wb", 30)])


# --------------------------------------------------------------------------- seed examples

def test_seed_example_1():
    dp = derive_drive_params(example1(), "d1")
    # IL[3] = IL[4] = 21 as the seed says; every other input "no function" (il_codes.unused)
    assert dp == DriveParams("d1", "can0", 10, {"LL[3]": -240, "HL[3]": 240, "VL[3]": -220, "VH[3]": 220,
                                                "IL[1]": 4, "IL[2]": 4, "IL[3]": 21, "IL[4]": 21, "IL[5]": 4,
                                                "IL[6]": 4})
    assert list(dp.params) == ["LL[3]", "HL[3]", "VL[3]", "VH[3]", *(f"IL[{n}]" for n in range(1, 7))]
    assert software_limits(example1(), "elbow") == {"cpr": 600, "pos_min": -220, "pos_max": 220,
                                                    "pos_margin": 30, "cal_sw_L": 3, "cal_sw_H": 4}


def test_seed_example_2():
    cfg = example2()
    assert dict(derive_drive_params(cfg, "d1").params) == {"LL[3]": -240, "HL[3]": 240, "VL[3]": -220,
                                                            "VH[3]": 220, "IL[1]": 5, "IL[2]": 4, "IL[3]": 4,
                                                            "IL[4]": 4, "IL[5]": 4, "IL[6]": 4}
    sw = software_limits(cfg, "elbow")
    assert sw["cal_sw_L"] == 1 and sw["cal_pos"] == 20 and "cal_sw_H" not in sw


def test_seed_example_3():
    cfg = example3()
    for name in ("wa", "wb"):
        assert dict(derive_drive_params(cfg, name).params) == {
            "LL[3]": -205, "HL[3]": 205, "VL[3]": -190, "VH[3]": 190,
            "IL[1]": 21, "IL[2]": 21, "IL[3]": 21, "IL[4]": 21, "IL[5]": 4, "IL[6]": 4}
    assert software_limits(cfg, "wrist") == {
        "cpr": 600, "pos_min": -220, "pos_max": 220, "pos_margin": 30,
        "pos_min_dd": -160, "pos_max_dd": 160, "pos_margin_dd": 10, "cal_pos": -220,
        "cal_sw_L": 1, "cal_sw_H": 2, "cal_sw_dd_L": 3, "cal_sw_dd_H": 4}
    assert software_limits(cfg, "roll") == software_limits(cfg, "wb") == software_limits(cfg, "wrist")


def test_il_codes_come_from_the_config():
    cfg = dataclasses.replace(example1(), il_codes=dataclasses.replace(example1().il_codes, stop=22))
    assert derive_drive_params(cfg, "d1").params["IL[3]"] == 22


# --------------------------------------------------------------------------- plain joints

def test_plain_joint_full_set_in_order():
    cur = CurrentLimits(continuous=3.0, peak=6.5, peak_time=2.0, where=loc("joints.elbow.current"))
    cfg = example1(vel_limit=1000, vel_trip=1200, accel=5000, decel=6000, current=cur)
    dp = derive_drive_params(cfg, "d1")
    assert list(dp.params) == [*PARAM_ORDER, *(f"IL[{n}]" for n in range(1, 7))]
    p = dp.params
    assert (p["LL[2]"], p["HL[2]"], p["VL[2]"], p["VH[2]"]) == (-1200, 1200, -1000, 1000)
    assert (p["AC"], p["DC"]) == (5000, 6000)
    assert (p["CL[1]"], p["PL[1]"], p["PL[2]"]) == (3.0, 6.5, 2)
    assert isinstance(p["PL[2]"], int) and isinstance(p["CL[1]"], float)
    assert validate_params(dp) == []


def test_params_are_read_only():
    dp = derive_drive_params(example1(), "d1")
    with pytest.raises(TypeError):
        dp.params["LL[3]"] = 0  # type: ignore[index]


def test_fractional_peak_time_names_the_config_location():
    cur = CurrentLimits(continuous=3.0, peak=6.0, peak_time=1.5, where=loc("joints.elbow.current.peak_time"))
    with pytest.raises(ConfigError, match="peak_time") as info:
        derive_drive_params(example1(current=cur), "d1")
    assert "arm.yaml:1: joints.elbow.current.peak_time" in str(info.value)


def test_switch_wired_to_other_drives_only():
    s = stop(2, -225, drives=("d2",))
    cfg = arm([joint("elbow", switches=(s,))], drives=[drive("d1", 10), drive("d2", 11)])
    assert derive_drive_params(cfg, "d1").params["IL[2]"] == 4  # the switch is not d1's: no function
    assert derive_drive_params(cfg, "d2").params == {"IL[2]": 21}  # d2 moves no joint: only its switch


def test_one_input_with_two_functions_is_a_config_error():
    cfg = arm([joint("elbow", switches=(stop(1, -225), home(1, 0)))], drives=[drive("d1", 10)])
    with pytest.raises(ConfigError, match="input 1"):
        derive_drive_params(cfg, "d1")


def test_switch_input_beyond_the_drive_model_is_a_config_error():
    cfg = arm([joint("elbow", switches=(stop(7, -225),))], drives=[drive("d1", 10, model="whistle-5/60")])
    with pytest.raises(ConfigError, match=re.escape("1..6")):
        derive_drive_params(cfg, "d1")


def test_negative_velocity_is_a_config_error():
    with pytest.raises(ConfigError, match="vel_limit"):
        derive_drive_params(example1(vel_limit=-5), "d1")


@given(lo=st.integers(-10**6, 10**6), width=st.integers(1, 10**6), over=st.integers(0, 1000),
       vel=st.integers(1, 10**6), extra=st.integers(1, 1000))
def test_plain_derivation_is_always_consistent(lo, width, over, vel, extra):
    cfg = arm([joint("j", full=(lo, lo + width), overshoot=over, margin=0, vel_limit=vel,
                     vel_trip=vel + extra, accel=vel, decel=vel)], drives=[drive("d1", 1)])
    dp = derive_drive_params(cfg, "d1")
    assert (dp.params["VL[3]"], dp.params["VH[3]"]) == (lo, lo + width)
    assert (dp.params["LL[3]"], dp.params["HL[3]"]) == (lo - over, lo + width + over)
    assert [f for f in validate_params(dp, allow_disabled=True) if f.level == "error"] == []


# --------------------------------------------------------------------------- pairs

def test_asymmetric_pair_uses_the_box_per_motor():
    cfg = example3(sigma_kw={}, delta_kw={})
    cfg = dataclasses.replace(cfg, joints={
        "pitch": dataclasses.replace(cfg.joints["pitch"], pos_min=-101, pos_max=200, overshoot=0),
        "roll": dataclasses.replace(cfg.joints["roll"], pos_min=-50, pos_max=31, overshoot=0)})
    a, b = derive_drive_params(cfg, "wa").params, derive_drive_params(cfg, "wb").params
    assert (a["VL[3]"], a["VH[3]"]) == (-75, 115)
    assert (b["VL[3]"], b["VH[3]"]) == (-66, 125)
    assert (a["LL[3]"], a["HL[3]"]) == (-75, 115)


def test_pair_speed_accel_and_current_rule():
    cur = CurrentLimits(continuous=3.0, peak=6.0, peak_time=1, where=loc("pairs.wrist.current"))
    cfg = example3(sigma_kw=dict(vel_limit=1001, vel_trip=1200, accel=301, decel=400),
                   delta_kw=dict(vel_limit=500, vel_trip=700, accel=200, decel=100),
                   pair_kw=dict(current=cur))
    for name in ("wa", "wb"):
        p = derive_drive_params(cfg, name).params
        assert (p["VL[2]"], p["VH[2]"]) == (-750, 750)  # floor(1501/2)
        assert (p["LL[2]"], p["HL[2]"]) == (-950, 950)
        assert (p["AC"], p["DC"]) == (250, 250)
        assert (p["CL[1]"], p["PL[1]"], p["PL[2]"]) == (3.0, 6.0, 1)
        assert validate_params(derive_drive_params(cfg, name)) == []


def test_half_configured_pair_speed_is_left_out_with_a_warning():
    cfg = example3(sigma_kw=dict(vel_limit=1000))
    derived, warnings = derive_checked(cfg, ["wa", "wb"])
    assert all("VL[2]" not in d.params for d in derived)
    assert any("vel_limit" in w and "roll" in w for w in warnings)


def test_pair_switch_wired_to_one_drive():
    cfg = example3()
    cfg = dataclasses.replace(cfg, joints={**cfg.joints, "roll": dataclasses.replace(
        cfg.joints["roll"], switches=(stop(3, -165, "low", drives=("wb",)), stop(4, 165, "high", drives=("wb",))))})
    assert derive_drive_params(cfg, "wa").params["IL[3]"] == 4
    assert derive_drive_params(cfg, "wb").params["IL[4]"] == 21


def test_explain_pair():
    ex = explain_pair(example3(sigma_kw=dict(vel_limit=100), delta_kw=dict(vel_limit=51)), "wrist")
    assert (ex.sigma, ex.delta, ex.drive_a, ex.drive_b) == ("pitch", "roll", "wa", "wb")
    assert ex.sigma_full == (-220, 220) and ex.delta_overshoot == (-170, 170)
    assert ex.motor_a_full == ex.motor_b_full == (-190, 190)
    assert ex.motor_a_overshoot == ex.motor_b_overshoot == (-205, 205)
    assert ex.motor_speed_limit == 75 and ex.motor_speed_trip is None
    assert "floor((220 + 160)/2)" in ex.rule and "necessary, not sufficient" in ex.rule
    assert ex.as_dict()["motor_a_full"] == [-190, 190]
    assert explain_pair(example3(), example3().pairs["wrist"]).pair == "wrist"
    with pytest.raises(UsageError) as info:
        explain_pair(example3(), "wirst")
    assert "wrist" in (info.value.hint or "")


@given(s_lo=st.integers(-500, 500), s_w=st.integers(1, 500), d_lo=st.integers(-500, 500),
       d_w=st.integers(1, 500), s_over=st.integers(0, 50), d_over=st.integers(0, 50))
def test_pair_derivation_is_consistent_and_covers_the_joint_ranges(s_lo, s_w, d_lo, d_w, s_over, d_over):
    cfg = example3()
    cfg = dataclasses.replace(cfg, joints={
        "pitch": dataclasses.replace(cfg.joints["pitch"], pos_min=s_lo, pos_max=s_lo + s_w, overshoot=s_over,
                                     switches=()),
        "roll": dataclasses.replace(cfg.joints["roll"], pos_min=d_lo, pos_max=d_lo + d_w, overshoot=d_over,
                                    switches=())})
    a, b = derive_drive_params(cfg, "wa").params, derive_drive_params(cfg, "wb").params
    # Corners of the Σ/Δ full range that are reachable must be inside both motors' VL/VH.
    for s in (s_lo, s_lo + 1, s_lo + s_w - 1, s_lo + s_w):
        for d in (d_lo, d_lo + 1, d_lo + d_w - 1, d_lo + d_w):
            if (s - d) % 2 == 0:
                m_a, m_b = (s + d) // 2, (s - d) // 2
                assert a["VL[3]"] <= m_a <= a["VH[3]"] and b["VL[3]"] <= m_b <= b["VH[3]"]
    for p in (a, b):
        assert p["LL[3]"] <= p["VL[3]"] and p["VH[3]"] <= p["HL[3]"]


# --------------------------------------------------------------------------- names

def test_resolve_names():
    cfg = arm([joint("elbow", "d1"), joint("pitch", None, role=JointRole.SIGMA, pair="wrist"),
               joint("roll", None, role=JointRole.DELTA, pair="wrist", full=(-160, 160))],
              [PairConfig("wrist", "wa", "wb", "pitch", "roll")],
              [drive("d1", 10), drive("wa", 20), drive("wb", 30)])
    # joint and pair names are resolved by sherpa_cli.bus.targets (tests/test_targets.py)
    assert [d.drive for d in derive_all(cfg, ["wb", "wa", "wb"])] == ["wb", "wa"]
    assert [d.drive for d in derive_all(cfg)] == ["d1", "wa", "wb"]
    with pytest.raises(UsageError) as info:
        derive_all(cfg, ["d2"])
    assert "d2" in info.value.message and "d1" in (info.value.hint or "")
    with pytest.raises(UsageError, match="unknown drive 'wrist'"):
        derive_all(cfg, ["wrist"])
    with pytest.raises(UsageError):
        derive_drive_params(cfg, "nope")
    with pytest.raises(UsageError):
        software_limits(cfg, "rol")


def test_drive_without_joint_gets_nothing_and_a_warning():
    cfg = arm([joint("elbow", "d1")], drives=[drive("d1", 10), drive("spare", 11)])
    derived, warnings = derive_checked(cfg)
    assert derived[1].params == {}
    assert any("spare" in w for w in warnings)


# --------------------------------------------------------------------------- currents

def _cur(cont, peak, t=1.0):
    return CurrentLimits(continuous=cont, peak=peak, peak_time=t, where=loc("joints.elbow.current"))


def _current_cfg(cont, peak, model="whistle-10/60", motor="kollmorgen-rbe-02110-a", t=1.0):
    return arm([joint("elbow", current=_cur(cont, peak, t))], drives=[drive("d1", 10, model, motor)])


def test_currents_within_ratings_give_no_findings():
    # motor 6.34 A cont / 25.3 A peak -> 18.975 A allowed; drive 10 A / 20 A
    assert check_currents(_current_cfg(6.34, 18.975)) == []


@pytest.mark.parametrize("cont, peak, needle", [
    (6.5, 10.0, "motor's continuous rating 6.34 A"),
    (5.0, 19.0, "75% of the motor's peak 25.3 A"),
    (5.0, 4.0, "below the continuous"),
])
def test_current_errors(cont, peak, needle):
    findings = check_currents(_current_cfg(cont, peak))
    errors = [f for f in findings if f.level == "error"]
    assert len(errors) == 1 and needle in errors[0].message
    assert "joint elbow" in errors[0].message and "drive d1" in errors[0].message
    assert errors[0].location == loc("joints.elbow.current") and errors[0].drive == "d1"


def test_drive_rating_errors():
    findings = check_currents(_current_cfg(3.0, 6.0, model="whistle-2.5/60"))
    msgs = [f.message for f in findings if f.level == "error"]
    assert any("drive's continuous rating 2.5 A" in m for m in msgs)
    assert any("drive's peak rating 5 A" in m for m in msgs)


def test_unknown_model_and_motor_are_warnings():
    findings = check_currents(_current_cfg(3.0, 6.0, model=None, motor=None))
    assert [f.level for f in findings] == ["warning", "warning"]
    assert "skipped" in findings[0].message and "skipped" in findings[1].message


def test_pair_currents_checked_on_both_drives():
    cfg = example3(pair_kw=dict(current=CurrentLimits(9.0, 12.0, 1, where=loc("pairs.wrist.current"))),
                   drives=[drive("wa", 20, "whistle-10/60", "tq-robodrive-50x14"),
                           drive("wb", 30, "whistle-10/60", "tq-robodrive-50x14")])
    errors = [f for f in check_currents(cfg) if f.level == "error"]
    assert {f.drive for f in errors} == {"wa", "wb"}
    assert all("pair wrist" in f.message for f in errors)
    with pytest.raises(ConfigError, match="pair wrist"):
        derive_checked(cfg)


def test_derive_checked_refuses_current_errors_and_keeps_warnings():
    with pytest.raises(ConfigError, match="exceeds"):
        derive_checked(_current_cfg(6.5, 10.0))
    derived, warnings = derive_checked(_current_cfg(3.0, 6.0, model=None))
    assert derived[0].params["CL[1]"] == 3.0 and any("skipped" in w for w in warnings)


# --------------------------------------------------------------------------- validate_params

def test_zero_disables_protection_is_an_error_unless_allowed():
    p = {"LL[3]": 0, "HL[3]": 0, "VL[3]": -10, "VH[3]": 10, "LL[2]": 0, "HL[2]": 100}
    errors = [f.message for f in validate_params(p, drive="d1") if f.level == "error"]
    assert any("position trip" in m for m in errors)
    assert any("LL[2] = 0" in m for m in errors)
    assert not any("VL[3]" in m for m in errors)  # order checks skip a disabled trip
    assert all(f.level == "warning" for f in validate_params(p, allow_disabled=True))
    mixed = validate_params(p, allow_disabled={"speed"})
    assert [f.level for f in mixed if "position" in f.message] == ["error"]


@pytest.mark.parametrize("params, needle", [
    ({"VL[3]": 10, "VH[3]": 10}, "VL[3] = 10 must be below"),
    ({"VL[2]": 5, "VH[2]": -5}, "VL[2] = 5 must be below"),
    ({"LL[3]": -5, "HL[3]": 50, "VL[3]": -10, "VH[3]": 10}, "LL[3] = -5"),
    ({"LL[3]": -50, "HL[3]": 5, "VL[3]": -10, "VH[3]": 10}, "VH[3] = 10"),
    ({"LL[2]": -100, "HL[2]": 100, "VL[2]": -100, "VH[2]": 90}, "LL[2] = -100"),
    ({"LL[2]": -200, "HL[2]": 100, "VL[2]": -100, "VH[2]": 100}, "HL[2] = 100"),
    ({"AC": 0}, "AC = 0"),
    ({"CL[1]": 5.0, "PL[1]": 4.0}, "PL[1]"),
])
def test_inconsistent_sets_are_errors(params, needle):
    findings = validate_params(params, drive="d1", where=loc("joints.elbow"))
    assert len(findings) == 1
    f = findings[0]
    assert isinstance(f, Finding) and f.level == "error" and needle in f.message
    assert f.location == loc("joints.elbow") and f.message.startswith("drive d1:")


def test_derive_checked_raises_on_an_inconsistent_set():
    # trip equal to the limit: not strictly above it
    with pytest.raises(ConfigError, match="strictly"):
        derive_checked(example1(vel_limit=100, vel_trip=100))
