"""dump-params and params diff: the dump file format, the diff rules, end to end on the simulated arm."""

from __future__ import annotations

import json
import re
import struct
from datetime import UTC
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sherpa_cli.bus.session import ArmSession
from sherpa_cli.config import load_config
from sherpa_cli.errors import CommunicationError, ConfigError, UsageError
from sherpa_cli.joints.limits import derive_drive_params
from sherpa_cli.ops import params_diff as pd
from sherpa_cli.ops.params_file import (
    IDENTITY_KEYS,
    DriveDump,
    ParamDump,
    dump_from_text,
    dump_to_text,
    read_dump,
    write_dump,
)
from sherpa_cli.ops.params_read import dump_meta, dump_params, read_live
from sherpa_cli.sim.arm import SimArm

ARM = "configs/sherpa-arm.yaml"
DATE = "2024-05-02T10:00:00Z"

IDENTITY = {"device_type": 0x20192, "vendor_id": 0x9A, "product_code": 0x10100, "revision": 0x103E8,
            "serial": 0x5A00010A, "device_name": "Whistle 10/60", "hardware_version": "0x1FF6B",
            "software_version": "Whistle 1.1.10.4 SIM"}


def _dump(date: str = DATE, **params) -> ParamDump:
    meta = {"tool": "sherpa-cli", "tool_version": "0.1.0", "config": ARM, "config_sha256": "ab" * 32, "date": date}
    d = DriveDump("elbow_1a", "can1", 40, dict(IDENTITY), {"UM": 5, "AC": 1500, "CL[1]": 3.0, **params},
                  {"CA[18]": "error 3: bad index"})
    return ParamDump(meta, {"elbow_1a": d})


def _float32(x: float) -> float:
    return struct.unpack("<f", struct.pack("<f", x))[0]


# --------------------------------------------------------------------------- the file format

def test_text_round_trips_and_is_stable():
    dump = _dump(**{"IL[10]": 4, "IL[2]": 21})
    text = dump_to_text(dump)
    assert dump_from_text(text, "f.yaml") == dump
    # keys sorted by letters then numeric index, whatever order they were read in
    params = text.split("params:\n", 1)[1].split("unreadable:", 1)[0]
    assert [line.split(":")[0].strip() for line in params.splitlines() if line.strip()] == \
        ["AC", "CL[1]", "IL[2]", "IL[10]", "UM"]
    assert text.startswith("# sherpa-cli parameter dump")


def test_two_dumps_differ_only_in_the_header_block():
    a = dump_to_text(_dump("2024-05-02T10:00:00Z")).splitlines()
    b = dump_to_text(_dump("2025-01-01T00:00:00Z")).splitlines()
    changed = [i for i, (x, y) in enumerate(zip(a, b, strict=True)) if x != y]
    assert len(a) == len(b) and len(changed) == 1
    assert a.index("drives:") > changed[0] > a.index("meta:")


values = st.one_of(st.integers(-2**31, 2**31 - 1),
                   st.floats(allow_nan=False, allow_infinity=False, width=32))
keys = st.sampled_from(["UM", "AC", "DC", "LL[2]", "HL[3]", "VL[3]", "CL[1]", "PL[1]", "PL[2]", "IL[1]", "IL[10]",
                        "CA[18]"])
names = st.text(alphabet="abcdefghijklmnopqrstuvwxyz0123456789_-", min_size=1, max_size=12).map(lambda s: "d" + s)
texts = st.one_of(st.none(), st.text(min_size=1, max_size=30).filter(lambda s: s.strip() == s and s))


@settings(max_examples=150, deadline=None)
@given(st.dictionaries(names, st.tuples(st.dictionaries(keys, values), st.integers(1, 127),
                                        st.dictionaries(keys, st.text(min_size=1, max_size=20)),
                                        st.lists(texts, min_size=3, max_size=3)), max_size=4))
def test_any_dump_round_trips(drives):
    built = {}
    for name, (params, node, unreadable, (dev, hw, sw)) in drives.items():
        unreadable = {k: v for k, v in unreadable.items() if k not in params}
        identity = {k: None for k in IDENTITY_KEYS} | {"device_name": dev, "hardware_version": hw,
                                                      "software_version": sw, "serial": node * 7}
        built[name] = DriveDump(name, "can0", node, identity, params, unreadable)
    dump = ParamDump({"tool": "sherpa-cli", "tool_version": "0.1.0", "config": None, "config_sha256": None,
                      "date": DATE}, built)
    text = dump_to_text(dump)
    back = dump_from_text(text, "x.yaml")
    assert back == dump
    assert dump_to_text(back) == text


