"""Every band of docs/section9/bands.yaml can fail: for each, a variant of the seed's experiment that
should not reproduce the seed's sentence -- the wrong switch sequence, a stiff supply, a noiseless or
frictionless simulator, a matched pair, a drive that garbles its target, no common start -- gives a number outside it.

The variants are short runs (a few steps of a recipe on the simulator's stepped time, at 200 Hz), not
the whole seed recipe (tests/test_section9.py runs that and shows every band holds there). A variant's
runs are made once per test process and shared by the bands they break.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path

import pytest
from conftest import ROOT

from sherpa_cli.log.section9 import _held, _move, falls_at, load_bands, seed_switch_ms, slowing_at
from sherpa_cli.log.step_compare import figures

BANDS = {b.key: b for b in load_bands(ROOT / "docs" / "section9" / "bands.yaml")}
SEED = ROOT / "configs" / "sim-profiles" / "seed-figures.yaml"
PROFILE = ["cmd shoulder_1a SP=1450 AC=12000 DC=12000 --apply", "cmd shoulder_1a_20a SP=1450 AC=12000 DC=12000 --apply"]
SHORT = "--rate 200 --uncalibrated"


def _drive_line(text: str, drive: str, **changes: object) -> str:
    """The seed profile with ``changes`` to one drive's `sim:` entry (a key there replaced, else added)."""
    start = text.index(f"    {drive}: {{supply_current_limit")
    end = text.index("}", start)
    entry = text[start:end]
    for key, value in changes.items():
        entry, n = re.subn(rf"\b{key}: [^,]+", f"{key}: {value}", entry)
        if not n:
            entry += f", {key}: {value}"
    return text[:start] + entry + text[end:]


# variant name -> (the profile's changes per drive, the recipe's steps ({out}: the variant's folder))
VARIANTS: dict[str, tuple[dict[str, dict[str, object]], list[str]]] = {
    # the switch as the tool does it without --from-mode / --mode-first: the motor off, MO=1 alone
    "no-seed-switch": ({}, [
        f"log step shoulder_yaw --position 0.2 --for 1 {SHORT} -o {{out}}/position --apply",
        "log step shoulder_yaw --velocity 0.1 --for 1 --rate 200 -o {out}/velocity --apply"]),
    # the 1 A supply does not sag: its speed levels off
    "stiff-supply": ({"shoulder_1a": {"bus_capacitance": 0}}, [
        *PROFILE,
        f"log step shoulder_yaw --position 1 --mode-first --for 1.2 {SHORT} -o {{out}}/weak --apply",
        f"log step shoulder_yaw_20a --position 1 --mode-first --for 1.2 {SHORT} -o {{out}}/strong --apply"]),
    # the "20 A" drive on the 1 A supply too: no difference between the supplies
    "weak-twice": ({"shoulder_1a_20a": {"supply_current_limit": 1.0}}, [
        *PROFILE,
        f"log step shoulder_yaw --position 1 --mode-first --for 1.2 {SHORT} -o {{out}}/weak --apply",
        f"log step shoulder_yaw_20a --position 1 --mode-first --for 1.2 {SHORT} -o {{out}}/strong --apply"]),
    # no encoder quantisation, no cogging, no Coulomb friction: a clean, faster torque step
    "noiseless-frictionless": ({"shoulder_1a": {"velocity_window": 0, "cogging_torque": 0, "coulomb": 0}}, [
        "log step shoulder_yaw --torque 1 --for 1.5 --rate 200 -o {out}/torque --apply"]),
    # motors that run their profiles 20 % fast, read through a 10 ms speed window
    "fast-coarse": ({name: {"speed_gain": 1.2, "velocity_window": 0.01} for name in ("shoulder_1a", "shoulder_1a_20a")}, [
        "log step shoulder_yaw --velocity 0.1 --for 1.5 --rate 200 -o {out}/slow --apply",
        "log step shoulder_yaw_20a --velocity -0.5 --for 1.5 --rate 200 -o {out}/fast --apply"]),
    # a pair whose motors are alike: nothing couples
    "matched-pair": ({"shoulder_2a": {"lag": 0.003, "start_skew": 0, "gravity": 0, "cogging_torque": 0},
                      "shoulder_2b": {"speed_gain": 1.0, "gravity": 0, "cogging_torque": 0}}, [
        "diffdrive move shoulder_diff --sigma 0.3 --naive --report {out}/sigma.json --apply",
        "diffdrive move shoulder_diff --delta -0.3 --naive --report {out}/delta.json --apply"]),
    # motor a stores every target 10 counts off (a garbled PA): the move ends, the held joint 10 counts away
    "garbled-target": ({"shoulder_2a": {"target_skew": 10}}, [
        "diffdrive move shoulder_diff --sigma 0.3 --naive --report {out}/sigma.json --apply",
        "diffdrive move shoulder_diff --delta -0.3 --naive --report {out}/delta.json --apply"]),
    # the seed's naive start where the tool's common start should be: there and back, both naive
    "naive-twice": ({}, [
        "diffdrive move shoulder_diff --sigma 0.3 --naive --report {out}/sigma-there.json --apply",
        "diffdrive move shoulder_diff --sigma 0 --naive --report {out}/sigma-back.json --apply",
        "diffdrive move shoulder_diff --delta -0.3 --naive --report {out}/delta-there.json --apply",
        "diffdrive move shoulder_diff --delta 0 --naive --report {out}/delta-back.json --apply"]),
}


