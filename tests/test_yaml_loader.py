"""parse_yaml composes with libyaml (yaml.CSafeLoader) where it exists, and that changes nothing:
the same values, lines and key paths as the pure loader, and the same errors (file:line: path: text).
"""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from sherpa_cli.config import yamlnodes
from sherpa_cli.config.yamlnodes import YNode, parse_yaml
from sherpa_cli.errors import ConfigError

ROOT = Path(__file__).resolve().parent.parent
SHIPPED = sorted([*ROOT.glob("configs/**/*.yaml"), *ROOT.glob("recipes/*.yaml")])

needs_libyaml = pytest.mark.skipif(not getattr(yaml, "__with_libyaml__", False),
                                   reason="PyYAML was built without libyaml: the pure loader is the only one")


def flat(node: YNode) -> list[tuple]:
    """Every node as (path, kind, line, key_line, scalar value or None), in file order."""
    out = [(node.path, node.kind, node.line, node.key_line, node.value if node.kind == "scalar" else None)]
    children = node.value.values() if node.kind == "map" else node.value if node.kind == "seq" else ()
    for child in children:
        out += flat(child)
    return out


def outcome(text: str):
    try:
        return ("ok", flat(parse_yaml(text, "x.yaml")))
    except ConfigError as exc:
        return ("error", str(exc.location), exc.problem, exc.hint)


def both(monkeypatch, text: str):
    fast = outcome(text)
    with monkeypatch.context() as m:
        m.setattr(yamlnodes, "FAST_LOADER", None)
        pure = outcome(text)
    return fast, pure


@needs_libyaml
def test_the_fast_loader_is_libyaml_and_is_used(monkeypatch):
    assert yamlnodes.FAST_LOADER is yaml.CSafeLoader
    used = []
    real = yaml.compose
    monkeypatch.setattr(yaml, "compose", lambda text, Loader: used.append(Loader) or real(text, Loader=Loader))
    parse_yaml("a: 1\n", "x.yaml")
    assert used == [yaml.CSafeLoader]


@needs_libyaml
@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: str(p.relative_to(ROOT)))
def test_shipped_files_compose_alike_with_both_loaders(monkeypatch, path):
    fast, pure = both(monkeypatch, path.read_text(encoding="utf-8"))
    assert fast[0] == "ok" and len(fast[1]) > 10
    assert fast == pure


@needs_libyaml
@pytest.mark.parametrize("text", [
    "a: 0o17\nb: 0x1F\nc: 1_000\nd: yes\ne: 1e3\nf: .inf\ng: 2001-12-14\nh: ~\ni: '07'\n",
    "base: &b {x: 1, y: [1, 2]}\nuse:\n  <<: *b\n  z: 3\n",
    "list:\n  - {a: 1}\n  -\n    b: 2\n  - - nested\n",
    "text: |\n  two\n  lines\nfolded: >\n  one\n  line\n",
])
def test_values_and_lines_are_the_same(monkeypatch, text):
    fast, pure = both(monkeypatch, text)
    assert fast[0] == "ok" and fast == pure


@needs_libyaml
@pytest.mark.parametrize("text", [
    "joints:\n  wrist: a: b\n",          # libyaml: "... not allowed in this context"
    "drives:\n  e: {node: [1, 2\n",      # libyaml: "did not find expected ',' or ']'"
    "a:\n  - 1\n - 2\n",
    "- a\nb: 1\n",
    "a: 1\n\tb: 2\n",
    "a: \x07x\n",
    "a: *missing\n",
    "a: 1\n---\nb: 2\n",
    "a: 1\na: 2\n",
    "a: \ud800\n",                        # libyaml raises UnicodeEncodeError, not a YAMLError
    "%YAML 1.3\n---\na: 1\n",            # libyaml refuses, the pure loader accepts (with a warning)
])
def test_errors_keep_the_pure_loaders_words_and_lines(monkeypatch, text):
    fast, pure = both(monkeypatch, text)
    assert fast == pure


def test_a_syntax_error_names_file_line_and_key_path():
    with pytest.raises(ConfigError) as exc:
        parse_yaml("drives:\n  e:\n    node: [1, 2\n", "arm.yaml")
    assert str(exc.value.location).startswith("arm.yaml:")
    assert exc.value.problem.startswith("YAML syntax error: expected ',' or ']'")
