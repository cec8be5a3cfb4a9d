"""`log record` ended by SIGTERM or SIGHUP (a service manager, a closed terminal) ends like Ctrl-C:
the samples so far are written, the drives' PDO settings are put back (RAM only, never saved),
exit 130 (docs/exit-codes.md)."""

from __future__ import annotations

import os
import signal
import time

import pytest

from sherpa_cli.cli import log_cmd
from sherpa_cli.log.recording import read_csv
from sherpa_cli.sim.arm import SimArm


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP], ids=["SIGTERM", "SIGHUP"])
def test_a_signal_ends_the_recording_and_restores_the_pdos(cli, monkeypatch, tmp_path, sig):
    seen: dict[str, int] = {}
    stop = SimArm.stop

    def stopped(self):  # the drive's TPDO1 COB-ID as the command left it
        with self.lock:
            seen.update({name: d.tpdo.cob[0] for name, d in self.drives.items()})
            saves = sum(d.save_count for d in self.drives.values())
        seen["saves"] = saves
        stop(self)

    def wait(seconds):
        time.sleep(0.2)
        os.kill(os.getpid(), sig)
        time.sleep(5)  # the handler interrupts this

    monkeypatch.setattr(SimArm, "stop", stopped)
    monkeypatch.setattr(log_cmd, "sleep", wait)
    def unhandled(signum, frame):  # without the command's own handler the test fails instead of dying
        raise AssertionError(f"{signal.Signals(signum).name} reached the test's fallback handler")

    before = signal.signal(sig, unhandled)
    out = tmp_path / "r.csv"
    t = time.monotonic()
    try:
        result = cli("--sim", "log", "record", "elbow_1a", "--rate", "50", "--for", "60", "-o", str(out))
        after = signal.getsignal(sig)
    finally:
        signal.signal(sig, before)
    assert time.monotonic() - t < 30
    assert result.exit_code == 130, result.transcript()
    assert "interrupted" in result.stderr and "restored" in result.stderr
    assert len(read_csv(out).times) >= 2
    assert seen["elbow_1a"] & 0x80000000  # TPDO1 not valid again: the power-up setting
    assert seen["saves"] == 0
    assert after is unhandled  # the command's handler is gone afterwards