def _speed(path: Path) -> float | None:
    return figures(path)[0].steady_speed


def _ripple(path: Path) -> float | None:
    return figures(path)[0].steady_ripple


def _sd(path: Path) -> float | None:
    f = figures(path)[0]
    return None if f.steady_ripple is None or f.steady_speed is None else f.steady_ripple * abs(f.steady_speed)


def _drop(out: Path) -> float | None:
    slow = slowing_at(figures(out / "strong"))
    drop = falls_at(figures(out / "weak"), slow)
    return None if drop is None else 1000 * drop


def _slowing(out: Path) -> float | None:
    slow = slowing_at(figures(out / "strong"))
    return None if slow is None else 1000 * slow


def _reduction(out: Path, side: str) -> float:
    there, back = _held(_move(out / f"{side}-there.json"))[0], _held(_move(out / f"{side}-back.json"))[0]
    return back / there


# band -> (the variant that must fail it, the band's number from the variant's runs, as log section9 reads it)
FAILS: dict[str, tuple[str, Callable[[Path], float | None]]] = {
    "fig9_1.switch_ms": ("no-seed-switch", lambda o: seed_switch_ms(figures(o / "position")[0])),
    "fig9_2.switch_ms": ("no-seed-switch", lambda o: 1000 * figures(o / "position")[0].switch_s),
    "fig9_3.switch_ms": ("no-seed-switch", lambda o: seed_switch_ms(figures(o / "velocity")[0])),
    "fig9_3.speed_rad_s": ("fast-coarse", lambda o: _speed(o / "slow")),
    "fig9_3.ripple": ("fast-coarse", lambda o: _ripple(o / "slow")),
    "fig9_5.drop_1a_ms": ("stiff-supply", _drop),
    "fig9_5.slowing_20a_ms": ("weak-twice", _slowing),
    "fig9_4.peak_ratio": ("weak-twice", lambda o: abs(figures(o / "weak")[0].peak_speed)
                          / abs(figures(o / "strong")[0].peak_speed)),
    "fig9_6.speed_rad_s": ("fast-coarse", lambda o: _speed(o / "fast")),
    "fig9_6.ripple": ("fast-coarse", lambda o: _ripple(o / "fast")),
    "fig9_8.speed_rad_s": ("noiseless-frictionless", lambda o: _speed(o / "torque")),
    "fig9_8.speed_sd_rad_s": ("noiseless-frictionless", lambda o: _sd(o / "torque")),
    "fig9_10.delta_excursion_rad": ("matched-pair", lambda o: _held(_move(o / "sigma.json"))[0]),
    "fig9_10.delta_returned_counts": ("garbled-target", lambda o: _held(_move(o / "sigma.json"))[1]),
    "fig9_11.sigma_excursion_rad": ("matched-pair", lambda o: _held(_move(o / "delta.json"))[0]),
    "fig9_11.sigma_returned_counts": ("garbled-target", lambda o: _held(_move(o / "delta.json"))[1]),
    "fig9_10.reduction_group": ("naive-twice", lambda o: _reduction(o, "sigma")),
    "fig9_11.reduction_group": ("naive-twice", lambda o: _reduction(o, "delta")),
}
_MADE: dict[str, Path] = {}


