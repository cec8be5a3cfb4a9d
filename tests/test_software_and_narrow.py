"""Tables at 80 columns; Appendix C's software side (Tables C.1/C.2) and a
config written back in the seed's D.1 format."""

from __future__ import annotations

import pytest
import yaml

from sherpa_cli.cli.output import fit_columns
from tests.conftest import ROOT

EXAMPLE1 = "configs/appendix-c/example1.yaml"
EXAMPLE2 = "configs/appendix-c/example2.yaml"
EXAMPLE3 = "configs/appendix-c/example3.yaml"
SEED_D1 = "configs/seed-d1.yaml"


@pytest.mark.golden
@pytest.mark.parametrize("name,args", [
    ("limits-show-software-example1", ["--config", EXAMPLE1, "limits", "show", "--software"]),
    ("limits-show-software-example3", ["--config", EXAMPLE3, "limits", "show", "--software"]),
    ("limits-show-software-seed-d1-json", ["--config", SEED_D1, "--json", "limits", "show", "--software"]),
    ("config-convert-rosparam-seed-d1", ["config", "convert", "--to", "rosparam", SEED_D1]),
    ("config-convert-rosparam-example3", ["config", "convert", "--to", "rosparam", EXAMPLE3]),
])
def test_software_side_golden(cli, golden, name, args):
    r = cli(*args)
    assert r.exit_code == 0, r.stderr
    golden(f"{name}.txt", r.transcript())


def test_table_c1_and_c2_values(cli):
    import json

    r = cli("--config", EXAMPLE1, "--json", "limits", "show", "--software")
    (entry,) = json.loads(r.stdout)["joints"]
    # Table C.1
    assert entry["params"] == {"cpr": 600, "pos_min": -220, "pos_max": 220, "pos_margin": 30, "cal_speed": -50,
                               "cal_pos": -220, "cal_sw_L": 3, "cal_sw_H": 4}
    # Example 2: cal_sw_L 1, no cal_sw_H, cal_pos 20
    r = cli("--config", EXAMPLE2, "--json", "limits", "show", "--software")
    params = json.loads(r.stdout)["joints"][0]["params"]
    assert (params["cal_sw_L"], params.get("cal_sw_H"), params["cal_pos"]) == (1, None, 20)
    # Table C.2
    r = cli("--config", EXAMPLE3, "--json", "limits", "show", "--software")
    params = json.loads(r.stdout)["joints"][0]["params"]
    table_c2 = {"cpr": 600, "pos_min": -220, "pos_max": 220, "pos_margin": 30, "pos_min_dd": -160,
                "pos_max_dd": 160, "pos_margin_dd": 10, "cal_pos": -220, "cal_sw_L": 1, "cal_sw_H": 2,
                "cal_sw_dd_L": 3, "cal_sw_dd_H": 4}
    assert {k: params[k] for k in table_c2} == table_c2


def test_software_filter_and_unknown_name(cli):
    r = cli("limits", "show", "--software", "elbow_pitch", "shoulder_roll")
    assert r.exit_code == 0
    assert "joint elbow_pitch" in r.stdout and "pair shoulder_diff" in r.stdout and "wrist_1" not in r.stdout
    r = cli("limits", "show", "--software", "nope")
    assert r.exit_code == 2 and "unknown joint, drive or pair: nope" in r.stderr


def _convert_back(cli, tmp_path, source: str):
    from sherpa_cli.config import load_config

    r = cli("config", "convert", "--to", "rosparam", source)
    assert r.exit_code == 0, r.stderr
    written = tmp_path / "back" / source.rsplit("/", 1)[-1]
    written.parent.mkdir(exist_ok=True)
    written.write_text(r.stdout)
    return load_config(ROOT / source), load_config(written)


def test_seed_d1_round_trip(cli, tmp_path):
    from sherpa_cli.config import dump_native

    original, again = _convert_back(cli, tmp_path, SEED_D1)
    # the same arm, line for line (the native dump names its source on its first line only)
    assert dump_native(again).splitlines()[1:] == dump_native(original).splitlines()[1:]
    # ... and the same D.1 values as the seed's file, node for node
    seed = yaml.safe_load((ROOT / SEED_D1).read_text())["ros_can_interface"]
    back = yaml.safe_load(cli("config", "convert", "--to", "rosparam", SEED_D1).stdout)["ros_can_interface"]
    for key in ("interfaces", "send_interval", "scheduler_interval", "queue_size"):
        assert back[key] == seed[key]
    for k, node in seed["nodes"].items():
        assert {key: v for key, v in back["nodes"][k].items() if key != "topics"} == \
            {key: v for key, v in node.items() if key != "topics"}


