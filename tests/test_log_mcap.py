"""MCAP: a `log record` MCAP read back with the mcap reader and decoded
with mcap-ros2-support equals the CSV of the same run; a `log capture` MCAP decodes like the
candump .log of the same frames; without the robotics extra, one line says what to install."""

from __future__ import annotations

import csv
import json
import math
import subprocess
import sys
import threading
import time
import uuid

import can
import pytest
from conftest import ROOT
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from sherpa_cli.config import load_config
from sherpa_cli.joints.units import counts_to_rad
from sherpa_cli.log.capture import capture, channel_for, read_frames
from sherpa_cli.log.mcap_out import FrameWriter
from tests.test_log_decode import BUSES, T0, known_sequence

ARM = ROOT / "configs/sherpa-arm.yaml"
EXTRA = "pip install 'sherpa-cli[robotics]'"


def _decoded(path):
    with path.open("rb") as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        messages = [(channel.topic, schema.name, message.log_time, ros)
                    for schema, channel, message, ros in reader.iter_decoded_messages()]
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
        profile = reader.get_header().profile
    return messages, metadata, profile


def _csv(path):
    with path.open(newline="") as fh:
        rows = list(csv.reader(fh))
    return rows[0], rows[1:]


def _cell(value: float, counts: bool = False) -> str:
    """A value as write_csv writes it (log/recording.py)."""
    if math.isnan(value):
        return ""
    return f"{value:.0f}" if counts else f"{value:.6g}"


# -- log record --------------------------------------------------------------------------------------

def test_record_mcap_equals_the_csv_of_the_same_run(cli, tmp_path):
    out_csv, out_mcap = tmp_path / "run.csv", tmp_path / "run.mcap"
    result = cli("--sim", "log", "record", "elbow_pitch", "shoulder_diff", "--rate", "100", "--for", "0.3",
                 "--current", "-o", str(out_csv), "-o", str(out_mcap))
    assert result.exit_code == 0, result.transcript()
    assert f"wrote {out_csv}" in result.stdout and f"wrote {out_mcap}" in result.stdout
    header, rows = _csv(out_csv)
    messages, metadata, profile = _decoded(out_mcap)
    assert profile == "ros2"
    zero = int(metadata["sherpa.recording"]["time_zero_ns"])
    names = ["elbow_pitch", "shoulder_pitch", "shoulder_roll"]  # config order; the pair's Σ and Δ joints
    drives = ["elbow_1a", "shoulder_2a", "shoulder_2b"]
    col = {name: i for i, name in enumerate(header)}
    # the recording's timestamps: time zero + time_s (the CSV's 6 decimals); a wall-time recording on a
    # loaded machine may miss a sample: a row with no joint (drive) value has no message, else one
    # (matched to a microsecond: the CSV's 6 decimals and the MCAP's nanoseconds round a time that ends
    # in ...5 each their own way)
    joints = [m for m in messages if m[0] == "/joint_states"]
    motors = [m for m in messages if m[0] == "/sherpa/motor_counts"]
    with_joint = [r for r in rows if any(r[col[f"{j}.pos_rad"]] for j in names)]
    with_drive = [r for r in rows if any(r[col[f"{d}.px"]] for d in drives)]
    assert len(with_joint) == len(joints) and len(with_drive) == len(motors)
    for kept, written in ((with_joint, joints), (with_drive, motors)):
        assert all(abs(float(r[0]) - (m[2] - zero) / 1e9) <= 1.5e-6 for r, m in zip(kept, written, strict=True))
    assert len(joints) > 0.5 * len(rows) > 0
    for row, message in zip(with_joint, joints, strict=True):
        _, schema, log_time, msg = message
        assert schema == "sensor_msgs/msg/JointState"
        assert msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec == log_time
        assert list(msg.name) == names
        assert [_cell(v) for v in msg.position] == [row[col[f"{j}.pos_rad"]] for j in names]
        assert [_cell(v) for v in msg.velocity] == [row[col[f"{j}.vel_rad_s"]] for j in names]
        # current of the plain joint; none for the Σ/Δ joints of a pair (NaN)
        assert _cell(msg.effort[0]) == row[col["elbow_pitch.cur_a"]] and all(math.isnan(v) for v in msg.effort[1:])
    for row, message in zip(with_drive, motors, strict=True):
        motor = message[3]
        assert motor.header.frame_id == "counts" and list(motor.name) == drives
        assert [_cell(v, counts=True) for v in motor.position] == [row[col[f"{d}.px"]] for d in drives]
    joints_in_order = [m for m in messages if m[0] == "/joint_states"]
    # the drives' status before and after, MO / SR / MF decoded
    status = [m for m in messages if m[0] == "/diagnostics"]
    assert len(status) == 2 and status[0][2] <= joints_in_order[0][2] and status[1][2] >= joints_in_order[-1][2]
    for _, schema, _, msg in status:
        assert schema == "diagnostic_msgs/msg/DiagnosticArray"
        assert [s.name for s in msg.status] == ["elbow_1a", "shoulder_2a", "shoulder_2b"]
        values = {kv.key: kv.value for kv in msg.status[0].values}
        assert values["MO"] == "0" and values["MF"] == "0x00000000" and values["SR"].startswith("0x")
        assert msg.status[0].level == 0 and msg.status[0].hardware_id == "can1:40"
    # the config's joint names and limits as metadata
    cfg = load_config(ARM)
    assert metadata["sherpa.config"]["joints"].split(",") == list(cfg.joints)
    assert metadata["sherpa.config"]["recorded_joints"].split(",") == names
    elbow = metadata["joint.elbow_pitch"]
    joint = cfg.joints["elbow_pitch"]
    assert elbow["role"] == "plain" and elbow["drive"] == "elbow_1a"
    assert float(elbow["normal_max_rad"]) == pytest.approx(counts_to_rad(joint.normal_range[1], joint.cpr))
    assert int(elbow["full_min_counts"]) == joint.pos_min
    assert metadata["sherpa.recording"]["source"] == "TPDO on SYNC"


