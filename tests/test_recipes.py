"""Recipe format, runner semantics (dry run, --from, failures, confirmations) and reports."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from sherpa_cli.errors import ConfigError, SafetyError, UsageError
from sherpa_cli.recipes import Step, load_recipe
from sherpa_cli.recipes.report import report_json, report_junit
from sherpa_cli.recipes.runner import CommandRun, check_json_path, run_recipe


def write(tmp_path: Path, text: str, name: str = "r.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


BASIC = """\
name: basic
vars: {drive: shoulder_1a}
steps:
  - name: look
    run: cmd {drive} PX
  - confirm: "Press the low end switch of {drive} now"
  - name: program
    run: [program-limits, "{drive}", --apply, --save, --yes]
    expect: {json: {"drives.*.saved": true}}
  - name: diff
    run: sherpa params diff config live
    expect: {exit: [0, 1]}
"""


class FakeSherpa:
    """Records command lines; answers from a table keyed by the first word."""

    def __init__(self, answers: dict[str, CommandRun] | None = None) -> None:
        self.calls: list[list[str]] = []
        self.answers = answers or {}

    def __call__(self, argv):
        argv = list(argv)
        self.calls.append(argv)
        words = [a for a in argv if not a.startswith("--json")]
        return self.answers.get(words[0], CommandRun(0, "ok\n", ""))


def test_load_substitutes_vars_and_splits_commands(tmp_path):
    r = load_recipe(write(tmp_path, BASIC))
    assert [s.name for s in r.steps] == ["look", "step-2", "program", "diff"]
    assert r.steps[0].argv == ("cmd", "shoulder_1a", "PX")
    assert r.steps[1].confirm == "Press the low end switch of shoulder_1a now"
    assert r.steps[2].argv == ("program-limits", "shoulder_1a", "--apply", "--save", "--yes")
    assert r.steps[2].writes and not r.steps[0].writes
    assert r.steps[2].dry_argv() == ("program-limits", "shoulder_1a")
    assert Step(9, "s", argv=("scan", "--reset")).dry_argv() == ("scan",)
    assert Step(9, "s", argv=("program-limits", "--apply", "-y")).dry_argv() == ("program-limits",)
    assert r.steps[3].argv == ("params", "diff", "config", "live")  # a leading "sherpa" is dropped
    assert r.steps[3].expect.exit == (0, 1)


def test_set_overrides_a_variable(tmp_path):
    r = load_recipe(write(tmp_path, BASIC), {"drive": "elbow_1a"})
    assert r.steps[0].argv == ("cmd", "elbow_1a", "PX")


def test_dry_run_strips_write_flags_and_skips_write_expectations(tmp_path):
    r = load_recipe(write(tmp_path, BASIC))
    fake = FakeSherpa()
    rep = run_recipe(r, fake, apply=False, confirm=lambda q: True)
    # a step with JSON expectations runs with --json in a dry run too (its plan is machine-read)
    assert fake.calls == [["cmd", "shoulder_1a", "PX"], ["--json", "program-limits", "shoulder_1a"],
                          ["params", "diff", "config", "live"]]
    # the confirm step is not asked in a dry run: nothing is written, so nothing needs confirming
    assert [x.status for x in rep.results] == ["passed", "skipped", "passed", "passed"]
    assert rep.results[2].dry_run and rep.exit_code == 0


def test_dry_run_skip_steps_and_confirm_steps_that_ask_anyway(tmp_path):
    text = """\
steps:
  - {name: look, run: cmd shoulder_1a PX}
  - {name: ask, confirm: "Press the switch", dry_run: run}
  - {name: program, run: program-limits --apply}
  - {name: verify, run: params diff config live, dry_run: skip}
"""
    r = load_recipe(write(tmp_path, text))
    fake = FakeSherpa()
    asked = []
    rep = run_recipe(r, fake, apply=False, confirm=lambda q: asked.append(q) or True)
    assert asked == ["Press the switch"]
    assert fake.calls == [["cmd", "shoulder_1a", "PX"], ["program-limits"]]
    assert [x.status for x in rep.results] == ["passed", "passed", "passed", "skipped"]
    assert rep.results[3].failures == ["dry run: nothing was written"] and rep.exit_code == 0
    rep = run_recipe(r, FakeSherpa(), apply=True, confirm=lambda q: True)
    assert [x.status for x in rep.results] == ["passed"] * 4


def test_dry_run_key_is_checked(tmp_path):
    with pytest.raises(ConfigError, match="dry_run must be one of run, skip"):
        load_recipe(write(tmp_path, "steps:\n  - {run: scan, dry_run: maybe}\n"))


def test_apply_runs_write_flags_and_checks_json(tmp_path):
    r = load_recipe(write(tmp_path, BASIC))
    saved = json.dumps({"drives": [{"saved": True}, {"saved": False}]})
    fake = FakeSherpa({"program-limits": CommandRun(0, saved, "")})
    rep = run_recipe(r, fake, apply=True, confirm=lambda q: True)
    assert fake.calls[1] == ["--json", "program-limits", "shoulder_1a", "--apply", "--save", "--yes"]
    prog = rep.results[2]
    assert prog.status == "failed" and prog.failures == ["drives.1.saved: false, expected true"]
    assert [x.status for x in rep.results] == ["passed", "passed", "failed", "skipped"]
    assert rep.exit_code == 1 and rep.outcome == "failed"


def test_exit_expectation_and_continue(tmp_path):
    text = """\
