"""The motion guard's bus watch on kernel vcan, in the QEMU guest of .ci/vcan-stage.sh (marker `vcan`).

vcan has no CAN controller, so it never goes bus-off and netlink reports no controller state ("not
reported by vcan"): the one path that can be checked there is the error-frame one. A BUS-OFF error
frame (CAN_ERR_BUSOFF, what a real adapter's driver sends) injected on the spare vcan while a drive
moves must reach the guard through python-can's SocketCAN receive path and stop the command, exit 3,
naming the bus. vcan's link reports no controller state, so only the error frame says the bus is
off: the exit tries the drive with one plain request (as it does a silent drive), and since vcan
still carries frames, the drive is stopped and switched off as usual.

The simulated drive runs in this process on the same vcan (its own socket), on wall time, with a
generous consumer time: the guest is 15-20x slower than a laptop.
"""

from __future__ import annotations

import threading
import time

import pytest
from test_bus_vcan import spare  # noqa: F401 - the fixture: the spare vcan, or a skip

from sherpa_cli.bus.session import ArmSession, resolve_target
from sherpa_cli.config import load_config_text
from sherpa_cli.motion.bus_watch import BusFaultError
from sherpa_cli.motion.guard import MotionGuard
from sherpa_cli.motion.settings import MotionSettings
from sherpa_cli.sim.arm import SimArm

pytestmark = pytest.mark.vcan

CONFIG = """\
name: bus-watch-vcan
protocol: {{mo_settle: 0.05, sv_blackout: 0.2, reply_timeout: 2.0, retries: 3}}
motion: {{consumer_time_ms: 2000, liveness_timeout: 5.0, bus_check_interval: 0.1}}
buses:
  can0: {{interface: socketcan, channel: {spare}}}
drives:
  drive1: {{bus: can0, node: 5, model: whistle-10/60}}
"""
BUS_OFF = (0x240, bytes([0, 0, 0, 0, 0, 0, 255, 1]))  # CAN_ERR_BUSOFF | CAN_ERR_CNT, TEC 255 REC 1


def test_a_bus_off_error_frame_on_vcan_stops_a_moving_drive(spare):  # noqa: F811 - the imported fixture
    import can

    cfg = load_config_text(CONFIG.format(spare=spare), "bus-watch-vcan.yaml")
    arm = SimArm(cfg, {"can0": {"interface": "socketcan", "channel": spare}}).start()
    other = can.Bus(interface="socketcan", channel=spare)  # "the adapter's driver" sending the error frame
    try:
        with ArmSession.open(cfg) as s:  # no sim: the link is read through netlink, as on a real adapter
            ref = resolve_target(cfg, "drive1")
            with pytest.raises(BusFaultError) as info, MotionGuard(s, [ref], settings=MotionSettings.from_config(cfg)) as g:
                g.enable(ref, 5)
                g.client(ref).set("JV", 0, 2000)
                g.client(ref).execute("BG")
                sent = threading.Event()
                deadline = time.monotonic() + 60
                while time.monotonic() < deadline:
                    g.check()
                    g.query(ref, "PX")
                    if not sent.is_set():
                        sent.set()
                        other.send(can.Message(arbitration_id=BUS_OFF[0], data=BUS_OFF[1], is_extended_id=False,
                                               is_error_frame=True))
                    time.sleep(0.05)
                pytest.fail("the guard did not stop the command")
            err = info.value
            assert err.exit_code == 3 and err.bus == "can0" and err.problem == "bus-off"
            assert f"bus can0 (socketcan:{spare}): went BUS-OFF during the motion (TEC 255, REC 1; seen in an " \
                   "error frame)" in str(err)
            (fault,) = g.report.bus_faults
            assert (fault.bus, fault.state, fault.seen_in) == ("can0", "BUS-OFF", "an error frame")
            (drive,) = g.report.drives
            assert drive.stopped_by not in ("not reached", "not stopped") and drive.motor_off, drive.line()
            assert not arm.drives["drive1"].motor_on
    finally:
        other.shutdown()
        arm.stop()