def test_write_is_atomic(tmp_path, monkeypatch):
    target = tmp_path / "arm.yaml"
    target.write_text("old contents\n")

    def crash(fd):
        raise OSError("disk full")

    monkeypatch.setattr("sherpa_cli.output_files.os.fsync", crash)
    with pytest.raises(UsageError, match="disk full; nothing was written"):
        write_dump(target, _dump())
    assert target.read_text() == "old contents\n"
    assert [p.name for p in tmp_path.iterdir()] == ["arm.yaml"]  # no temporary file left behind


BAD_FILES = [
    ("syntax", "meta: {date: x\ndrives: {}\n", r"x\.yaml:2: .*YAML syntax error"),
    ("not-a-mapping", "- 1\n- 2\n", r"x\.yaml:1: expected a parameter dump"),
    ("no-drives", "meta: {date: x}\n", r"x\.yaml:1: .*missing required key 'drives'"),
    ("no-meta", "drives: {}\n", r"x\.yaml:1: .*missing required key 'meta'"),
    ("value-is-text", "meta: {}\ndrives:\n  a:\n    bus: can0\n    node: 3\n    params:\n      AC: fast\n",
     r"x\.yaml:7: drives\.a\.params\.AC: expected a number, got the string 'fast'"),
    ("bad-key", "meta: {}\ndrives:\n  a:\n    bus: can0\n    node: 3\n    params:\n      LL[9]: 1\n",
     r"x\.yaml:7: drives\.a\.params\.LL\[9\]: bad parameter key: LL\[9\]: index outside 1\.\.3"),
    ("unknown-drive-key", "meta: {}\ndrives:\n  a:\n    bus: can0\n    nodes: 3\n",
     r"x\.yaml:5: drives\.a\.nodes: unknown key 'nodes'.*did you mean 'node'"),
    ("node-range", "meta: {}\ndrives:\n  a:\n    bus: can0\n    node: 300\n",
     r"x\.yaml:5: drives\.a\.node: node id must be 1\.\.127"),
    ("config-file", "name: arm\nbuses: {}\n", r"x\.yaml:1: name: unknown key 'name' in the top level"),
]


@pytest.mark.parametrize("name,text,pattern", BAD_FILES, ids=[b[0] for b in BAD_FILES])
def test_bad_dump_files_name_file_line_and_key(tmp_path, name, text, pattern):
    path = tmp_path / "x.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        read_dump(path)
    assert re.search(pattern, str(info.value)), str(info.value)


def test_missing_dump_file(tmp_path):
    with pytest.raises(ConfigError, match=re.escape("nope.yaml: dump file not found")):
        read_dump(tmp_path / "nope.yaml")


def test_dump_date_comes_from_the_environment_or_the_clock():
    from datetime import datetime

    cfg = load_config(ARM)
    assert dump_meta(cfg, environ={"SHERPA_DUMP_DATE": DATE})["date"] == DATE

    def fixed() -> datetime:
        return datetime(2024, 1, 2, 3, 4, 5, tzinfo=UTC)

    meta = dump_meta(cfg, fixed, environ={})
    assert meta["date"] == "2024-01-02T03:04:05Z"
    import hashlib
    assert meta["config_sha256"] == hashlib.sha256(Path(ARM).read_bytes()).hexdigest()
    assert meta["config"] == ARM


# --------------------------------------------------------------------------- diff rules

@settings(max_examples=300, deadline=None)
@given(st.floats(min_value=-1e6, max_value=1e6, allow_nan=False).filter(lambda x: abs(x) > 1e-3))
def test_a_float32_round_trip_compares_equal(x):
    assert pd.same_value(x, _float32(x))
    assert not pd.same_value(x, x * (1 + 1e-5))


def test_int_compare_is_exact():
    assert pd.same_value(1000, 1000)
    assert not pd.same_value(1000, 1001)
    assert pd.same_value(5, 5.0)  # config derives CL[1]=5.0 from "5"; the drive may say either


def _side(label, params, unreadable=None, partial=False, kind="file"):
    return pd.Side(label, kind, {"d": pd.SideDrive("can0", 1, params, unreadable or {})}, partial)


def test_config_side_covers_only_what_it_derives():
    config = _side("config", {"AC": 1000, "CL[1]": 2.3}, partial=True, kind="config")
    live = _side("live", {"AC": 1000, "CL[1]": _float32(2.3), "UM": 5}, {"CA[18]": "error 3: bad index"})
    report = pd.diff_sides(config, live, ["d"])
    assert report.differences == 0
    assert [r.key for r in report.drives[0].rows] == ["AC", "CL[1]"]


