"""Clearing a tripped dead-man (motion/trip_clear.py) on the in-process simulated arm: the dead-man id
it takes for its own MO=1/MO=0 is one no other drive of the bus still watches."""

from __future__ import annotations

import json
import struct

import pytest

from sherpa_cli.bus import journal
from sherpa_cli.bus.session import ArmSession, resolve_target
from sherpa_cli.config import load_config
from sherpa_cli.motion.settings import MotionSettings
from sherpa_cli.motion.trip_clear import clear_heartbeat_trip
from sherpa_cli.sim.arm import SimArm

CONFIG = """\
name: trip-clear-test
protocol: {mo_settle: 0.05, sv_blackout: 0.2}
motion: {consumer_time_ms: 300, host_node_id: 126, host_id_pool: [124]}
buses:
  can0: {interface: socketcan, channel: can0}
drives:
  drive1: {bus: can0, node: 5, model: whistle-10/60}
  drive2: {bus: can0, node: 6, model: whistle-10/60}
"""


def consumer(session, ref) -> int:
    return struct.unpack("<I", bytes(session.sdo(ref).upload(0x1016, 1, name="consumer"))[:4])[0]


@pytest.mark.parametrize("partner_state", ["operational", "tripped"])
def test_the_id_taken_to_clear_a_trip_is_not_one_another_drive_still_watches(tmp_path, partner_state):
    """A killed pair command leaves both drives' consumers armed on its id. Clearing the first drive's
    trip under that same id re-armed the partner's consumer with this heartbeat, and when it ended the
    partner tripped again -- in the middle of being put back, on a slow enough machine ("no answer")."""
    path = tmp_path / "arm.yaml"
    path.write_text(CONFIG, encoding="utf-8")
    cfg = load_config(path)
    settings = MotionSettings.from_config(cfg)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        first, partner = resolve_target(cfg, "drive1"), resolve_target(cfg, "drive2")
        for ref in (first, partner):
            s.client(ref).nmt_start()
        # what the killed command left on the partner: its consumer watching the first pool id (a
        # minute: it must not trip while this test runs)
        s.sdo(partner).download(0x1016, 1, struct.pack("<I", 126 << 16 | 60000), name="consumer")
        if partner_state == "tripped":
            # its journal (a process of another boot: not alive) and NMT Stopped, deaf to SDO, as its
            # own trip leaves it with 0x1029:1 = 2
            step = journal.sdo("motion command", 0x1016, 1, 4, 0)
            path = journal.path_for("can0", 6)
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(json.dumps({"steps": [{**step.as_json(), "pid": 999999, "proc": "0-other-boot:1"}]}))
            assert journal.leftover(partner)
            s.links["can0"].network.send_message(0, bytes([0x02, 6]))  # NMT stop
        clear_heartbeat_trip(s, first, settings)
        with s.sim.lock:
            watching = s.sim.drives["drive2"].deadman_watching()
            armed = [v for _, i, sub, v in s.sim.drives["drive1"].od_writes if (i, sub) == (0x1016, 1) and v]
        assert consumer(s, first) == 0 and consumer(s, partner) == 126 << 16 | 60000
    assert armed == [124 << 16 | 300], [hex(v) for v in armed]  # the pool's next id: 126 is watched
    assert not watching, "the partner's leftover consumer heard the trip clearing's heartbeat"
