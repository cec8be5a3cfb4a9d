"""`sherpa commission` and the shipped recipes end to end on the simulated arm."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET

import pytest
import yaml

from sherpa_cli.recipes import load_recipe

EXAMPLE3 = "configs/appendix-c/example3.yaml"


@pytest.fixture(autouse=True)
def stable_durations(monkeypatch):
    """Every recipe step lasts 0.5 s on the runner's clock, so durations in the goldens are stable."""
    monkeypatch.setenv("SHERPA_FAKE_STEP_SECONDS", "0.5")


def normalized(result, tmp_path) -> str:
    return result.transcript().replace(str(tmp_path), "<tmp>")


@pytest.mark.parametrize("name", ["commission-arm.yaml", "backup.yaml"])
def test_shipped_recipes_load(name):
    from sherpa_cli.cli.recipe_cmd import RECIPES_DIR

    recipe = load_recipe(RECIPES_DIR / name)
    assert recipe.steps and all(s.name for s in recipe.steps)


@pytest.mark.golden
def test_commission_example3_applies_saves_and_the_numbers_arrive(cli, golden, tmp_path):
    backup = tmp_path / "backup.yaml"
    report, junit = tmp_path / "report.json", tmp_path / "report.xml"
    r = cli("--config", EXAMPLE3, "--sim", "commission", "--apply", "--yes", "--set", f"backup={backup}",
            "--report", str(report), "--junit", str(junit))
    golden("commission-example3-apply.txt", normalized(r, tmp_path))
    assert r.exit_code == 0, r.stderr
    assert "every drive is programmed, verified and saved (2 drives)" in r.stdout
    data = json.loads(report.read_text())
    assert data["outcome"] == "passed" and data["counts"]["passed"] == 9
    save = next(s for s in data["steps"] if s["name"] == "save")
    assert save["dry_run"] is False and save["command"][-3:] == ["--apply", "--save", "--yes"]
    suite = ET.parse(junit).getroot().find("testsuite")
    assert (suite.get("tests"), suite.get("failures")) == ("9", "0")
    # the backup was taken before anything was written: it holds what the drives held before (the
    # simulator's delivered values), not the Appendix C numbers
    dumped = yaml.safe_load(backup.read_text())["drives"]
    for drive in ("drive1", "drive2"):
        params = dumped[drive]["params"]
        assert (params["VL[3]"], params["VH[3]"], params["LL[3]"], params["HL[3]"]) != (-190, 190, -205, 205)
    # ... and a new invocation (a power cycle: RAM from flash) reads them back from the drives
    for drive in ("drive1", "drive2"):
        r = cli("--config", EXAMPLE3, "--sim", "--json", "cmd", drive, "VL[3]", "VH[3]", "LL[3]", "HL[3]",
                "IL[1]", "IL[2]", "IL[3]", "IL[4]")
        values = [x["value"] for x in json.loads(r.stdout)["results"]]
        assert values == [-190, 190, -205, 205, 21, 21, 21, 21], r.stdout
    # a second commissioning finds nothing to write and saves nothing
    r = cli("--config", EXAMPLE3, "--sim", "commission", "--apply", "--yes", "--set", f"backup={backup}")
    golden("commission-example3-again.txt", normalized(r, tmp_path))
    assert r.exit_code == 0 and r.stdout.count("held already, no SV needed") == 2
    # ... whose backup, taken before it, holds the Appendix C numbers the first one programmed
    dumped = yaml.safe_load(backup.read_text())["drives"]
    for drive in ("drive1", "drive2"):
        params = dumped[drive]["params"]
        assert (params["VL[3]"], params["VH[3]"], params["LL[3]"], params["HL[3]"]) == (-190, 190, -205, 205)
        assert [params[f"IL[{n}]"] for n in (1, 2, 3, 4)] == [21, 21, 21, 21]
    assert f"backup from before this run: {backup}\n" in r.stdout
    assert "homing marks are cleared;\n  home the arm next" in r.stdout