def test_rows_only_on_one_side_and_unreadable_values_are_differences():
    a = _side("a.yaml", {"AC": 1, "DC": 2, "UM": 5}, {"CA[18]": "error 3: bad index"})
    b = _side("b.yaml", {"AC": 1, "SD": 3, "UM": 5, "CA[18]": 4096})
    rows = {r.key: r.status for r in pd.diff_sides(a, b, ["d"]).drives[0].rows}
    assert rows == {"AC": pd.SAME, "CA[18]": pd.DIFFERS, "DC": pd.ONLY_A, "SD": pd.ONLY_B, "UM": pd.SAME}


def test_a_drive_on_one_side_only_counts_once():
    a = pd.Side("a", "file", {"x": pd.SideDrive("can0", 1, {"AC": 1}), "y": pd.SideDrive("can0", 2, {"AC": 1})})
    b = pd.Side("b", "file", {"x": pd.SideDrive("can0", 1, {"AC": 1})})
    report = pd.diff_sides(a, b, ["x", "y"])
    assert [(d.drive, d.only_in) for d in report.drives] == [("x", None), ("y", "A")]
    assert report.differences == 1


# --------------------------------------------------------------------------- ops on the simulated arm

COMMISSIONED = ["shoulder_1b", "shoulder_2a", "shoulder_2b", "elbow_1a"]  # switches, a pair, a plain joint


def test_commissioned_drives_match_the_config_and_one_change_shows_as_one(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "state"))
    cfg = load_config(ARM)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as session:
        from sherpa_cli.elmo.commands import parse_param_key
        from sherpa_cli.ops.params_read import ref_of

        for name in COMMISSIONED:  # what commissioning does: motor off, then every derived value
            client = session.client(ref_of(cfg, name))
            client.nmt_start()
            client.motor_off()
            for key, value in derive_drive_params(cfg, name).params.items():
                client.set(*parse_param_key(key), value)
        dump = dump_params(session, COMMISSIONED)
        write_dump(tmp_path / "after.yaml", dump)
        session.client(ref_of(cfg, "elbow_1a")).set("DC", 0, 1234)
        changed = read_live(session, COMMISSIONED)

    config, _ = pd.config_side(cfg, COMMISSIONED)
    saved, _ = pd.file_side(tmp_path / "after.yaml", cfg)
    clean = pd.diff_sides(saved, config, COMMISSIONED)
    assert clean.differences == 0
    assert sum(len(d.rows) for d in clean.drives) == sum(len(derive_drive_params(cfg, n).params)
                                                         for n in COMMISSIONED)
    live = pd.dump_side("live", ParamDump({}, changed), kind="live")
    report = pd.diff_sides(config, live, COMMISSIONED)
    differing = [(d.drive, r.key, r.a, r.b) for d in report.drives for r in d.rows if r.status != pd.SAME]
    assert differing == [("elbow_1a", "DC", 1500, 1234)]
    # file vs live sees the same single change, and nothing of UM/CA[18]/IL that config does not cover
    assert [(d.drive, r.key) for d in pd.diff_sides(saved, live, COMMISSIONED).drives for r in d.rows
            if r.status != pd.SAME] == [("elbow_1a", "DC")]


def test_a_drive_dying_half_way_names_itself(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "state"))
    cfg = load_config(ARM)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg), buses=["can1"]) as session:
        def progress(drive, what):
            if (drive, what) == ("elbow_1b", "LL[3]"):
                with session.sim.lock:
                    session.sim.drives["elbow_1b"]._dead = True  # power stage and CPU gone mid-dump

        with pytest.raises(CommunicationError) as info:
            dump_params(session, ["elbow_1a", "elbow_1b", "wrist_1a"], progress)
    assert "elbow_1b (node 41)" in str(info.value)
    assert "LL[3]" in str(info.value)


# --------------------------------------------------------------------------- CLI, end to end

def _clean(text: str, tmp_path: Path) -> str:
    """The parts that differ per run or transport: tmp paths, the config file and its hash."""
    text = text.replace(str(tmp_path), "<tmp>")
    text = re.sub(r"^(  config: ).*", r"\1<config>", text, flags=re.M)
    text = re.sub(r"^(  config_sha256: )[0-9a-f]{64}", r"\1<sha256>", text, flags=re.M)
    text = re.sub(r'("config": )"[^"]*"', r'\1"<config>"', text)
    return re.sub(r'("config_sha256": )"[0-9a-f]{64}"', r'\1"<sha256>"', text)


