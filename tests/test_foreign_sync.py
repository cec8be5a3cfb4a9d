"""A second SYNC producer on a recorded bus: another node (the test, on the served
bus) sends SYNC while `log record` or `log step` records. The drives answer both producers, so the
samples no longer fit the tool's time grid: the command stops with one message naming the bus (exit
3), after writing what it has and putting the PDO settings back (and, for `log step`, after the
guard stopped the motor), instead of reporting more samples than SYNCs."""

from __future__ import annotations

import contextlib
import json
import threading
import time

import can
import pytest
from killed_helpers import MOVING, wait_moving
from killed_helpers import arm as arm
from killed_helpers import shared_arm as shared_arm
from test_drive_watch_crossprocess import other_node
from test_motion_crossprocess import finish, sherpa

# a 100 Hz SYNC producer thread and a 1 kHz step: python-can-remote (the CI tests stage, a simulator of
# the module's own); not in the 15-20x slower vcan guest, where the producer thread cannot keep its rate
pytestmark = pytest.mark.crossprocess

FOREIGN_RATE = 100.0  # Hz, as a second `sherpa log record --rate 100` would


@pytest.mark.parametrize("name", ["log record", "log step"])
def test_a_foreign_sync_producer_stops_the_recording_with_a_message(arm, tmp_path, name):
    cmd = MOVING[name]
    since = time.monotonic()
    proc = sherpa(arm, tmp_path, *cmd.argv(tmp_path))
    bus = other_node(arm)
    stop = threading.Event()

    def produce() -> None:
        sync = can.Message(arbitration_id=0x080, data=b"", is_extended_id=False)
        while not stop.wait(1 / FOREIGN_RATE):
            with contextlib.suppress(can.CanOperationError):  # a full vcan queue: the next one
                bus.send(sync)

    producer = threading.Thread(target=produce, daemon=True)
    try:
        wait_moving(arm, cmd, since, proc, tmp_path)
        producer.start()
        code, out, err = finish(proc)
    finally:
        stop.set()
        if producer.is_alive():
            producer.join(timeout=5)
        bus.shutdown()
        if proc.poll() is None:
            proc.kill()
            finish(proc)
    why = f"exit {code}\n--- stdout\n{out}--- stderr\n{err}"
    assert code == 3, why
    assert "error: bus can1: elbow_1a answered" in err and "another node is sending SYNC (0x080)" in err, why
    assert "Traceback" not in err, why
    if name == "log step":
        assert any(ln.startswith("stop: elbow_1a (") and "stopped; motor off" in ln for ln in err.splitlines()), why
    else:
        assert "samples up to the stop are written" in err, why
        assert (tmp_path / "out.csv").exists(), why
    journal = tmp_path / "state" / "sherpa-cli" / "journal" / "can1-node40.json"
    assert not journal.exists() or not json.loads(journal.read_text() or "{}").get("steps"), why
