"""One outbox, in order: every frame a simulated drive sends, SDO answers included,
leaves in the order it was produced. A TPDO the drive produced before an SDO request is never sent
after the answer to that request. Before, SDO answers went straight to the bus while the drive's
other frames waited in its outbox: with a 1 ms event timer, 56 of 60 tries showed a TPDO after the
answer that disabled it -- recording start/stop code that works only with that order would break on
a real drive."""

from __future__ import annotations

import struct
import time

import can
from conftest import ROOT

from sherpa_cli.bus.session import ArmSession, resolve_target
from sherpa_cli.config import load_config
from sherpa_cli.sim.arm import SimArm

DRIVE, NODE, BUS = "elbow_1a", 40, "can1"
TRIES = 20


def _w(s: ArmSession, ref, index: int, sub: int, fmt: str, value: int) -> None:
    s.sdo(ref).download(index, sub, struct.pack(fmt, value))


def _enable_tpdo1(s: ArmSession, ref) -> None:
    """TPDO1: PX (0x6064), event-driven every 1 ms, valid."""
    _w(s, ref, 0x1800, 1, "<I", 0x80000000 | (0x180 + NODE))
    _w(s, ref, 0x1A00, 0, "<B", 0)
    _w(s, ref, 0x1A00, 1, "<I", 0x60640020)
    _w(s, ref, 0x1A00, 0, "<B", 1)
    _w(s, ref, 0x1800, 2, "<B", 254)
    _w(s, ref, 0x1800, 5, "<H", 1)
    _w(s, ref, 0x1800, 1, "<I", 0x180 + NODE)


def test_no_tpdo_leaves_after_the_answer_that_disabled_it():
    cfg = load_config(ROOT / "configs/sherpa-arm.yaml")
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg), buses=[BUS]) as s:
        ref = resolve_target(cfg, DRIVE)
        s.client(ref).nmt_start()
        observer = can.Bus(interface="virtual", channel=s.sim.endpoints[BUS]["channel"])
        try:
            late: list[str] = []
            for i in range(TRIES):
                _enable_tpdo1(s, ref)
                time.sleep(0.02)  # the timer runs: TPDOs flow
                while observer.recv(timeout=0) is not None:
                    pass
                disable = struct.pack("<BHBI", 0x23, 0x1800, 1, 0x80000000 | (0x180 + NODE))
                observer.send(can.Message(arbitration_id=0x600 + NODE, data=disable, is_extended_id=False))
                frames: list[can.Message] = []
                deadline = time.monotonic() + 2.0
                answered = None
                while time.monotonic() < deadline:
                    msg = observer.recv(timeout=0.05)
                    if msg is None:
                        if answered is not None and time.monotonic() > answered + 0.1:
                            break
                        continue
                    frames.append(msg)
                    if msg.arbitration_id == 0x580 + NODE and answered is None:
                        assert msg.data[0] == 0x60, f"try {i}: the disable was refused: {bytes(msg.data).hex()}"
                        answered = time.monotonic()
                assert answered is not None, f"try {i}: no answer"
                ids = [m.arbitration_id for m in frames]
                after = ids[ids.index(0x580 + NODE) + 1:]
                if 0x180 + NODE in after:
                    late.append(f"try {i}: {after.count(0x180 + NODE)} TPDO1 after the answer")
            assert not late, late
        finally:
            observer.shutdown()



def test_a_remote_frame_on_the_sync_id_is_no_sync():
    """CiA 301: an RTR frame on 0x080 requests a frame; it is no SYNC. Five of them made
    five synchronous TPDOs."""
    cfg = load_config(ROOT / "configs/sherpa-arm.yaml")
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg), buses=[BUS]) as s:
        ref = resolve_target(cfg, DRIVE)
        s.client(ref).nmt_start()
        _enable_tpdo1(s, ref)
        _w(s, ref, 0x1800, 1, "<I", 0x80000000 | (0x180 + NODE))
        _w(s, ref, 0x1800, 2, "<B", 1)  # at every SYNC
        _w(s, ref, 0x1800, 1, "<I", 0x180 + NODE)
        observer = can.Bus(interface="virtual", channel=s.sim.endpoints[BUS]["channel"])
        try:
            for _ in range(5):
                observer.send(can.Message(arbitration_id=0x080, is_remote_frame=True, is_extended_id=False))
            observer.send(can.Message(arbitration_id=0x080, data=b"", is_extended_id=False))
            seen = []
            deadline = time.monotonic() + 1.0
            while time.monotonic() < deadline:
                msg = observer.recv(timeout=0.05)
                if msg is not None and msg.arbitration_id == 0x180 + NODE:
                    seen.append(msg)
            assert len(seen) == 1, f"{len(seen)} TPDO1 for 5 RTR frames and 1 SYNC"
        finally:
            observer.shutdown()
