"""The calibration mark never reaches flash (review 2, note on motion/calibration.py): whether SV copies
UI[] to flash is UNCONFIRMED for the Whistle, and a flash that held UI[flag]=1 would make a joint look
homed after a power cycle with PX = 0 wherever it stands. The program engine (`program-limits
--save`, `params restore --save`) clears the mark before SV and puts it back in RAM after a
confirmed SV (the counter still means the joint: SV does not touch PX)."""

from __future__ import annotations

from pathlib import Path

import pytest

from sherpa_cli.bus.session import ArmSession, DriveRef
from sherpa_cli.config import load_config
from sherpa_cli.elmo import codec
from sherpa_cli.joints.limits import derive_checked
from sherpa_cli.ops import program
from sherpa_cli.ops.program import DriveTarget
from sherpa_cli.ops.save_ledger import SaveLedger
from sherpa_cli.sim.arm import SimArm

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE3 = ROOT / "configs" / "appendix-c" / "example3.yaml"


@pytest.fixture
def state_home(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "state"))
    return tmp_path / "state"


def requests(drive, since: int) -> list[tuple[str, str, int | float | None]]:
    rpdo2 = 0x300 + drive.node
    return [(r.kind, program.param_key(r.letters, r.index), r.value)
            for r in (codec.decode_request(data) for _, can_id, data in list(drive.received)[since:] if can_id == rpdo2)
            if r.kind in ("set", "execute")]


def test_save_clears_the_calibration_mark_before_sv_and_puts_it_back_after(state_home):
    cfg = load_config(EXAMPLE3)
    flag = f"UI[{cfg.protocol.calibration_flag}]"
    derived, _ = derive_checked(cfg, None)
    targets = [DriveTarget(d.drive, d.bus, d.node, d.params) for d in derived]
    homed, other = targets[0].drive, targets[1].drive
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as session:
        d = cfg.drives[homed]
        c = session.client(DriveRef(homed, d.bus, d.node, d))
        c.nmt_start()
        c.set("UI", cfg.protocol.calibration_flag, 1)  # as `home` leaves it
        mark = {n: len(x.received) for n, x in session.sim.drives.items()}
        plans = program.read_plans(session, targets, need_serial=True)
        result = program.apply_plans(session, plans, save=True, ledger=SaveLedger())
        assert [o.status for o in result.outcomes] == ["saved", "saved"]
        sent = requests(session.sim.drives[homed], mark[homed])
        sv = sent.index(("execute", "SV", None))
        assert ("set", flag, 0) in sent[:sv], "the mark must be cleared before SV"
        assert sent[sv + 1:].count(("set", flag, 1)) == 1, "and put back in RAM after a confirmed SV"
        with session.sim.lock:
            assert session.sim.drives[homed].ram[flag] == 1
        # a drive without the mark gets no UI write at all
        assert not [r for r in requests(session.sim.drives[other], mark[other]) if r[1] == flag]
