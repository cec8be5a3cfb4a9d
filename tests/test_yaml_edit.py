"""config/yaml_edit.py: one entry of a section set in a YAML text, every other byte kept."""

from __future__ import annotations

import json

import pytest
import yaml
from hypothesis import given
from hypothesis import strategies as st

from sherpa_cli.config.yaml_edit import YamlEditError, format_scalar, set_entry

DOC = """\
# the arm on the bench  (kept)
name: bench
joints:            # every joint
  yaw: {drive: yaw_drive}

poses:
  # where the arm rides on the truck
  transport:   # a key-line comment stays
    yaw: 0.5     # an old value: replaced with its comment
    elbow: -1.25
  # docking comes next
  dock: {yaw: 0.1}

# trailing comment (kept)
tail: 1
"""


def test_an_existing_block_entry_is_replaced_in_place_and_every_comment_outside_it_stays():
    got = set_entry(DOC, "poses", "transport", {"yaw": 0.25, "elbow": -1.0})
    assert yaml.safe_load(got)["poses"]["transport"] == {"yaw": 0.25, "elbow": -1.0}
    assert got == DOC.replace("    yaw: 0.5     # an old value: replaced with its comment\n    elbow: -1.25",
                              "    yaw: 0.25\n    elbow: -1.0")


def test_a_flow_entry_becomes_a_block_one_and_the_rest_is_untouched():
    got = set_entry(DOC, "poses", "dock", {"yaw": 0.2})
    assert got == DOC.replace("  dock: {yaw: 0.1}", "  dock:\n    yaw: 0.2")


def test_a_new_entry_goes_after_the_last_one_at_the_sections_indentation():
    doc = "poses:\n    a:\n        x: 1.0\n# after\nz: 2\n"
    got = set_entry(doc, "poses", "b", {"x": 2.0, "w": "10deg"})
    assert got == "poses:\n    a:\n        x: 1.0\n    b:\n      x: 2.0\n      w: 10deg\n# after\nz: 2\n"
    assert yaml.safe_load(got) == {"poses": {"a": {"x": 1.0}, "b": {"x": 2.0, "w": "10deg"}}, "z": 2}


@pytest.mark.parametrize("section", ["poses: {}\n", "poses:\n", "poses: ~  # none yet\n"])
def test_an_empty_section_takes_its_first_entry(section):
    got = set_entry("name: x\n" + section + "tail: 1\n", "poses", "p", {"j": 1.5})
    assert yaml.safe_load(got) == {"name": "x", "poses": {"p": {"j": 1.5}}, "tail": 1}


def test_a_missing_section_is_appended_after_a_last_line_without_newline():
    got = set_entry("name: x  # no newline at the end", "poses", "p", {"j": -0.0001})
    assert got == "name: x  # no newline at the end\nposes:\n  p:\n    j: -0.0001\n"


@pytest.mark.parametrize(("doc", "section", "key", "entries", "message"), [
    ("poses: [1, 2]\n", "poses", "p", {"j": 1.0}, "poses: is not a mapping"),
    ("- 1\n", "poses", "p", {"j": 1.0}, "not a mapping"),
    ("a: [\n", "poses", "p", {"j": 1.0}, "not YAML"),
    ("", "poses", "", {"j": 1.0}, "empty name"),
    ("", "poses", "p", {}, "nothing to write"),
    ("", "poses", "p", {"j": float("nan")}, "not a finite number"),
])
def test_what_cannot_be_written_is_refused_with_the_reason(doc, section, key, entries, message):
    with pytest.raises(YamlEditError, match=message):
        set_entry(doc, section, key, entries)


@given(st.floats(allow_nan=False, allow_infinity=False, min_value=-1e6, max_value=1e6))
def test_a_number_reads_back_within_nine_significant_digits(x):
    back = yaml.safe_load(f"v: {format_scalar(x)}")["v"]
    assert isinstance(back, float)
    assert back == pytest.approx(x, rel=1e-8, abs=1e-300)


names = st.one_of(st.from_regex(r"[a-z][a-z0-9_]{0,6}", fullmatch=True), st.sampled_from(["yes", "y", "On", "null", "a b", "x:y", "#c", "é"]))
values = st.floats(min_value=-10, max_value=10, allow_nan=False).map(lambda v: float(format_scalar(v)))
poses = st.dictionaries(names, st.dictionaries(names, values, min_size=1, max_size=4), max_size=4)


def q(word: str) -> str:
    return json.dumps(word)


def test_a_name_yaml_would_read_as_something_else_is_quoted():
    got = set_entry("", "poses", "yes", {"a b": 1.0, "on": "10deg"})
    assert yaml.safe_load(got) == {"poses": {"yes": {"a b": 1.0, "on": "10deg"}}}


@given(poses=poses, flow=st.booleans(), key=names, entries=st.dictionaries(names, values, min_size=1, max_size=4))
def test_the_document_reads_back_as_the_old_one_with_the_entry_set_and_its_comments_kept(poses, flow, key, entries):
    lines = ["# head", "name: arm"]
    if poses:
        lines.append("poses:  # the section")
        for name, joints in poses.items():
            lines.append(f"  # before {name}")
            if flow:
                lines.append(f"  {q(name)}: {{{', '.join(f'{q(j)}: {format_scalar(v)}' for j, v in joints.items())}}}")
            else:
                lines.append(f"  {q(name)}:")
                lines.extend(f"    {q(j)}: {format_scalar(v)}" for j, v in joints.items())
    lines += ["# tail", "tail: 1", ""]
    doc = "\n".join(lines)
    got = set_entry(doc, "poses", key, entries)
    want = {**poses, key: entries}
    assert yaml.safe_load(got) == {"name": "arm", **({"poses": want}), "tail": 1}
    kept = [ln for ln in doc.splitlines() if ln.lstrip().startswith("#")]
    assert [ln for ln in got.splitlines() if ln.lstrip().startswith("#")] == kept
