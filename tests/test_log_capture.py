"""`sherpa log capture`: every format written from live (python-can virtual) buses decodes back to
the frames sent; a stop (Ctrl-C) loses nothing already received; counts and load are reported."""

from __future__ import annotations

import threading
import time
import uuid

import can
import pytest

from sherpa_cli.log.capture import capture, frame_bits, read_frames
from tests.test_log_decode import BUSES, known_sequence


def _buses():
    tag = uuid.uuid4().hex[:8]
    channels = {name: f"logcap-{tag}-{name}" for name in BUSES}
    listen = {name: can.Bus(interface="virtual", channel=ch) for name, ch in channels.items()}
    send = {name: can.Bus(interface="virtual", channel=ch) for name, ch in channels.items()}
    return channels, listen, send


def _send_known(send) -> int:
    n = 0
    for bus, cob, data in known_sequence():
        send[bus].send(can.Message(arbitration_id=cob, data=data, is_extended_id=False))
        n += 1
    return n


def _close(*groups):
    for group in groups:
        for bus in group.values():
            bus.shutdown()


@pytest.mark.parametrize("suffix", [".log", ".asc", ".blf", ".csv", ".trc"])
def test_each_format_holds_every_frame_sent(tmp_path, suffix):
    _, listen, send = _buses()
    try:
        sent = _send_known(send)
        path = tmp_path / f"cap{suffix}"
        result = capture(listen, path, BUSES, stop=threading.Event(), frame_limit=sent)
    finally:
        _close(listen, send)
    assert result.frames == sent and result.lost == 0
    frames = list(read_frames(path, BUSES))
    got = [(f.can_id, f.data) for f in frames]
    # across buses the order of frames that arrived together is the writer's; per bus it is the bus's
    assert sorted(got) == sorted((cob, data) for _, cob, data in known_sequence())
    if suffix != ".csv":  # .csv keeps no channel
        for bus in BUSES:
            assert [(f.can_id, f.data) for f in frames if f.bus == bus] == \
                [(cob, data) for b, cob, data in known_sequence() if b == bus]


def test_a_stop_before_the_first_read_still_writes_what_the_buses_received(tmp_path):
    """Ctrl-C: the frames already received by the interface are drained, not dropped."""
    _, listen, send = _buses()
    stop = threading.Event()
    stop.set()
    try:
        sent = _send_known(send)
        result = capture(listen, tmp_path / "c.log", BUSES, stop=stop)
    finally:
        _close(listen, send)
    assert result.frames == sent
    assert len(list(read_frames(tmp_path / "c.log", BUSES))) == sent


def test_keyboard_interrupt_ends_the_capture_and_keeps_the_frames(tmp_path):
    _, listen, send = _buses()
    sent = _send_known(send)
    calls = []

    def interrupt():
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt

    try:
        result = capture(listen, tmp_path / "c.asc", BUSES, stop=threading.Event(), on_frame=interrupt)
    finally:
        _close(listen, send)
    # the interrupt came while writing frame 3; the rest were drained on the way out
    assert result.frames == sent
    assert len(list(read_frames(tmp_path / "c.asc", BUSES))) == sent


def test_load_is_bits_over_bitrate_time():
    assert frame_bits(8) == 47 + 64 + (34 + 64 - 1) // 4 + 3  # 135 bits worst case at DLC 8
    assert frame_bits(0) < frame_bits(8) < frame_bits(8, extended=True)


def test_cli_capture_for_a_while_then_reports(cli, tmp_path):
    channels, listen, send = _buses()
    _close(listen)
    bus_map = ",".join(f"{name}=virtual:{ch}" for name, ch in channels.items())
    out = tmp_path / "run.log"
    done = threading.Event()

    def traffic():
        while not done.is_set():
            send["can1"].send(can.Message(arbitration_id=0x728, data=b"\x05", is_extended_id=False))
            time.sleep(0.01)

    sender = threading.Thread(target=traffic, daemon=True)
    sender.start()
    try:
        result = cli("--bus-map", bus_map, "log", "capture", "-o", str(out), "--for", "0.6")
        result_json = cli("--json", "--bus-map", bus_map, "log", "capture", "-o", str(tmp_path / "b.blf"),
                          "--for", "0.3")
    finally:
        done.set()
        sender.join()
        _close(send)
    assert result.exit_code == 0, result.stderr
    written = list(read_frames(out, BUSES))
    assert written and all(f.bus == "can1" and f.can_id == 0x728 for f in written)
    said = " ".join(result.stdout.split())  # the line wraps at the fixed width when tmp_path is long (xdist)
    assert f"{len(written)} frames in" in said and "0 lost" in said
    import json

    report = json.loads(result_json.stdout)
    assert report["frames"] == len(list(read_frames(tmp_path / "b.blf", BUSES))) > 0
    assert [b["bus"] for b in report["buses"]] == BUSES and report["buses"][1]["load"] > 0


def test_cli_capture_refuses_unknown_format_and_bus(cli, tmp_path):
    bad = cli("log", "capture", "-o", str(tmp_path / "x.pcap"))
    assert bad.exit_code == 2 and "unknown capture format .pcap" in bad.stderr
    bus = cli("--bus-map", "can0=virtual:q", "log", "capture", "-o", str(tmp_path / "x.log"), "--bus", "can9")
    assert bus.exit_code == 2 and "--bus can9" in bus.stderr


def test_overrun_error_frames_count_as_lost(tmp_path):
    _, listen, send = _buses()
    try:
        send["can0"].send(can.Message(arbitration_id=0x4, data=bytes([0, 0x01, 0, 0, 0, 0, 0, 0]),
                                      is_error_frame=True, is_extended_id=False))
        send["can0"].send(can.Message(arbitration_id=0x70A, data=b"\x05", is_extended_id=False))
        result = capture(listen, tmp_path / "c.log", BUSES, stop=threading.Event(), frame_limit=2)
    finally:
        _close(listen, send)
    assert result.counts["can0"].errors == 1 and result.lost == 1 and result.frames == 2


def test_mf4_without_asammdf_is_one_clear_message_for_capture_and_decode(tmp_path, monkeypatch):
    import importlib.util

    from sherpa_cli.errors import UsageError
    from sherpa_cli.log.capture import check_output

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "asammdf" else real(name, *a))
    with pytest.raises(UsageError, match=r"run\.mf4: \.mf4 needs the asammdf package"):
        check_output(tmp_path / "run.mf4")
    (tmp_path / "old.mf4").write_bytes(b"MDF     4.10    ")
    with pytest.raises(UsageError, match=r"old\.mf4: \.mf4 needs the asammdf package"):
        list(read_frames(tmp_path / "old.mf4"))


def test_a_sim_capture_is_refused_saying_why_and_the_way_that_works(cli, tmp_path):
    """`--sim log capture` cannot hear another command's in-process arm: refused before any arm is
    powered or file written, saying why (not the old "no traffic of its own") and how to capture a
    simulated bus (a served simulator and its --bus-map)."""
    out = tmp_path / "bus.log"
    result = cli("--sim", "log", "capture", "-o", str(out), "--for", "1")
    assert result.exit_code == 2, result.transcript()
    assert result.stderr.startswith("error: log capture --sim: the in-process simulated arm talks only with the "
                                    "command that opens it"), result.transcript()
    assert "nothing captured" in result.stderr and "`sherpa sim --serve 127.0.0.1:54701`" in result.stderr
    assert "--bus-map" in result.stderr and "Traceback" not in result.stderr
    assert not out.exists() and not (tmp_path / "state" / "sherpa-cli" / "sim").exists()