@pytest.mark.golden
def test_commission_dry_run_writes_nothing(cli, golden, tmp_path, monkeypatch):
    from sherpa_cli.elmo import codec
    from sherpa_cli.sim.arm import SimArm

    # Watch the frames the arm received: a dry run sends only queries. The steps share one session,
    # so one simulated arm serves the whole recipe.
    arms = []
    factory = SimArm.for_session.__func__

    def capture(cls, cfg, channels):
        arms.append(factory(cls, cfg, channels))
        return arms[-1]

    monkeypatch.setattr(SimArm, "for_session", classmethod(capture))
    r = cli("--config", EXAMPLE3, "--sim", "commission", "--set", f"backup={tmp_path / 'b.yaml'}")
    assert len(arms) == 1, "the steps ran against one simulated arm"
    for arm in arms:
        for d in arm.drives.values():
            kinds = {codec.decode_request(data).kind for _, can_id, data in d.received if can_id == 0x300 + d.node}
            assert kinds <= {"query"}, f"{d.node}: only queries in a dry run, got {kinds}"
            assert d.od_writes == [] and d.save_count == 0
    golden("commission-example3-dry-run.txt", normalized(r, tmp_path))
    # nothing is wrong: the dry run shows its plan, asks nothing and does not verify what it did not write
    assert r.exit_code == 0, r.stdout
    assert "[6/9] confirm-save  skipped (dry run: nothing to confirm)" in r.stdout
    assert "[4/9] backup        skipped (dry run: nothing was written)" in r.stdout
    assert "[7/9] save          passed (dry run)" in r.stdout
    assert "[8/9] verify        skipped (dry run: nothing was written)" in r.stdout
    assert "dry run: nothing was written (2 drives)" in r.stdout
    r = cli("--config", EXAMPLE3, "--sim", "--json", "cmd", "drive1", "LL[3]")
    assert json.loads(r.stdout)["results"][0]["value"] != -205


@pytest.mark.golden
@pytest.mark.realbus
def test_commission_whole_arm(arm_cli, golden, tmp_path):
    # The steps share one session, so RAM survives between them as on the real arm: the save step
    # finds nothing to write and saves what the apply step left in RAM. The steps' output is in
    # the report only, so the transcript is the same on every transport.
    r = arm_cli("commission", "--apply", "--yes", "--set", f"backup={tmp_path / 'b.yaml'}")
    golden("commission-arm-apply.txt", normalized(r, tmp_path))
    assert r.exit_code == 0, r.stdout
    assert "every drive is programmed, verified and saved (14 drives)" in r.stdout


def test_commission_stops_at_a_missing_drive_and_says_where_to_resume(cli, tmp_path):
    cfg = tmp_path / "arm.yaml"
    from tests.conftest import ROOT

    base = (ROOT / EXAMPLE3).read_text()
    cfg.write_text(base + "\nsim:\n  drives:\n    drive2: {die_at: 0}\n")
    r = cli("--config", str(cfg), "--sim", "commission", "--apply", "--yes",
            "--set", f"backup={tmp_path / 'b.yaml'}")
    assert r.exit_code == 1
    assert "[1/9] scan          FAILED" in r.stdout and "exit code 1, expected 0" in r.stdout
    assert "resume with: --from scan" in r.stdout
    assert "commissioning is NOT complete" in r.stdout or "the save step did not run" in r.stdout


def test_after_commissioning_one_changed_value_is_the_only_difference(cli, tmp_path):
    # The check after commissioning: the dump of a commissioned drive matches the config;
    # change one value and the diff shows exactly that one. With --sim a change must be saved
    # (SV) to outlive the invocation, exactly like a real arm that is power-cycled.
    r = cli("--config", EXAMPLE3, "--sim", "commission", "--apply", "--yes",
            "--set", f"backup={tmp_path / 'b.yaml'}")
    assert r.exit_code == 0, r.stdout
    r = cli("--config", EXAMPLE3, "--sim", "--json", "params", "diff", "config", "live")
    assert r.exit_code == 0, r.stdout
    r = cli("--config", EXAMPLE3, "--sim", "cmd", "drive2", "AC=777", "SV", "--apply", "--raw-save")
    assert r.exit_code == 0, r.stderr
    r = cli("--config", EXAMPLE3, "--sim", "--json", "params", "diff", "config", "live")
    assert r.exit_code == 1
    data = json.loads(r.stdout)
    differing = [(d["drive"], p["param"], p["a"], p["b"]) for d in data["drives"] for p in d["params"]
                 if p["status"] != "same"]
    assert differing == [("drive2", "AC", 500, 777)]