def test_record_mcap_only_and_poll(cli, tmp_path):
    """An MCAP alone; `--poll` rows (one drive each) keep the other joints NaN, never a stale value."""
    out = tmp_path / "poll.mcap"
    result = cli("--sim", "log", "record", "elbow_pitch", "wrist_1", "--poll", "--for", "0.2", "-o", str(out))
    assert result.exit_code == 0, result.transcript()
    messages, metadata, _ = _decoded(out)
    joints = [m[3] for m in messages if m[0] == "/joint_states"]
    assert joints and metadata["sherpa.recording"]["source"] == "poll"
    assert all(sum(not math.isnan(v) for v in msg.position) == 1 for msg in joints)


def test_step_writes_one_mcap_with_the_metrics(cli, tmp_path):
    out = tmp_path / "step.mcap"
    result = cli("--sim", "--config", "tests/data/step-arm.yaml", "log", "step", "arm", "--position", "0.2",
                 "--rate", "500", "--for", "0.5", "-o", str(out), "--apply")
    assert result.exit_code == 0, result.transcript()
    assert f"mcap: {out}" in result.stdout and not (tmp_path / "step.mcap" / "recording.csv").exists()
    messages, metadata, _ = _decoded(out)
    metrics = [m for m in messages if m[0] == "/sherpa/step_metrics"]
    assert len(metrics) == 1 and metrics[0][1] == "std_msgs/msg/String"
    body = json.loads(metrics[0][3].data)
    assert body["joint"] == "arm" and body["mode"] == "position" and body["metrics"]["final"] > 0.1
    # t = 0 is the step's command: the metrics sit there, the recording starts 0.1 s before it
    zero = int(metadata["sherpa.recording"]["time_zero_ns"])
    first = min(m[2] for m in messages if m[0] == "/joint_states")
    assert metrics[0][2] == zero and first < zero


def test_step_mcap_counts_agree_everywhere(cli, tmp_path):
    """`log step -o x.mcap`: the samples the report prints are the /joint_states messages the file
    holds, and its metadata and embedded metrics say the same (they counted the whole recording,
    the stop and standstill after the step included, while the file holds the step only)."""
    out = tmp_path / "step.mcap"
    result = cli("--sim", "--config", "tests/data/step-arm.yaml", "log", "step", "arm", "--position", "0.2",
                 "--rate", "500", "--for", "0.5", "-o", str(out), "--apply")
    assert result.exit_code == 0, result.transcript()
    messages, metadata, _ = _decoded(out)
    states = [m for m in messages if m[0] == "/joint_states"]
    motors = [m for m in messages if m[0] == "/sherpa/motor_counts"]
    body = json.loads(next(m for m in messages if m[0] == "/sherpa/step_metrics")[3].data)
    line = next(x for x in result.stdout.splitlines() if x.startswith("arm (elbow)"))
    printed, of = (int(v) for v in line.rsplit("; ", 1)[1].removesuffix(" samples").split(" of "))
    assert printed == of == len(states) == len(motors), line  # nothing missing on stepped time
    assert int(metadata["sherpa.recording"]["samples"]) == body["samples"] == body["expected"] == len(states)


