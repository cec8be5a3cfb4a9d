"""Bad input through the real CLI: exit code 2, one message naming what and where, no traceback.

The config cases are the loader's own (tests/test_config_errors.py) run end to end through
`sherpa`; the argument cases are the command-line mistakes a technician makes.
"""

from __future__ import annotations

import pytest
from test_config_errors import CASES, Bad, _apply


def _assert_clean_usage_error(result, *needles: str) -> None:
    assert result.exit_code == 2, result.transcript()
    assert "Traceback" not in result.stderr and "Traceback" not in result.stdout
    assert result.stdout == "", "nothing goes to stdout when the input is bad"
    for needle in needles:
        assert needle in result.stderr, result.transcript()


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_bad_config_through_the_cli(cli, tmp_path, case: Bad):
    text, line = _apply(case)
    path = tmp_path / f"{case.id}.yaml"
    path.write_text(text, encoding="utf-8")
    for command in (["config", "check"], ["limits", "show"]):
        result = cli("--config", str(path), *command)
        _assert_clean_usage_error(result, f"error: {path}:{line}: {case.path}: ", case.phrase)
        assert len([ln for ln in result.stderr.splitlines() if ln.startswith("error:")]) == 1


ARGUMENTS = [
    ("unknown-option", ["--bogus"], ["No such option: --bogus"]),
    ("unknown-command", ["frobnicate"], ["No such command 'frobnicate'"]),
    ("unknown-subcommand", ["config", "frobnicate"], ["No such command 'frobnicate'"]),
    ("missing-config-file", ["--config", "no/such.yaml", "limits", "show"], ["no/such.yaml", "not found"]),
    ("config-is-a-directory", ["--config", "configs", "limits", "show"], ["configs", "is a directory"]),
    ("check-missing-file", ["config", "check", "nope.yaml"], ["nope.yaml"]),
    ("convert-needs-file", ["config", "convert"], ["Missing argument 'FILE'"]),
    ("limits-unknown-name", ["limits", "show", "elbo_pitch"], ["elbo_pitch", "elbow_pitch"]),
    ("diffdrive-unknown-pair", ["diffdrive", "limits", "shoulder_dif"], ["shoulder_dif", "shoulder_diff"]),
    ("diffdrive-not-a-pair", ["diffdrive", "limits", "elbow_pitch"], ["elbow_pitch"]),
    ("convert-sigma-alone", ["diffdrive", "convert", "shoulder_diff", "--sigma", "10"], ["--sigma and --delta"]),
    ("convert-motor-a-alone", ["diffdrive", "convert", "shoulder_diff", "--motor-a", "10"], ["--motor-a and --motor-b"]),
    ("convert-both-kinds", ["diffdrive", "convert", "shoulder_diff", "--sigma", "1", "--delta", "1",
                            "--motor-a", "1", "--motor-b", "1"], ["either --sigma and --delta, or --motor-a"]),
    ("convert-nothing", ["diffdrive", "convert", "shoulder_diff"], ["either --sigma and --delta"]),
    ("convert-bad-unit", ["diffdrive", "convert", "shoulder_diff", "--unit", "furlong", "--sigma", "1",
                          "--delta", "1"], ["--unit", "furlong"]),
    ("convert-fractional-counts", ["diffdrive", "convert", "shoulder_diff", "--sigma", "1.5", "--delta", "0.5"],
     ["--sigma", "1.5", "whole number"]),
    ("convert-not-a-number", ["diffdrive", "convert", "shoulder_diff", "--sigma", "abc", "--delta", "1"],
     ["--sigma", "cannot read 'abc' as a number with an optional unit"]),
    ("convert-unknown-unit", ["diffdrive", "convert", "shoulder_diff", "--sigma", "10furlongs", "--delta", "1"],
     ["--sigma", "unknown unit"]),
    ("convert-parity", ["diffdrive", "convert", "shoulder_diff", "--sigma", "3", "--delta", "2"], ["Σ=3 and Δ=2 cannot be reached", "both even or both odd"]),
    ("convert-nan-rad", ["diffdrive", "convert", "shoulder_diff", "--unit", "rad", "--sigma", "nan",
                         "--delta", "0"], ["finite"]),
]


@pytest.mark.parametrize("name,args,needles", ARGUMENTS, ids=[a[0] for a in ARGUMENTS])
def test_bad_arguments(cli, name, args, needles):
    _assert_clean_usage_error(cli(*args), *needles)


def test_current_above_the_catalog_is_refused_with_its_location(cli, tmp_path):
    from test_config_errors import BASE

    text = BASE.replace("current: {continuous: 3.0, peak: 10.0, peak_time: 2}",
                        "current: {continuous: 3.0, peak: 30.0, peak_time: 2}")
    path = tmp_path / "hot.yaml"
    path.write_text(text)
    line = text.splitlines().index("    current: {continuous: 3.0, peak: 30.0, peak_time: 2}") + 1
    shown = cli("--config", str(path), "limits", "show")
    _assert_clean_usage_error(shown, f"{path}:{line}", "peak")
    checked = cli("--config", str(path), "config", "check")
    assert checked.exit_code == 1 and "error: " in checked.stdout and "peak" in checked.stdout


def test_debug_shows_the_traceback(cli):
    from sherpa_cli.errors import UsageError

    with pytest.raises(UsageError):
        cli("--debug", "limits", "show", "no_such_joint")


def test_at_least_forty_distinct_bad_inputs():
    assert len(CASES) + len(ARGUMENTS) >= 40


@pytest.mark.parametrize("args,line", [
    (("scan", "--sim"), "hint: --sim is a global option: it goes before the command, `sherpa --sim scan`"),
    (("home", "elbow_pitch", "--json"),
     "hint: --json is a global option: it goes before the command, `sherpa --json home elbow_pitch`"),
    (("diffdrive", "move", "shoulder_diff", "--config", "configs/sherpa-arm.yaml", "--sigma", "0.1"),
     "hint: --config is a global option: it goes before the command, "
     "`sherpa --config configs/sherpa-arm.yaml diffdrive move shoulder_diff --sigma 0.1`"),
])
def test_a_global_option_after_the_command_says_where_it_goes(cli, args, line):
    result = cli(*args)
    assert result.exit_code == 2 and "No such option" in result.stderr
    assert line in result.stderr.splitlines(), result.stderr


def test_an_unknown_option_gets_no_global_option_hint(cli):
    result = cli("scan", "--bogus")
    assert result.exit_code == 2 and "No such option: --bogus" in result.stderr and "hint:" not in result.stderr
    # a global option in its place but without its value is another mistake: no hint to move it
    result = cli("--config")
    assert result.exit_code == 2 and "requires an argument" in result.stderr and "hint:" not in result.stderr


def test_the_hint_moves_the_refused_option_not_the_one_already_in_place(cli):
    result = cli("--json", "scan", "--json")
    assert "hint: --json is a global option: it goes before the command, `sherpa --json --json scan`" in result.stderr


def test_a_unit_split_from_its_value_is_named_not_taken_for_a_second_joint(cli):
    """`jog elbow_pitch --to 0.1 rad` used to say "name one JOINT to jog (got 2)"."""
    result = cli("--sim", "jog", "elbow_pitch", "--to", "0.1", "rad", "--apply")
    assert result.exit_code == 2, result.transcript()
    assert "'rad' after the value is its unit: write it without a space (--to 0.1rad" in result.stderr
    assert "got 2" not in result.stderr