@pytest.fixture
def dump_date(monkeypatch):
    monkeypatch.setenv("SHERPA_DUMP_DATE", DATE)


ARM_CASES = [
    ("dump-params-elbow", ["dump-params", "elbow_pitch", "wrist_3b"]),
    ("dump-params-json", ["--json", "dump-params", "shoulder_diff"]),
    ("params-diff-config-live", ["params", "diff", "config", "live", "-t", "elbow_1a", "-t", "shoulder_1b"]),
    ("params-diff-config-live-json", ["--json", "params", "diff", "config", "-t", "shoulder_2a"]),
    ("params-diff-config-live-only", ["params", "diff", "config", "--only-differences", "-t", "wrist_3a"]),
]


@pytest.mark.golden
@pytest.mark.realbus
@pytest.mark.parametrize("name,args", ARM_CASES, ids=[c[0] for c in ARM_CASES])
def test_params_on_the_arm_golden(arm_golden, dump_date, tmp_path, name, args):
    arm_golden(name, args, clean=lambda text: _clean(text, tmp_path))


@pytest.mark.golden
@pytest.mark.realbus
@pytest.mark.parametrize("json_flag", [False, True], ids=["text", "json"])
def test_params_diff_file_vs_live_golden(arm_cli, golden, dump_date, tmp_path, json_flag):
    path = tmp_path / "arm.yaml"
    first = arm_cli("dump-params", "-o", str(path), "elbow_1a", "elbow_1b")
    assert first.exit_code == 0, first.stderr
    assert first.stdout == f"wrote 2 drives to {path}\n"
    result = arm_cli(*(["--json"] if json_flag else []), "params", "diff", str(path), "live")
    assert result.exit_code == 0
    golden(f"params-diff-file-live{'-json' if json_flag else ''}.txt", _clean(result.transcript(), tmp_path))


def test_dump_to_file_equals_stdout_and_header_is_exact(cli, dump_date, tmp_path):
    import hashlib

    path = tmp_path / "sub" / "arm.yaml"
    assert cli("--sim", "dump-params", "-o", str(path), "wrist_2a").exit_code == 0
    shown = cli("--sim", "dump-params", "wrist_2a")
    assert shown.exit_code == 0 and shown.stdout == path.read_text()
    meta = read_dump(path).meta
    assert meta == {"tool": "sherpa-cli", "tool_version": __import__("sherpa_cli").__version__, "config": ARM,
                    "config_sha256": hashlib.sha256(Path(ARM).read_bytes()).hexdigest(), "date": DATE}


def test_saved_value_persists_and_diff_shows_exactly_it(cli):
    # AC=1500 is what the config derives for elbow_1a: after SV it is the one derived value the
    # factory drive already matches, so every other derived parameter (factory value) differs.
    assert cli("--sim", "cmd", "elbow_1a", "AC=1500", "SV", "--apply", "--raw-save").exit_code == 0
    result = cli("--sim", "--json", "params", "diff", "config", "live", "-t", "elbow_pitch")
    assert result.exit_code == 1
    report = json.loads(result.stdout)
    rows = {r["param"]: (r["a"], r["b"], r["status"]) for r in report["drives"][0]["params"]}
    derived = derive_drive_params(load_config(ARM), "elbow_1a").params
    assert set(rows) == set(derived)
    assert rows["AC"] == (1500, 1500, "same")
    factory = {"DC": 100000, "LL[2]": -1000000, "HL[2]": 1000000, "VL[2]": -500000, "VH[2]": 500000,
               "LL[3]": -10**9, "HL[3]": 10**9, "VL[3]": -10**9, "VH[3]": 10**9, "CL[1]": 5.0, "PL[1]": 10.0,
               "PL[2]": 3}
    assert {k: (a, b) for k, (a, b, s) in rows.items() if s == "differs"} == \
        {k: (derived[k], v) for k, v in factory.items()}
    # the factory drive's inputs already have no function (IL = il_codes.unused), as the config derives
    assert report["differences"] == len([k for k in derived if not k.startswith("IL[")]) - 1