def test_the_metadata_counts_the_joint_states_the_file_holds_from_the_one_rule(tmp_path):
    """A row with a drive's current but no position (its TPDO3 came, its TPDO1 did not) has no
    /joint_states message: the metadata counted it all the same (the rows), log step's report
    counted PX cells -- three rules for one number. Now all take Recording.sample_rows."""
    from sherpa_cli.log.mcap_out import write_recording
    from sherpa_cli.log.recording import Recording

    cfg = load_config(ROOT / "tests" / "data" / "step-arm.yaml")
    nan = math.nan
    rec = Recording(times=[0.0, 0.002, 0.004], columns={
        "arm.pos_rad": [0.0, nan, 0.01], "arm.vel_rad_s": [0.0, nan, 0.1], "arm.cur_a": [0.5, 0.6, nan],
        "elbow.px": [0.0, nan, 10.0], "elbow.vx": [0.0, nan, 100.0], "elbow.iq_a": [0.5, 0.6, nan]})
    assert rec.sample_rows() == [0, 2]
    write_recording(tmp_path / "r.mcap", rec, cfg, time_zero_ns=10**18)
    messages, metadata, _ = _decoded(tmp_path / "r.mcap")
    states = [m for m in messages if m[0] == "/joint_states"]
    assert len(states) == int(metadata["sherpa.recording"]["samples"]) == 2


@pytest.mark.parametrize("args", [("--torque", "1", "--for", "1"), ("--velocity", "0.1", "--for", "1.5", "--hold", "0.5")])
def test_step_mcap_counts_agree_for_a_step_cut_by_time_and_one_held(cli, tmp_path, args):
    """The count printed, the /joint_states messages, the metadata and the embedded metrics, for a
    torque step that runs its time out and a velocity step held after settling (the bundled config's
    0.5 s settle window: the switch is in the file too)."""
    out = tmp_path / "step.mcap"
    result = cli("--sim", "log", "step", "elbow_pitch", *args, "--rate", "500", "-o", str(out), "--apply")
    assert result.exit_code == 0, result.transcript()
    messages, metadata, _ = _decoded(out)
    states = [m for m in messages if m[0] == "/joint_states"]
    body = json.loads(next(m for m in messages if m[0] == "/sherpa/step_metrics")[3].data)
    line = next(x for x in result.stdout.splitlines() if x.startswith("elbow_pitch (elbow_1a)"))
    printed = int(line.rsplit("; ", 1)[1].split(" of ")[0])
    assert printed == len(states) == int(metadata["sherpa.recording"]["samples"]) == body["samples"], line


# -- log capture / decode ----------------------------------------------------------------------------

def _write_known(path) -> None:
    writer = FrameWriter(path) if path.suffix == ".mcap" else can.Logger(str(path))
    with writer:
        for i, (bus, cob, data) in enumerate(known_sequence()):
            writer.on_message_received(can.Message(
                timestamp=T0 + i * 0.001, arbitration_id=cob, data=data, is_extended_id=False,
                channel=channel_for(path.suffix, bus, BUSES)))


def test_capture_mcap_decodes_to_the_same_text_as_the_log(cli, tmp_path):
    for suffix in (".log", ".mcap"):
        _write_known(tmp_path / f"bus{suffix}")
    log = cli("log", "decode", str(tmp_path / "bus.log"))
    mcap = cli("log", "decode", str(tmp_path / "bus.mcap"))
    assert mcap.exit_code == 0 and log.exit_code == 0, mcap.transcript()
    assert mcap.stdout == log.stdout and "EMCY 0x8110" in mcap.stdout
    as_json = cli("--json", "log", "decode", str(tmp_path / "bus.mcap"), "--kind", "emcy")
    assert as_json.stdout == cli("--json", "log", "decode", str(tmp_path / "bus.log"), "--kind", "emcy").stdout.replace(
        str(tmp_path / "bus.log"), str(tmp_path / "bus.mcap"))