def _variant(name: str, cli, tmp_path_factory: pytest.TempPathFactory) -> Path:
    if name in _MADE:
        return _MADE[name]
    changes, steps = VARIANTS[name]
    folder = tmp_path_factory.mktemp(name)
    # patient SDO and liveness bounds, as tests/test_section9.py has them (a loaded machine, stepped time)
    text = SEED.read_text(encoding="utf-8").replace(
        "protocol: {mo_settle: 0.5, sv_blackout: 0.5}", "protocol: {mo_settle: 0.5, sv_blackout: 0.5, sdo_timeout: 2.0}"
    ).replace("motion: {consumer_time_ms: 1000,", "motion: {consumer_time_ms: 1000, liveness_timeout: 10,")
    assert "liveness_timeout: 10" in text
    for drive, keys in changes.items():
        text = _drive_line(text, drive, **keys)
    config = folder / "profile.yaml"
    config.write_text(text, encoding="utf-8")
    recipe = folder / "variant.yaml"
    recipe.write_text("sim_time: stepped\nsteps:\n" + "".join(f"  - run: {s.format(out=folder)}\n" for s in steps),
                      encoding="utf-8")
    assert cli("--config", str(config), "sim", "--reset-state").exit_code == 0  # every joint at its centre
    result = cli("--config", str(config), "--sim", "recipe", "run", str(recipe), "--apply")
    assert result.exit_code == 0, result.transcript()
    _MADE[name] = folder
    return folder


def test_every_band_has_a_variant_that_fails_it():
    assert set(FAILS) == set(BANDS)


@pytest.mark.parametrize("key", sorted(FAILS))
def test_the_band_fails_on_its_variant(key, cli, cli_windows, tmp_path_factory):
    cli_windows(False)  # the profile's 500 ms settle window: the switch bands are about it
    variant, number = FAILS[key]
    value = number(_variant(variant, cli, tmp_path_factory))
    assert not BANDS[key].holds(value), f"{key} = {value} holds on the variant {variant!r}"


def _run(speeds: list[float], switch: tuple[str, ...] = (), switch_s: float = 0.0):
    """A run as `log step` leaves it, in memory: the speed every 10 ms from t = 0."""
    from sherpa_cli.log.recording import Recording
    from sherpa_cli.log.step_compare import RunFigures

    times = [i * 0.01 for i in range(len(speeds))]
    fig = RunFigures(name="r", path="r", joint="j", mode="position", value=1.0, switch_s=switch_s,
                     switch_steps=list(switch), settled=True, metrics={}, motion_start_s=0.0, peak_speed=max(speeds),
                     peak_speed_after_s=None, slowing_after_s=None, steady_speed=None, steady_ripple=None)
    return fig, Recording(times=times, columns={"j.vel_rad_s": speeds})


def test_a_drop_is_a_speed_that_falls_before_the_strong_run_decelerates_not_one_that_levels_off():
    rising = [min(2.0, 0.2 * i) for i in range(10)]  # 2 rad/s from 0.1 s on
    falls = [*rising, *(2.0 - 0.1 * i for i in range(10)), *([1.0] * 30)]  # peak at 0.10 s, then down to 1
    levels = [*rising, *([2.0] * 40)]
    assert falls_at(_run(falls), 0.4) == pytest.approx(0.10)
    assert falls_at(_run(levels), 0.4) is None
    assert falls_at(_run(falls), 0.115) is None  # it falls only after the strong run decelerated: no drop
    assert falls_at(_run(falls), None) is None


def test_only_the_seed_s_switch_has_a_switch_time():
    assert seed_switch_ms(_run([0.0, 1.0], ("MO=0", "UM=5", "MO=1"), 1.02)[0]) == pytest.approx(1020)
    assert seed_switch_ms(_run([0.0, 1.0], ("MO=0", "UM=2", "MO=1"), 1.02)[0]) == pytest.approx(1020)
    for other in [("MO=1",), ("UM=5", "MO=1"), (), ("MO=0", "MO=1", "UM=5")]:
        assert seed_switch_ms(_run([0.0, 1.0], other, 0.51)[0]) is None, other
