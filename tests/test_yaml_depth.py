"""YAML nesting limits hold whatever PyYAML and libyaml refuse first.

PyYAML 6.0.4's libyaml scanner refuses deep flow nesting while scanning ahead, before the
parser yields the events the project's depth check counts; the pure loader that composes
what libyaml refused recurses. The project's own check must refuse such input first, with
one located message, in every door a YAML input takes (config, recipe check, recipe run).
"""

from __future__ import annotations

import pytest
import yaml

from sherpa_cli.config import yamlnodes
from sherpa_cli.config.yamlnodes import MAX_DEPTH, parse_yaml
from sherpa_cli.errors import ConfigError

DEEP = {
    "flow lists": "a: " + "[" * 2000 + "]" * 2000 + "\n",
    "flow mappings": "a: " + "{b: " * 2000 + "1" + "}" * 2000 + "\n",
    "block lists": "a:\n" + "".join("  " * i + "-\n" for i in range(1, 300)) + "  " * 300 + "- x\n",
    "block mappings": "".join("  " * i + f"k{i}:\n" for i in range(300)) + "  " * 300 + "v: 1\n",
    "just past the limit": "a: " + "[" * MAX_DEPTH + "]" * MAX_DEPTH + "\n",
}


def refusal(text: str) -> ConfigError:
    with pytest.raises(ConfigError) as info:
        parse_yaml(text, "deep.yaml")
    return info.value


@pytest.mark.parametrize("text", DEEP.values(), ids=DEEP.keys())
def test_deep_nesting_is_refused_by_the_projects_check(text):
    exc = refusal(text)
    assert str(exc).startswith("deep.yaml:") and f"nesting deeper than {MAX_DEPTH} levels" in str(exc)
    assert exc.location.line is not None  # located: the line where level 33 opens


@pytest.mark.parametrize("text", DEEP.values(), ids=DEEP.keys())
def test_deep_nesting_is_refused_with_the_pure_loader_alone(monkeypatch, text):
    monkeypatch.setattr(yamlnodes, "FAST_LOADER", None)  # PyYAML built without libyaml
    assert f"nesting deeper than {MAX_DEPTH} levels" in str(refusal(text))


class RefusesAhead(yaml.SafeLoader):
    """A fast loader that, like libyaml 6.0.4 but sooner, refuses a document before yielding any event."""

    def check_event(self, *choices):
        raise yaml.scanner.ScannerError("while scanning ahead", None, "exceeded maximum nesting depth", None)


@pytest.mark.parametrize("text", DEEP.values(), ids=DEEP.keys())
def test_a_fast_loader_that_refuses_first_does_not_hand_deep_input_to_a_recursion(monkeypatch, text):
    monkeypatch.setattr(yamlnodes, "FAST_LOADER", RefusesAhead)
    assert f"nesting deeper than {MAX_DEPTH} levels" in str(refusal(text))


def test_a_nesting_the_check_missed_is_still_one_message(monkeypatch):
    """The net under the check: a RecursionError while composing becomes the same refusal."""
    monkeypatch.setattr(yamlnodes, "check_limits", lambda text, filename: None)
    exc = refusal(DEEP["flow lists"])
    assert str(exc).startswith("deep.yaml") and f"nesting deeper than {MAX_DEPTH} levels" in str(exc)


def test_nesting_at_the_limit_still_parses():
    root = parse_yaml("a: " + "[" * (MAX_DEPTH - 1) + "1" + "]" * (MAX_DEPTH - 1) + "\n", "ok.yaml")
    assert root.kind == "map"


def test_a_syntax_error_stays_a_syntax_error():
    with pytest.raises(ConfigError, match="YAML syntax error"):
        parse_yaml("a: [1, 2\nb: 3\n", "bad.yaml")


@pytest.mark.parametrize("kind", ["flow lists", "block mappings"])
@pytest.mark.parametrize("argv", [
    ["recipe", "check", "{path}"],
    ["--sim", "recipe", "run", "{path}"],
    ["--sim", "recipe", "run", "{path}", "--apply", "--yes"],
    ["config", "check", "{path}"],
    ["--config", "{path}", "scan"],
], ids=["recipe check", "recipe run", "recipe run --apply", "config check", "--config"])
def test_deep_input_through_the_cli_is_one_located_message(cli, tmp_path, kind, argv):
    path = tmp_path / "deep.yaml"
    path.write_text(DEEP[kind])
    result = cli(*(a.format(path=path) for a in argv))
    assert result.exit_code == 2, result.transcript()
    assert "Traceback" not in result.stderr and "RecursionError" not in result.stderr
    errors = [line for line in result.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and f"{path}:" in errors[0] and f"nesting deeper than {MAX_DEPTH} levels" in errors[0], \
        result.transcript()