def test_capture_mcap_has_one_channel_per_bus_with_the_documented_schema(tmp_path):
    tag = uuid.uuid4().hex[:8]
    channels = {name: f"mcapcap-{tag}-{name}" for name in BUSES}
    listen = {name: can.Bus(interface="virtual", channel=ch) for name, ch in channels.items()}
    send = {name: can.Bus(interface="virtual", channel=ch) for name, ch in channels.items()}
    try:
        for bus, cob, data in known_sequence():
            send[bus].send(can.Message(arbitration_id=cob, data=data, is_extended_id=False))
        path = tmp_path / "bus.mcap"
        result = capture(listen, path, BUSES, stop=threading.Event(), frame_limit=len(known_sequence()))
    finally:
        for bus in [*listen.values(), *send.values()]:
            bus.shutdown()
    assert result.frames == len(known_sequence())
    for bus in BUSES:
        assert [(f.can_id, f.data) for f in read_frames(path, BUSES) if f.bus == bus] == \
            [(cob, data) for b, cob, data in known_sequence() if b == bus]
    with path.open("rb") as fh:
        reader = make_reader(fh)
        summary = reader.get_summary()
        assert summary is not None
        topics = sorted(c.topic for c in summary.channels.values())
        assert topics == ["/can/can0", "/can/can1", "/can/can2"]
        schema = next(iter(summary.schemas.values()))
        assert (schema.name, schema.encoding) == ("sherpa.CanFrame", "jsonschema")
        assert {c.message_encoding for c in summary.channels.values()} == {"json"}
        first = next(reader.iter_messages(topics=["/can/can1"]))[2]
        assert json.loads(first.data) == {"bus": "can1", "id": 0x728, "extended": False, "remote": False,
                                          "error": False, "dlc": 1, "data": "00"}


def test_cli_capture_writes_mcap(cli, tmp_path):
    tag = uuid.uuid4().hex[:8]
    send = can.Bus(interface="virtual", channel=f"mcapcli-{tag}")
    done = threading.Event()

    def traffic():
        while not done.is_set():
            send.send(can.Message(arbitration_id=0x70A, data=b"\x05", is_extended_id=False))
            time.sleep(0.01)

    sender = threading.Thread(target=traffic, daemon=True)
    sender.start()
    try:
        result = cli("--bus-map", f"can0=virtual:mcapcli-{tag}", "log", "capture", "-o", str(tmp_path / "b.mcap"),
                     "--bus", "can0", "--for", "0.3")
    finally:
        done.set()
        sender.join()
        send.shutdown()
    assert result.exit_code == 0, result.transcript()
    frames = list(read_frames(tmp_path / "b.mcap"))
    assert frames and all(f.bus == "can0" and f.can_id == 0x70A for f in frames)
    decoded = cli("log", "decode", str(tmp_path / "b.mcap"))
    assert "heartbeat" in decoded.stdout


def test_a_file_that_is_not_an_mcap_is_one_clear_message(cli, tmp_path):
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"\x89MCAP0\r\nthis is not one")
    result = cli("log", "decode", str(bad))
    assert result.exit_code == 2 and "not a readable .mcap capture" in result.stderr
    assert "Traceback" not in result.stderr


# -- without the robotics extra ----------------------------------------------------------------------

@pytest.mark.parametrize("args", [
    ("--sim", "log", "record", "--for", "1", "-o", "{tmp}/r.mcap"),
    ("--sim", "log", "step", "elbow_pitch", "--position", "0.1", "-o", "{tmp}/s.mcap", "--apply"),
    ("--bus-map", "can0=virtual:nothing", "log", "capture", "-o", "{tmp}/c.mcap"),
    ("log", "decode", "{tmp}/c.mcap"),
])
def test_mcap_without_the_extra_says_what_to_install(cli, tmp_path, monkeypatch, args):
    (tmp_path / "c.mcap").write_bytes(b"")
    for name in ("mcap", "mcap.reader", "mcap.writer", "mcap_ros2", "mcap_ros2.writer", "mcap_ros2.decoder"):
        monkeypatch.setitem(sys.modules, name, None)  # `import mcap` raises ImportError
    result = cli(*(a.format(tmp=tmp_path) for a in args))
    assert result.exit_code == 2, result.transcript()
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and EXTRA in lines[0] and "Traceback" not in result.stderr, result.stderr
    assert not list(tmp_path.glob("[rs].mcap"))  # nothing written, nothing sent


@pytest.mark.parametrize("args", [
    ("--sim", "monitor", "--foxglove", "--for", "1"),
    ("--sim", "log", "record", "--for", "1", "-o", "{tmp}/r.csv", "--foxglove"),
])
def test_foxglove_without_the_extra_says_what_to_install(cli, tmp_path, monkeypatch, args):
    monkeypatch.setitem(sys.modules, "foxglove", None)
    result = cli(*(a.format(tmp=tmp_path) for a in args))
    assert result.exit_code == 2, result.transcript()
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and EXTRA in lines[0] and "foxglove-sdk" in lines[0], result.stderr
    assert not (tmp_path / "r.csv").exists()