def test_native_to_rosparam_keeps_the_software_side(cli, tmp_path):
    from sherpa_cli.config.software import software_params

    for source in (EXAMPLE1, EXAMPLE3, "configs/sherpa-arm.yaml"):
        original, again = _convert_back(cli, tmp_path, source)
        assert [e.params for e in software_params(again)] == [e.params for e in software_params(original)]
    r = cli("config", "convert", "--to", "rosparam", "configs/sherpa-arm.yaml")
    assert "the rosparam format has no overshoot" in r.stderr  # what it cannot hold is said, once per kind
    assert len(r.stderr.splitlines()) <= 6


def test_convert_to_unknown_format(cli):
    r = cli("config", "convert", "--to", "xml", SEED_D1)
    assert r.exit_code == 2 and "--to xml: expected native or rosparam" in r.stderr


# ----------------------------------------------------------------------------- 80 columns

def test_fit_columns_drops_by_priority_never_breaks_words():
    cols = ["drive", "bus:node", "model", "motor", "moves"]
    rows = [["shoulder_1a", "can0:10", "whistle-10/60", "kollmorgen-rbe-02110-a", "shoulder_yaw_stiffness"]]
    assert fit_columns(cols, rows, 100) == [0, 1, 2, 3, 4]
    assert fit_columns(cols, rows, 80) == [0, 1, 2, 3]  # default: the last column goes first ...
    assert fit_columns(cols, rows, 80, drop=(3, 2)) == [0, 1, 2, 4]
    assert fit_columns(cols, rows, 60, drop=(3, 2)) == [0, 1, 4]  # ... or in the given order
    assert fit_columns(cols, rows, 10) == [0]  # the name always stays


NARROW = [
    ("config-check-sherpa-arm-80", ["config", "check"]),
    ("limits-show-software-example3-80", ["--config", EXAMPLE3, "limits", "show", "--software"]),
    ("limits-show-arm-select-80", ["limits", "show", "shoulder_pitch"]),
]


@pytest.mark.golden
@pytest.mark.parametrize("name,args", NARROW, ids=[n for n, _ in NARROW])
def test_tables_at_80_columns_golden(cli, golden, monkeypatch, name, args):
    monkeypatch.setenv("COLUMNS", "80")
    r = cli(*args)
    assert r.exit_code == 0, r.stderr
    _no_broken_words(r.stdout)
    golden(f"{name}.txt", r.transcript())


@pytest.mark.golden
@pytest.mark.realbus
@pytest.mark.parametrize("name,args", [
    ("monitor-once-80", ["monitor", "--once"]),
    ("identify-sim-80", ["identify", "elbow_1a"]),
])
def test_live_tables_at_80_columns_golden(arm_cli, golden, monkeypatch, name, args):
    monkeypatch.setenv("COLUMNS", "80")
    r = arm_cli(*args)
    assert r.exit_code == 0, r.stderr
    _no_broken_words(r.stdout)
    golden(f"{name}.txt", r.transcript())


@pytest.mark.golden
def test_commission_at_80_columns_golden(cli, golden, monkeypatch, tmp_path):
    monkeypatch.setenv("COLUMNS", "80")
    monkeypatch.setenv("SHERPA_FAKE_STEP_SECONDS", "0.5")
    r = cli("--sim", "commission", "--apply", "--yes", "--set", f"backup={tmp_path / 'b.yaml'}")
    assert r.exit_code == 0, r.stdout
    assert all(len(line) <= 80 for line in r.stdout.splitlines()
               if not line.startswith(("every drive", "backup from before this run: ")))  # a path is not folded
    _no_broken_words(r.stdout)
    golden("commission-arm-apply-80.txt", r.transcript().replace(str(tmp_path), "<tmp>"))


def _known_words() -> set[str]:
    """Identifiers of the bundled arm (names with '_', '-' or digits) and long header words."""
    import re

    from sherpa_cli.config import load_config

    cfg = load_config(ROOT / "configs/sherpa-arm.yaml")
    words = {*cfg.drives, *cfg.joints, *cfg.pairs, *(d.model for d in cfg.drives.values() if d.model),
             *(d.motor for d in cfg.drives.values() if d.motor)}
    return {w for w in words if re.search(r"[_\d-]", w)} | {"operational", "heartbeat"}


def _no_broken_words(text: str) -> None:
    """No known name is cut: a token that is only the start of a name (and no name itself) is a fold."""
    words = _known_words()
    for line in text.splitlines():
        for token in (t.strip(",()") for t in line.split()):
            if len(token) >= 3 and token not in words:
                cut = [w for w in words if w.startswith(token)]
                assert not cut, f"{cut[0]!r} is broken in the line {line!r}"
