"""Golden-output tests of the commands over the pure core: whole output, fixed width, no colour.

Regenerate with ``python -m pytest --update-golden`` and review ``git diff tests/golden``.
"""

from __future__ import annotations

import json

import pytest

SHIPPED = ["configs/sherpa-arm.yaml", "configs/seed-d1.yaml", "configs/appendix-c/example1.yaml",
           "configs/appendix-c/example2.yaml", "configs/appendix-c/example3.yaml"]


def _slug(path: str) -> str:
    return path.removeprefix("configs/").removesuffix(".yaml").replace("/", "-")


CASES = (
    [(f"config-check-{_slug(p)}", ["config", "check", p]) for p in SHIPPED]
    + [(f"config-check-{_slug(p)}-json", ["--json", "config", "check", p]) for p in SHIPPED[:2]]
    + [(f"limits-show-{_slug(p)}", ["--config", p, "limits", "show"]) for p in SHIPPED]
    + [
        ("limits-show-example3-json", ["--config", "configs/appendix-c/example3.yaml", "--json", "limits", "show"]),
        ("limits-show-arm-select", ["limits", "show", "shoulder_pitch", "elbow_pitch"]),
        ("limits-show-arm-json-elbow", ["--json", "limits", "show", "elbow_1a"]),
        ("diffdrive-limits-arm", ["diffdrive", "limits", "shoulder_diff"]),
        ("diffdrive-limits-arm-json", ["--json", "diffdrive", "limits", "shoulder_pitch"]),
        ("diffdrive-limits-example3", ["--config", "configs/appendix-c/example3.yaml", "diffdrive", "limits", "pair1"]),
        ("diffdrive-limits-seed-d1", ["--config", "configs/seed-d1.yaml", "diffdrive", "limits", "node1"]),
        ("diffdrive-convert-joints", ["diffdrive", "convert", "shoulder_diff", "--sigma", "100", "--delta", "-40"]),
        ("diffdrive-convert-motors-json", ["--json", "diffdrive", "convert", "shoulder_diff",
                                           "--motor-a", "30", "--motor-b", "70"]),
        ("diffdrive-convert-rad", ["diffdrive", "convert", "shoulder_diff", "--unit", "rad",
                                   "--sigma", "0.5", "--delta", "0.25"]),
        ("diffdrive-convert-rad-parity", ["diffdrive", "convert", "shoulder_diff", "--unit", "rad",
                                          "--sigma", "0.5", "--delta", "0.2094"]),
        ("diffdrive-convert-outside", ["diffdrive", "convert", "shoulder_diff", "--sigma", "3000", "--delta", "0"]),
        ("config-convert-seed-d1", ["config", "convert", "configs/seed-d1.yaml"]),
        ("help", ["--help"]),
        ("limits-help", ["limits", "show", "--help"]),
    ]
)


@pytest.mark.golden
@pytest.mark.parametrize("name,args", CASES, ids=[c[0] for c in CASES])
def test_golden(cli, golden, name, args):
    result = cli(*args)
    assert "Traceback" not in result.stderr
    golden(f"{name}.txt", result.transcript())


def test_limits_json_has_the_documented_shape_and_the_seed_numbers(cli):
    result = cli("--config", "configs/appendix-c/example3.yaml", "--json", "limits", "show")
    assert result.exit_code == 0, result.stderr
    data = json.loads(result.stdout)
    assert [d["drive"] for d in data["drives"]] == ["drive1", "drive2"]
    for drive in data["drives"]:
        assert set(drive) == {"drive", "bus", "node", "params"}
        params = drive["params"]
        assert (params["VL[3]"], params["VH[3]"], params["LL[3]"], params["HL[3]"]) == (-190, 190, -205, 205)
        assert [params[f"IL[{n}]"] for n in range(1, 5)] == [21, 21, 21, 21]


def test_limits_example1_and_example2_numbers(cli):
    one = json.loads(cli("--config", "configs/appendix-c/example1.yaml", "--json", "limits", "show").stdout)
    p1 = one["drives"][0]["params"]
    assert (p1["LL[3]"], p1["HL[3]"], p1["VL[3]"], p1["VH[3]"], p1["IL[3]"], p1["IL[4]"]) == (-240, 240, -220, 220, 21, 21)
    two = json.loads(cli("--config", "configs/appendix-c/example2.yaml", "--json", "limits", "show").stdout)
    p2 = two["drives"][0]["params"]
    assert p2["IL[1]"] == 5 and p2["IL[3]"] == p2["IL[4]"] == 4  # example 1's stop switches cleared


def test_convert_output_loads_back_to_the_same_model(cli, tmp_path):
    from sherpa_cli.config import load_config

    result = cli("config", "convert", "configs/seed-d1.yaml")
    assert result.exit_code == 0, result.stderr
    native = tmp_path / "native.yaml"
    native.write_text(result.stdout)
    original, again = load_config("configs/seed-d1.yaml"), load_config(native)
    assert again.drives == original.drives and again.joints == original.joints and again.pairs == original.pairs


def test_default_config_comes_from_the_environment(cli, monkeypatch):
    monkeypatch.setenv("SHERPA_CONFIG", "configs/appendix-c/example1.yaml")
    result = cli("--json", "limits", "show")
    assert [d["drive"] for d in json.loads(result.stdout)["drives"]] == ["drive1"]


def test_version(cli):
    from sherpa_cli import __version__

    result = cli("--version")
    assert result.exit_code == 0 and result.stdout.strip() == f"sherpa-cli {__version__}"


def test_no_color_flag_and_env_give_plain_text(cli, monkeypatch):
    monkeypatch.delenv("NO_COLOR")
    monkeypatch.setenv("FORCE_COLOR", "1")
    monkeypatch.setenv("TERM", "xterm-256color")
    coloured = cli("limits", "show", "no_such_joint")
    plain = cli("--no-color", "limits", "show", "no_such_joint")
    assert plain.exit_code == coloured.exit_code == 2
    assert "\x1b[" not in plain.stderr and "no_such_joint" in plain.stderr
    assert "\x1b[" in coloured.stderr  # the flag, not the environment, made the difference