on_failure: continue
steps:
  - {name: a, run: scan}
  - {name: b, run: identify, on_failure: stop}
  - {name: c, run: monitor --once}
"""
    fake = FakeSherpa({"scan": CommandRun(1, "", "missing\n"), "identify": CommandRun(3, "", "")})
    rep = run_recipe(load_recipe(write(tmp_path, text)), fake, apply=False, confirm=lambda q: True)
    assert [x.status for x in rep.results] == ["failed", "failed", "skipped"]
    assert rep.results[0].failures == ["exit code 1, expected 0"]
    assert rep.results[2].failures == ["step 2 (b) failed"]


def test_from_skips_earlier_steps(tmp_path):
    r = load_recipe(write(tmp_path, BASIC))
    fake = FakeSherpa()
    rep = run_recipe(r, fake, apply=False, confirm=lambda q: True, start_at=r.find_step("program"))
    assert [x.status for x in rep.results] == ["skipped", "skipped", "passed", "passed"]
    assert r.find_step("4").name == "diff"
    with pytest.raises(UsageError, match="no such step"):
        r.find_step("nope")


def test_declined_and_unanswerable_confirmations_stop_the_run(tmp_path):
    r = load_recipe(write(tmp_path, BASIC))
    rep = run_recipe(r, FakeSherpa(), apply=True, confirm=lambda q: False)
    assert [x.status for x in rep.results] == ["passed", "declined", "skipped", "skipped"]

    def nobody(q):
        raise SafetyError("no terminal")

    rep = run_recipe(r, FakeSherpa(), apply=True, confirm=nobody)
    assert rep.results[1].status == "declined" and rep.results[1].failures == ["no terminal"]


def test_interrupted_step_ends_the_run_with_130(tmp_path):
    r = load_recipe(write(tmp_path, BASIC))
    rep = run_recipe(r, FakeSherpa({"cmd": CommandRun(130, "", "error: interrupted\n")}), apply=True,
                     confirm=lambda q: True)
    assert rep.outcome == "interrupted" and rep.exit_code == 130
    assert [x.status for x in rep.results] == ["interrupted", "skipped", "skipped", "skipped"]


@pytest.mark.parametrize("doc,path,wanted,failures", [
    ({"a": [1, 2]}, "a.1", 2, []),
    ({"a": [1, 2]}, "a.*", 1, ["a.1: 2, expected 1"]),
    ({"a": {"x": {"ok": True}, "y": {"ok": True}}}, "a.*.ok", True, []),
    ({"a": {}}, "a.b", 1, ["a.b: no such key in the output"]),
    ({"a": [1]}, "a.3", 1, ["a.3: the list has only 1 item(s)"]),
    ({"a": []}, "a.*", 1, ["a.*: matches nothing in the output"]),
    ({"missing": []}, "missing", [], []),
])
def test_json_paths(doc, path, wanted, failures):
    assert check_json_path(doc, path, wanted) == failures


def test_reports(tmp_path):
    r = load_recipe(write(tmp_path, BASIC))
    fake = FakeSherpa({"params": CommandRun(2, "", "error: bad\n")})
    rep = run_recipe(r, fake, apply=False, confirm=lambda q: True)
    data = json.loads(report_json(rep))
    assert data["outcome"] == "failed" and data["counts"]["failed"] == 1
    assert data["steps"][3]["command"] == ["sherpa", "params", "diff", "config", "live"]
    suite = ET.fromstring(report_junit(rep)).find("testsuite")
    # the confirm step is skipped in a dry run
    assert (suite.get("tests"), suite.get("failures"), suite.get("skipped")) == ("4", "1", "1")
    failed = [c for c in suite.iter("testcase") if c.find("failure") is not None]
    assert [c.get("name") for c in failed] == ["04-diff"]
    assert failed[0].find("failure").get("message") == "exit code 2, expected 0 or 1"


BAD = [
    ("not-a-map", "- a\n", "expected a recipe mapping"),
    ("unknown-key", "stepz: []\n", "unknown key 'stepz'"),
    ("no-steps", "steps: []\n", "at least one step"),
    ("both", "steps:\n  - {run: scan, confirm: 'ok?'}\n", "exactly one of"),
    ("neither", "steps:\n  - {name: x}\n", "exactly one of"),
    ("global-option", "steps:\n  - run: --sim scan\n", "'--sim' is a global option"),
    ("config-option", "steps:\n  - run: scan --config=x.yaml\n", "'--config' is a global option"),
    ("nested", "steps:\n  - run: recipe run x.yaml\n", "recipes do not nest"),
    ("dup-name", "steps:\n  - {name: a, run: scan}\n  - {name: a, run: scan}\n", "used twice"),
    ("bad-var", "steps:\n  - run: cmd {drive} PX\n", "unknown variable {drive}"),
    ("bad-exit", "steps:\n  - {run: scan, expect: {exit: 300}}\n", "outside 0..255"),
    ("bad-failure", "on_failure: retry\nsteps:\n  - run: scan\n", "on_failure must be one of"),
    ("confirm-expect", "steps:\n  - {confirm: 'ok?', expect: {exit: 0}}\n", "no result to expect"),
    ("quote", "steps:\n  - run: cmd 'x PX\n", "cannot split"),
    ("numeric-name", "steps:\n  - {name: '3', run: scan}\n", "invalid step name"),
]


@pytest.mark.parametrize("name,text,message", BAD, ids=[b[0] for b in BAD])
def test_bad_recipes_name_file_and_line(tmp_path, name, text, message):
    path = write(tmp_path, text)
    with pytest.raises(ConfigError) as info:
        load_recipe(path)
    assert message in str(info.value)
    assert str(path) in str(info.value)


def test_unknown_set_variable(tmp_path):
    with pytest.raises(ConfigError, match="has no variable 'nope'"):
        load_recipe(write(tmp_path, BASIC), {"nope": "1"})


def test_cli_bad_recipe_exit_2_no_traceback(cli, tmp_path):
    path = write(tmp_path, "steps:\n  - {run: scan, confirm: x}\n")
    r = cli("recipe", "run", str(path))
    assert r.exit_code == 2 and "Traceback" not in r.stderr
    assert f"{path}:2" in r.stderr and "exactly one of" in r.stderr
    r = cli("recipe", "run", str(tmp_path / "missing.yaml"))
    assert r.exit_code == 2 and "recipe file not found" in r.stderr
    r = cli("recipe", "run", str(write(tmp_path, BASIC, "b.yaml")), "--from", "zzz")
    assert r.exit_code == 2 and "--from zzz: no such step" in r.stderr
    r = cli("recipe", "run", str(write(tmp_path, BASIC, "c.yaml")), "--set", "novalue")
    assert r.exit_code == 2 and "expected KEY=VALUE" in r.stderr


def test_cli_confirm_without_terminal_declines(cli, tmp_path):
    path = write(tmp_path, "steps:\n  - confirm: Go?\n  - run: limits show elbow_pitch\n")
    r = cli("recipe", "run", str(path), "--apply")  # a dry run asks nothing
    assert r.exit_code == 1
    assert "[1/2] step-1  declined (answer: no answer)" in r.stdout
    assert "[2/2] step-2  skipped (step 1 (step-1) declined)" in r.stdout
    r = cli("recipe", "run", str(path), "--apply", "--verbose")
    assert r.exit_code == 1 and "-> declined (answer: no answer)" in r.stdout
    r = cli("recipe", "run", str(path), "--apply", "--yes")
    assert r.exit_code == 0 and "[2/2] step-2  passed" in r.stdout
    r = cli("recipe", "run", str(path))
    assert r.exit_code == 0 and "[1/2] step-1  skipped (dry run: nothing to confirm)" in r.stdout


def test_cli_unreadable_recipe_and_unwritable_reports_exit_2_no_traceback(cli, tmp_path):
    binary = tmp_path / "binary.yaml"
    binary.write_bytes(b"\xff\xfe\x00\xba garbage")
    r = cli("recipe", "run", str(binary))
    assert r.exit_code == 2 and "Traceback" not in r.stderr
    assert f"{binary}: cannot read recipe: not UTF-8" in r.stderr
    r = cli("recipe", "run", str(tmp_path))
    assert r.exit_code == 2 and f"{tmp_path}: is a directory" in r.stderr
    path = write(tmp_path, "steps:\n  - run: limits show elbow_pitch\n", "ok.yaml")
    r = cli("recipe", "run", str(path), "--junit", str(tmp_path))
    assert r.exit_code == 2 and "--junit" in r.stderr and "is a directory" in r.stderr
    assert "[1/1]" not in r.stdout, "refused before any step ran"
    blocker = tmp_path / "a-file"
    blocker.write_text("x")
    r = cli("recipe", "run", str(path), "--report", str(blocker / "report.json"))
    assert r.exit_code == 2 and "Traceback" not in r.stderr
    assert f"--report {blocker / 'report.json'}: cannot write the report" in r.stderr


def test_recipe_dir_points_at_the_recipes_own_directory_from_any_working_directory(tmp_path, monkeypatch):
    """The Section 9 recipe's bands table is found from any directory (run from /tmp its last step
    failed after every figure: "--bands docs/section9/bands.yaml: cannot read it"); outputs stay
    relative to where it runs."""
    from sherpa_cli.recipes.model import load_recipe

    root = Path(__file__).resolve().parent.parent
    monkeypatch.chdir(tmp_path)
    recipe = load_recipe(root / "recipes" / "seed-section9.yaml")
    summary = next(s for s in recipe.steps if "section9" in " ".join(s.argv) and "--bands" in s.argv)
    bands = Path(summary.argv[summary.argv.index("--bands") + 1])
    assert bands.is_absolute() and bands.resolve() == root / "docs" / "section9" / "bands.yaml" and bands.exists()
    assert recipe.variables["out"] == "section9-out"  # an output: the working directory's
