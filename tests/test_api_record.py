"""`Arm.record()`: the `log record` engine from Python, on the simulated arm's stepped time."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from motion_helpers import stepped_session

from sherpa_cli.api import Arm, RecordResult
from sherpa_cli.bus.targets import DriveRef
from sherpa_cli.config import load_config
from sherpa_cli.errors import UsageError
from sherpa_cli.joints.units import TAU
from sherpa_cli.log.recording import Recording, read_csv

ROOT = Path(__file__).resolve().parent.parent
CONFIG = ROOT / "configs" / "sherpa-arm.yaml"


def _present(values: list[float]) -> list[float]:
    return [v for v in values if not math.isnan(v)]


def test_one_second_at_200_hz_is_held_in_memory_in_rad_with_counts_beside():
    cfg = load_config(CONFIG)
    with stepped_session(cfg, ["can1"]) as (session, stepped):
        arm = Arm(session)
        d = arm.config.drives["elbow_1a"]
        client = session.client(DriveRef("elbow_1a", d.bus, d.node, d))
        client.nmt_start()
        client.set("PX", 0, 900)  # a quarter turn of the joint's 3600 counts
        result = arm.record(["elbow_pitch"], rate=200, duration=1.0, timebase=stepped)
        t_end = stepped.now()
    assert isinstance(result, RecordResult) and result.ok and result.streamed is None
    assert result.expected is not None and 199 <= result.expected <= 201  # 1 s of simulated time at 200 Hz
    assert result.samples == {"elbow_1a": result.rows} and result.rows >= 195
    assert t_end == pytest.approx(1.0, abs=0.1)  # the wait ran on the stepped clock
    joint = result.recording.joint("elbow_pitch")
    motor = result.recording.drive("elbow_1a")
    times = result.recording.times
    assert times[0] == pytest.approx(0.0) and times[1] - times[0] == pytest.approx(0.005)
    assert _present(motor.position_counts) == [900.0] * result.rows
    assert _present(joint.position) == [pytest.approx(900 * TAU / 3600)] * result.rows  # rad
    assert all(v == 0 for v in _present(joint.velocity))
    assert result.plan.refs[0].name == "elbow_1a" and result.plan.rate == 200


def test_the_result_writes_the_csv_the_command_writes(tmp_path):
    cfg = load_config(CONFIG)
    with stepped_session(cfg, ["can1"]) as (session, stepped):
        result = Arm(session).record(["elbow_pitch"], rate=100, duration=0.2, timebase=stepped, current=False)
    result.write_csv(tmp_path / "r.csv")
    back = read_csv(tmp_path / "r.csv")
    assert back.joints() == ["elbow_pitch"] and len(back.times) == result.rows
    assert back.columns["elbow_1a.px"] == result.recording.columns["elbow_1a.px"]


def test_streamed_rows_go_to_the_file_and_not_to_memory(tmp_path):
    cfg = load_config(CONFIG)
    out = tmp_path / "s.csv"
    with stepped_session(cfg, ["can1"]) as (session, stepped):
        result = Arm(session).record(["elbow_pitch"], rate=100, duration=0.2, timebase=stepped, stream_to=out)
    assert result.streamed == out and result.recording.times == []
    assert len(read_csv(out).times) == result.rows > 10
    with pytest.raises(UsageError, match="streamed"):
        result.write_csv(tmp_path / "again.csv")


def test_a_polled_recording_runs_on_the_injected_time():
    cfg = load_config(CONFIG)
    with stepped_session(cfg, ["can1"]) as (session, stepped):
        result = Arm(session).record(["elbow_pitch"], duration=0.1, poll=True, timebase=stepped)
    assert result.expected is None and result.samples["elbow_1a"] >= 2
    assert result.recording.joint("elbow_pitch").current is None


def test_bad_values_and_a_rate_the_bus_cannot_carry_are_refused_before_anything_is_sent():
    cfg = load_config(CONFIG)
    with stepped_session(cfg, ["can1"]) as (session, stepped):
        arm = Arm(session)
        with pytest.raises(UsageError, match=r"--for 0.0: expected seconds > 0"):
            arm.record(["elbow_pitch"], duration=0.0, timebase=stepped)
        with pytest.raises(UsageError, match=r"--rate 0.5: expected Hz >= 1"):
            arm.record(["elbow_pitch"], rate=0.5, timebase=stepped)
        with pytest.raises(UsageError, match="highest rate"):
            arm.record(None, rate=10000, timebase=stepped)
        assert stepped.now() == 0.0  # nothing waited, nothing recorded
    with pytest.raises(UsageError, match=r"nope: not in the recording \(it has no joints\)"):
        Recording().joint("nope")


def test_the_log_record_command_is_a_layer_over_the_api(cli, monkeypatch, tmp_path):
    calls: list[tuple] = []
    real = Arm.record

    def spy(self, targets=None, rate=100.0, duration=1.0, **kw):
        calls.append((targets, rate, duration))
        return real(self, targets, rate, duration, **kw)

    monkeypatch.setattr(Arm, "record", spy)
    out = tmp_path / "r.csv"
    result = cli("--sim", "log", "record", "elbow_pitch", "--rate", "50", "--for", "0.2", "-o", str(out))
    assert result.exit_code == 0, result.transcript()
    assert calls == [(["elbow_pitch"], 50.0, 0.2)]
    assert len(read_csv(out).times) >= 2


def test_the_drives_own_recorders_record_at_the_servo_rate_and_refuse_bad_values():
    cfg = load_config(CONFIG)
    with stepped_session(cfg, ["can1"]) as (session, stepped):
        arm = Arm(session)
        with pytest.raises(UsageError, match="--trigger soon"):
            arm.record_drives(["elbow_pitch"], 0.05, trigger="soon")
        result = arm.record_drives(["elbow_pitch"], 0.05, clock=stepped.now, sleep=stepped.sleep)
    assert result.samples["elbow_1a"] > 10 and result.period_s < 0.005  # far above a SYNC recording's rate
    assert len(_present(result.recording.joint("elbow_pitch").position)) > 10


def test_a_finished_recording_stops_listening_for_emcy():
    """Each `Arm.record(..., status=True)` left its EMCY callback on the session's clients: a later
    EMCY went into every finished result, appended from the receive thread while a writer read it."""
    from sherpa_cli.bus.targets import drive_ref

    cfg = load_config(CONFIG)
    with stepped_session(cfg, ["can1"]) as (session, stepped):
        client = session.client(drive_ref(cfg, "elbow_1a"))
        before = len(client._emcy_callbacks)
        Arm(session).record(["elbow_pitch"], rate=50, duration=0.1, status=True, timebase=stepped)
        assert len(client._emcy_callbacks) == before
