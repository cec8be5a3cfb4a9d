"""The journal of temporary drive changes across processes: SIGKILL a `jog
--velocity` or a `log record` in its own process; the next motion command refuses the drive and says
what was left; `sherpa recover --apply` puts it back (the touched objects read exactly as before the
killed command); a jog then works.
"""

from __future__ import annotations

import json
import os
import signal
import struct
import time

import pytest
from conftest import ROOT
from test_motion_crossprocess import DRIVE, JOINT, NODE, finish, sherpa, start_jog
from test_motion_crossprocess import arm as arm

from sherpa_cli.bus.busmap import apply_bus_map, parse_bus_map
from sherpa_cli.bus.session import ArmSession, resolve_target
from sherpa_cli.config import load_config

pytestmark = [pytest.mark.realbus, pytest.mark.crossprocess]

SDO_OBJECTS = [(0x1016, 1, "<I"), (0x1029, 1, "<B"), (0x6007, 0, "<h"), (0x1800, 1, "<I"), (0x1800, 2, "<B"),
               (0x1A00, 0, "<B"), (0x1A00, 1, "<I"), (0x1A00, 2, "<I")]
INTERP = ["UM", "SP", "AC", "DC", "MF"]


def snapshot(arm_) -> dict[str, int]:
    """The touched objects of the jog's drive, read by the test through a session of its own (SDO and
    the interpreter; NMT start first, which changes nothing the commands touch)."""
    cfg = apply_bus_map(load_config(ROOT / arm_.config), parse_bus_map([arm_.bus_map]))
    with ArmSession.open(cfg, buses=["can1"]) as s:
        ref = resolve_target(cfg, DRIVE)
        c = s.client(ref)
        c.nmt_start()
        out: dict[str, int] = {letters: int(c.get(letters)) for letters in INTERP}
        for index, sub, fmt in SDO_OBJECTS:
            raw = s.sdo(ref).upload(index, sub)
            out[f"0x{index:04X}:{sub}"] = struct.unpack(fmt, (bytes(raw) + bytes(4))[:struct.calcsize(fmt)])[0]
        return out


def run(arm_, tmp_path, *args: str) -> tuple[int, str, str]:
    return finish(sherpa(arm_, tmp_path, *args))


def test_a_killed_velocity_jog_is_refused_until_recover_puts_it_back(arm, tmp_path):
    before = snapshot(arm)
    proc, _ = start_jog(arm, tmp_path)
    t_kill = time.monotonic()
    os.kill(proc.pid, signal.SIGKILL)
    finish(proc)
    arm.wait_trip((DRIVE,), t_kill)  # what `recover` is to report
    code, out, err = run(arm, tmp_path, "jog", JOINT, "--velocity", "0.1", "--for", "0.3", "--apply")
    assert code == 1, f"{out}\n{err}"
    assert f"{DRIVE} (can1:{NODE}): a motion command that did not finish (killed?) left temporary changes" in err
    assert "sherpa recover" in err and "Traceback" not in err
    code, out, err = run(arm, tmp_path, "recover", JOINT)  # dry run: says what happened
    assert code == 0, f"{out}\n{err}"
    assert "0x1016:1=0x0" in out and "its dead-man tripped" in out and "dry run" in out
    code, out, err = run(arm, tmp_path, "recover", JOINT, "--apply")
    assert code == 0, f"{out}\n{err}"
    assert "MF 0x800 cleared" in out
    assert snapshot(arm) == before
    code, out, err = run(arm, tmp_path, "jog", JOINT, "--velocity", "0.1", "--for", "0.3", "--apply")
    assert code == 0, f"{out}\n{err}"


def test_a_killed_log_record_is_put_back_by_recover(arm, tmp_path):
    before = snapshot(arm)
    proc = sherpa(arm, tmp_path, "log", "record", JOINT, "--rate", "100", "--for", "30", "-o",
                  str(tmp_path / "r.csv"))
    journal = tmp_path / "state" / "sherpa-cli" / "journal" / f"can1-node{NODE}.json"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:  # the recorder has noted its TPDO changes and is recording
        if journal.exists() and len(json.loads(journal.read_text())["steps"]) >= 5:
            break
        time.sleep(0.05)
    time.sleep(1.0)
    os.kill(proc.pid, signal.SIGKILL)
    finish(proc)
    assert snapshot(arm) != before  # the TPDO mapping is still the recorder's
    code, out, err = run(arm, tmp_path, "jog", JOINT, "--velocity", "0.1", "--for", "0.3", "--apply")
    assert code == 1 and "a log record that did not finish" in err, f"{out}\n{err}"
    code, out, err = run(arm, tmp_path, "--recover", "jog", JOINT, "--velocity", "0.1", "--for", "0.3", "--apply")
    assert code == 0, f"{out}\n{err}"
    assert snapshot(arm) == before