def test_dump_with_a_drive_dying_half_way_writes_nothing(cli, tmp_path, monkeypatch):
    from sherpa_cli.ops import params_read
    from sherpa_cli.sim.arm import SimArm

    arms = []
    original_factory = SimArm.for_session.__func__

    def capture(cls, cfg, channels):
        arm = original_factory(cls, cfg, channels)
        arms.append(arm)
        return arm

    original_read = params_read.read_params

    def read_and_die(client, keys, progress=None, drive=""):
        def kill(d, key):
            if (d, key) == ("wrist_1b", "VL[3]"):
                with arms[-1].lock:
                    arms[-1].drives["wrist_1b"]._dead = True
        return original_read(client, keys, kill, drive)

    monkeypatch.setattr(SimArm, "for_session", classmethod(capture))
    monkeypatch.setattr(params_read, "read_params", read_and_die)
    existing = tmp_path / "existing.yaml"
    existing.write_text("precious\n")
    fresh = tmp_path / "fresh.yaml"
    for target in (existing, fresh):
        result = cli("--sim", "dump-params", "-o", str(target))
        assert result.exit_code == 3, result.stderr
        assert "error: wrist_1b (node 51): no answer to VL[3]" in result.stderr
        assert "Traceback" not in result.stderr and result.stdout == ""
    assert existing.read_text() == "precious\n"
    assert not fresh.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["existing.yaml", "state"]


def test_dump_of_a_dead_drive_from_the_config_sim_section(cli, tmp_path):
    config = tmp_path / "arm.yaml"
    config.write_text(Path(ARM).read_text() + "\nsim:\n  drives:\n    wrist_3b: {die_at: 0.0}\n")
    out = tmp_path / "dump.yaml"
    result = cli("--config", str(config), "--sim", "dump-params", "-o", str(out), "wrist_3a", "wrist_3b")
    assert result.exit_code == 3
    assert "wrist_3b (node 71)" in result.stderr and "Traceback" not in result.stderr
    assert not out.exists()


BAD_CLI = [
    ("dump-params-unknown-target", ["--sim", "dump-params", "elbow"]),
    ("params-diff-unknown-target", ["--sim", "params", "diff", "config", "-t", "wrist9"]),
    ("params-diff-live-live", ["--sim", "params", "diff", "live", "live"]),
    ("params-diff-missing-file", ["--sim", "params", "diff", "{tmp}/none.yaml"]),
    ("params-diff-yaml-error", ["--sim", "params", "diff", "{tmp}/broken.yaml", "config"]),
    ("params-diff-wrong-shape", ["--sim", "params", "diff", "{tmp}/shape.yaml", "config"]),
    ("params-diff-foreign-drive", ["--sim", "params", "diff", "{tmp}/foreign.yaml", "config"]),
]

BAD_TEXTS = {
    "broken.yaml": "meta: {}\ndrives:\n  elbow_1a:\n    bus: can1\n    node: [40\n",
    "shape.yaml": "meta: {}\ndrives:\n  elbow_1a:\n    bus: can1\n    node: 40\n    params: [AC, 1000]\n",
    "foreign.yaml": "meta: {}\ndrives:\n  elbow_1a: {bus: can1, node: 40, params: {AC: 1}}\n"
                    "  gripper: {bus: can3, node: 90, params: {AC: 1}}\n",
}


@pytest.mark.golden
@pytest.mark.parametrize("name,args", BAD_CLI, ids=[c[0] for c in BAD_CLI])
def test_bad_inputs_golden(cli, golden, tmp_path, name, args):
    for file, text in BAD_TEXTS.items():
        (tmp_path / file).write_text(text)
    result = cli(*(a.replace("{tmp}", str(tmp_path)) for a in args))
    assert result.exit_code == 2
    assert "Traceback" not in result.stderr and result.stdout == ""
    golden(f"{name}.txt", _clean(result.transcript(), tmp_path))


def test_dump_to_an_unwritable_path_is_one_clear_line(cli, tmp_path):
    blocker = tmp_path / "a-file"
    blocker.write_text("x")
    target = blocker / "dump.yaml"  # its directory cannot exist: a file is in the way
    result = cli("--sim", "dump-params", "elbow_1a", "-o", str(target))
    assert result.exit_code == 2 and "Traceback" not in result.stderr
    assert result.stderr.startswith(f"error: --output {target}: cannot write the dump: ")
    assert blocker.read_text() == "x"


def test_params_diff_of_an_empty_dump_with_the_live_drives_reads_nothing(cli, tmp_path):
    """A dump that names no drive, diffed with `live`: the empty drive list reached the API, which
    takes an empty list for every drive, and the command failed on a bus it had not opened (exit 2)."""
    empty = tmp_path / "empty.yaml"
    empty.write_text("meta: {}\ndrives: {}\n", encoding="utf-8")
    result = cli("--sim", "params", "diff", str(empty), "live")
    assert result.exit_code == 0, result.transcript()
    assert "no difference" in result.stdout and "0 drives" in result.stdout, result.transcript()