def test_help_imports_no_robotics_module():
    code = ("import sys\nfrom sherpa_cli.cli.app import run\nrc = run(['--help'])\n"
            "print(sorted(m for m in ('mcap', 'mcap_ros2', 'foxglove', 'websockets') if m in sys.modules), rc)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True)
    assert out.stdout.strip().splitlines()[-1] == "[] 0", out.stdout


@pytest.mark.parametrize(("args", "message"), [
    (("-o", "{tmp}/r.parquet"), "only .csv and .mcap are written"),
    (("-o", "{tmp}/a.mcap", "-o", "{tmp}/b.mcap"), "a .mcap file is already given"),
    (("-o", "{tmp}/nowhere/r.mcap"), "does not exist"),
    (("-o", "{tmp}/r.csv", "--foxglove-at", "127.0.0.1:9"), "need --foxglove"),
    (("-o", "{tmp}/r.csv", "--foxglove", "--foxglove-at", "8765"), "is not HOST:PORT"),
    (("-o", "{tmp}/r.csv", "--foxglove", "--foxglove-at", "0.0.0.0:8765"), "refusing to show the arm beyond"),
])
def test_record_output_bad_inputs(cli, tmp_path, args, message):
    result = cli("--sim", "log", "record", "--for", "1", *(a.format(tmp=tmp_path) for a in args))
    assert result.exit_code == 2 and message in result.stderr, result.transcript()
    assert "Traceback" not in result.stderr
    assert not list(tmp_path.glob("*.*"))


def test_emcy_and_faults_in_a_recording(tmp_path):
    """write_recording on its own: an EMCY heard while recording goes to /rosout with its Elmo text, a
    latched MF makes the drive's diagnostic an ERROR with the fault decoded; a joint a sample lacks is
    NaN, a sample without any value is left out."""
    import struct

    from sherpa_cli.elmo.faults import decode_emcy
    from sherpa_cli.log.mcap_out import DriveState, TimedEmcy, TimedStatus, write_recording
    from sherpa_cli.log.recording import Recording

    cfg = load_config(ARM)
    rec = Recording(times=[0.0, 0.01, 0.02], columns={
        "elbow_pitch.pos_rad": [0.0, math.nan, 0.2], "elbow_pitch.vel_rad_s": [0.0, math.nan, 1.0],
        "wrist_1.pos_rad": [0.1, 0.1, math.nan], "wrist_1.vel_rad_s": [0.0, 0.0, math.nan],
        "elbow_1a.px": [0.0, math.nan, 115.0], "elbow_1a.vx": [0.0, math.nan, 573.0]})
    zero = 1_700_000_000_000_000_000
    emcy = decode_emcy(struct.pack("<HBBHH", 0x8110, 0x11, 0, 0, 0x2A8))
    status = [TimedStatus(zero - 1, (DriveState("elbow_1a", "can1", 40, mo=1, um=5, sr=0, mf=0x1000),)),
              TimedStatus(zero + 30_000_000, (DriveState("elbow_1a", "can1", 40, problem="no answer"),))]
    out = tmp_path / "r.mcap"
    write_recording(out, rec, cfg, time_zero_ns=zero, status=status,
                    emcy=[TimedEmcy(zero + 15_000_000, "elbow_1a", emcy)])
    messages, _, _ = _decoded(out)
    assert [(m[0], m[2] - zero) for m in messages] == [
        ("/diagnostics", -1), ("/joint_states", 0), ("/sherpa/motor_counts", 0),
        ("/joint_states", 10_000_000),  # elbow_1a's counts missed that sample: no motor message
        ("/rosout", 15_000_000), ("/joint_states", 20_000_000), ("/sherpa/motor_counts", 20_000_000),
        ("/diagnostics", 30_000_000)]
    log = next(m[3] for m in messages if m[0] == "/rosout")
    assert log.level == 40 and log.name == "elbow_1a" and log.msg.startswith("EMCY 0x8110: CAN message lost")
    first, last = (m[3].status[0] for m in messages if m[0] == "/diagnostics")
    assert first.level == 2 and first.message.startswith("MF: ")
    assert any(kv.key == "MF fault" for kv in first.values)
    assert last.level == 2 and last.message == "no answer"
    missed = [m[3] for m in messages if m[0] == "/joint_states"][1]
    assert list(missed.name) == ["elbow_pitch", "wrist_1"] and list(missed.effort) == []
    assert math.isnan(missed.position[0]) and missed.position[1] == 0.1
