"""`Arm.monitor()`: `sherpa monitor` as an iterator of typed snapshots, on the simulated arm's stepped time."""

from __future__ import annotations

from pathlib import Path

import pytest
from motion_helpers import stepped_session

from sherpa_cli.api import Arm, MonitorSnapshot
from sherpa_cli.bus.targets import drive_ref
from sherpa_cli.config import load_config
from sherpa_cli.errors import UsageError
from sherpa_cli.joints.units import TAU

ROOT = Path(__file__).resolve().parent.parent
CONFIG = ROOT / "configs" / "sherpa-arm.yaml"


def test_count_bounds_the_snapshots_and_each_holds_rad_beside_counts():
    cfg = load_config(CONFIG)
    with stepped_session(cfg, ["can1"]) as (session, stepped):
        arm = Arm(session)
        with arm.monitor(["elbow_pitch"], interval=0.2, count=3, clock=stepped.now, sleep=stepped.sleep) as stream:
            snaps = list(stream)
    assert [s.number for s in snaps] == [1, 2, 3] and all(isinstance(s, MonitorSnapshot) for s in snaps)
    assert [s.at for s in snaps] == sorted(s.at for s in snaps)
    assert snaps[1].at - snaps[0].at >= 0.2  # the interval slept on the injected clock
    elbow = snaps[-1]["elbow_1a"]
    assert snaps[-1].ok and [d.drive for d in snaps[-1]] == ["elbow_1a"]
    assert elbow.answering and elbow.nmt == "operational" and elbow.joint == "elbow_pitch"
    assert elbow.px is not None and elbow.position_rad == pytest.approx(elbow.px * TAU / 3600)


def test_duration_bounds_the_snapshots_on_the_injected_clock():
    cfg = load_config(CONFIG)
    with stepped_session(cfg, ["can1"]) as (session, stepped):
        start = stepped.now()
        with Arm(session).monitor(["elbow_1a"], interval=0.1, duration=0.35, clock=stepped.now,
                                  sleep=stepped.sleep) as stream:
            snaps = list(stream)
    assert 3 <= len(snaps) <= 4
    assert all(s.at - start <= 0.35 + 0.1 for s in snaps)  # none started after the duration


def test_leaving_early_puts_the_heartbeat_back_and_a_write_needs_apply():
    cfg = load_config(CONFIG)
    with stepped_session(cfg, ["can1"]) as (session, stepped):
        arm = Arm(session)
        with pytest.raises(UsageError, match="apply=True"):
            arm.monitor(["elbow_1a"], heartbeat_ms=50)
        with arm.monitor(["elbow_1a"], heartbeat_ms=50, apply=True, clock=stepped.now,
                         sleep=stepped.sleep) as stream:
            for snap in stream:
                assert snap["elbow_1a"].heartbeat_ms == 50
                break  # an endless stream, left after one snapshot
        writes = [(i, s, v) for _, i, s, v in session.sim.drives["elbow_1a"].od_writes]
    assert writes == [(0x1017, 0, 50), (0x1017, 0, 0)]
    with pytest.raises(UsageError, match="--interval 0"):
        Arm(session).monitor(interval=0)


def test_the_monitor_command_is_a_layer_over_the_api(cli, monkeypatch):
    calls: list[tuple] = []
    real = Arm.monitor

    def spy(self, targets=None, **kw):
        calls.append((targets, kw.get("count")))
        return real(self, targets, **kw)

    monkeypatch.setattr(Arm, "monitor", spy)
    once = cli("--sim", "monitor", "--once", "elbow_pitch")
    assert once.exit_code == 0, once.transcript()
    import sherpa_cli.cli.monitor_cmd as monitor_cmd

    monkeypatch.setattr(monitor_cmd, "sleep", lambda s: None)
    live = cli("--sim", "monitor", "--interval", "0.05", "--for", "0.1", "elbow_pitch")
    assert live.exit_code == 0, live.transcript()
    assert live.stdout.count("bus can1") == 2
    assert calls == [(["elbow_pitch"], 1), (["elbow_pitch"], 2)]


def test_a_stream_left_by_break_without_with_puts_the_heartbeat_back_and_unhooks_its_emcy_listener():
    """`for s in arm.monitor(..., apply=True): break` kept 0x1017 at the monitor's value: the stream
    and its generator held each other, so dropping the stream closed nothing; and every monitor left
    an EMCY callback on the session's client."""
    cfg = load_config(CONFIG)
    with stepped_session(cfg, ["can1"]) as (session, stepped):
        arm = Arm(session)
        client = session.client(drive_ref(cfg, "elbow_1a"))
        before = len(client._emcy_callbacks)
        for snap in arm.monitor(["elbow_1a"], heartbeat_ms=50, apply=True, clock=stepped.now, sleep=stepped.sleep):
            assert snap["elbow_1a"].heartbeat_ms == 50
            break
        writes = [(i, s, v) for _, i, s, v in session.sim.drives["elbow_1a"].od_writes]
        assert writes == [(0x1017, 0, 50), (0x1017, 0, 0)]
        assert len(client._emcy_callbacks) == before
