"""Stale inputs: program-limits gives every input the config does not assign "no function" (il_codes.unused),
so re-wiring from Appendix C Example 1 (stop switches on inputs 3 and 4) to Example 2 (one home switch on
input 1) leaves no stop switch behind; `params diff config` compares IL[1..n]; a D.1 config says once
which speed/acceleration parameters it leaves alone."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from sherpa_cli.config import load_config
from sherpa_cli.config.model import ILCodes
from sherpa_cli.errors import ConfigError
from sherpa_cli.joints.limits import derive_checked

ROOT = Path(__file__).resolve().parent.parent
EX1 = "configs/appendix-c/example1.yaml"
EX2 = "configs/appendix-c/example2.yaml"
IL = [f"IL[{n}]" for n in range(1, 7)]  # a Whistle 10/60 has 6 inputs


@pytest.fixture
def powered_arm(monkeypatch):
    """In-process arms that keep the previous arm's RAM (a real arm stays powered between commands)."""
    from sherpa_cli.sim.arm import SimArm

    arms: list = []
    original = SimArm.for_session.__func__

    def for_session(cls, cfg, channels, **kwargs):
        arm = original(cls, cfg, channels, **kwargs)
        if arms:
            for name, drive in arm.drives.items():
                if name in arms[-1].drives:
                    drive.ram.update(arms[-1].drives[name].ram)
        arms.append(arm)
        return arm

    monkeypatch.setattr(SimArm, "for_session", classmethod(for_session))
    return arms


def test_every_input_gets_a_function_and_unassigned_ones_none():
    (d1,) = derive_checked(load_config(ROOT / EX1))[0]
    (d2,) = derive_checked(load_config(ROOT / EX2))[0]
    assert [d1.params[k] for k in IL] == [4, 4, 21, 21, 4, 4]
    assert [d2.params[k] for k in IL] == [5, 4, 4, 4, 4, 4]


def test_unused_code_is_a_setting_that_must_differ_from_the_switch_codes(tmp_path):
    text = (ROOT / EX2).read_text()
    custom = tmp_path / "custom.yaml"
    custom.write_text(text + "\nil_codes: {unused: 6}\n")
    (d,) = derive_checked(load_config(custom))[0]
    assert [d.params[k] for k in IL] == [5, 6, 6, 6, 6, 6]
    clash = tmp_path / "clash.yaml"
    clash.write_text(text + "\nil_codes: {unused: 5}\n")
    with pytest.raises(ConfigError) as err:
        load_config(clash)
    assert "il_codes.unused and il_codes.home are both 5" in str(err.value)
    assert ILCodes().unused == 4


def test_example1_then_example2_wiring_leaves_no_stop_switch(cli, powered_arm):
    r1 = cli("--config", EX1, "--sim", "program-limits", "--apply")
    assert r1.exit_code == 0, r1.transcript()
    assert [powered_arm[-1].drives["drive1"].ram[k] for k in IL] == [4, 4, 21, 21, 4, 4]
    plan = cli("--config", EX2, "--sim", "--json", "program-limits")
    changes = {p["key"]: (p["now"], p["target"]) for p in json.loads(plan.stdout)["drives"][0]["params"]
               if p["changes"]}
    assert changes == {"IL[1]": (4, 5), "IL[3]": (21, 4), "IL[4]": (21, 4)}
    r2 = cli("--config", EX2, "--sim", "program-limits", "--apply")
    assert r2.exit_code == 0, r2.transcript()
    assert [powered_arm[-1].drives["drive1"].ram[k] for k in IL] == [5, 4, 4, 4, 4, 4]


def test_params_diff_config_compares_every_input(cli, powered_arm):
    assert cli("--config", EX1, "--sim", "program-limits", "--apply").exit_code == 0
    r = cli("--config", EX2, "--sim", "--json", "params", "diff", "config", "live")
    assert r.exit_code == 1, r.transcript()
    rows = {row["param"]: row for d in json.loads(r.stdout)["drives"] for row in d["params"]}
    differing = sorted(k for k, row in rows.items() if row["status"] != "same")
    assert "IL[3]" in differing and "IL[4]" in differing and "IL[1]" in differing
    assert all(rows[k]["status"] == "same" for k in ("IL[2]", "IL[5]", "IL[6]"))


def test_d1_config_says_once_what_it_leaves_on_the_drive(cli):
    shown = cli("--config", "configs/seed-d1.yaml", "limits", "show")
    assert shown.exit_code == 0, shown.transcript()
    note = "no speed/acceleration limits configured: VL/VH[2], LL/HL[2], AC, DC stay as the drives have them"
    assert shown.stdout.count(note) == 1
    plan = cli("--config", "configs/seed-d1.yaml", "--sim", "program-limits")
    assert plan.stdout.count(note) == 1
    full = cli("--config", EX1, "limits", "show")
    assert "no speed/acceleration" not in full.stdout
