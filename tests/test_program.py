"""`sherpa program-limits`: the plan/apply/verify/save engine, proven by what the simulated drives received."""

from __future__ import annotations

import dataclasses
import json
import signal
import threading
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sherpa_cli.bus.session import ArmSession, DriveRef
from sherpa_cli.config import load_config
from sherpa_cli.elmo import codec
from sherpa_cli.errors import ConfigError, SafetyError
from sherpa_cli.joints.limits import derive_checked
from sherpa_cli.ops import program
from sherpa_cli.ops.program import DriveTarget, write_order
from sherpa_cli.ops.save_ledger import SaveLedger, save_warning
from sherpa_cli.sim import state as sim_state
from sherpa_cli.sim.arm import SimArm

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE3 = "configs/appendix-c/example3.yaml"


# --------------------------------------------------------------------------- helpers

def targets_of(cfg, names=None) -> list[DriveTarget]:
    derived, _ = derive_checked(cfg, names)
    return [DriveTarget(d.drive, d.bus, d.node, d.params) for d in derived]


def requests(drive, since: int = 0) -> list[codec.Request]:
    """Interpreter requests the simulated drive received (after the first ``since`` frames)."""
    rpdo2 = 0x300 + drive.node
    return [codec.decode_request(data) for _, can_id, data in list(drive.received)[since:] if can_id == rpdo2]


def key_of(r: codec.Request) -> str:
    return program.param_key(r.letters, r.index)


def sets(drive, since: int = 0) -> list[tuple[str, int | float]]:
    return [(key_of(r), r.value) for r in requests(drive, since) if r.kind == "set"]


def executes(drive, since: int = 0) -> list[str]:
    return [r.letters for r in requests(drive, since) if r.kind == "execute"]


def sdo_downloads(drive) -> list[bytes]:
    sdo_rx = 0x600 + drive.node
    return [data for _, can_id, data in drive.received if can_id == sdo_rx and data[0] & 0xE0 == 0x20]


def client(session, name):
    d = session.cfg.drives[name]
    return session.client(DriveRef(name, d.bus, d.node, d))


@pytest.fixture
def state_home(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "state"))
    return tmp_path / "state"


@pytest.fixture
def cfg3():
    return load_config(ROOT / EXAMPLE3)


# --------------------------------------------------------------------------- write order (pure)

def _valid_chain(values: dict) -> bool:
    return not program._broken_rules(values)


def test_write_order_keeps_every_step_consistent_from_factory_values():
    now = {"LL[3]": -10**9, "VL[3]": -10**9, "VH[3]": 10**9, "HL[3]": 10**9, "CL[1]": 5.0, "PL[1]": 10.0}
    targets = {"LL[3]": -240, "HL[3]": 240, "VL[3]": -220, "VH[3]": 220, "CL[1]": 12.0, "PL[1]": 15.0}
    order = write_order(now, targets)
    assert order == ["VL[3]", "LL[3]", "VH[3]", "HL[3]", "PL[1]", "CL[1]"]


def test_write_order_peak_before_continuous_only_when_needed():
    assert write_order({"CL[1]": 5.0, "PL[1]": 10.0}, {"CL[1]": 3.0, "PL[1]": 12.0}) == ["CL[1]", "PL[1]"]
    assert write_order({"CL[1]": 5.0, "PL[1]": 10.0}, {"CL[1]": 11.0, "PL[1]": 12.0}) == ["PL[1]", "CL[1]"]
    assert write_order({"CL[1]": 5.0, "PL[1]": 10.0}, {"CL[1]": 2.0, "PL[1]": 4.0}) == ["CL[1]", "PL[1]"]


def test_write_order_moves_a_window_past_itself():
    now = {"LL[3]": 0, "VL[3]": 10, "VH[3]": 20, "HL[3]": 30}
    up = {"LL[3]": 100, "VL[3]": 110, "VH[3]": 120, "HL[3]": 130}
    assert write_order(now, up) == ["HL[3]", "VH[3]", "VL[3]", "LL[3]"]
    down = {"LL[3]": -130, "VL[3]": -120, "VH[3]": -110, "HL[3]": -100}
    assert write_order(now, down) == ["LL[3]", "VL[3]", "VH[3]", "HL[3]"]


def test_write_order_skips_unchanged_and_puts_the_unit_mode_first():
    assert write_order({"AC": 5, "UM": 5, "DC": 1}, {"AC": 6, "DC": 1, "UM": 2}) == ["UM", "AC"]


def test_write_order_refuses_targets_that_break_the_order():
    with pytest.raises(SafetyError, match="VL\\[3\\]"):
        write_order({"VL[3]": -5, "VH[3]": 5}, {"VL[3]": 10, "VH[3]": 9})


chain = st.lists(st.integers(-1000, 1000), min_size=4, max_size=4, unique=True).map(sorted)


@settings(max_examples=300, deadline=None)
@given(now=chain, target=chain, cl=st.tuples(st.floats(0.5, 9), st.floats(0.5, 9)),
       pl=st.tuples(st.floats(0.5, 9), st.floats(0.5, 9)))
def test_write_order_property_every_prefix_is_consistent(now, target, cl, pl):
    keys = ("LL[3]", "VL[3]", "VH[3]", "HL[3]")
    n = dict(zip(keys, now, strict=True))
    t = dict(zip(keys, target, strict=True))
    n["CL[1]"], n["PL[1]"] = min(cl), max(cl)
    t["CL[1]"], t["PL[1]"] = min(pl), max(pl)
    order = write_order(n, t)
    assert sorted(order) == sorted(k for k in t if n[k] != t[k])
    state = dict(n)
    for key in order:
        state[key] = t[key]
        assert _valid_chain(state), (order, key, state)
    assert state == t


def test_related_keys_are_the_order_partners():
    assert program.related_keys(["VL[2]", "VH[2]"]) == ["LL[2]", "HL[2]"]
    assert program.related_keys(["CL[1]"]) == ["PL[1]"]
    assert program.related_keys(["AC"]) == []


# --------------------------------------------------------------------------- checks before I/O

def test_check_targets_refuses_protection_off_read_only_and_out_of_range():
    with pytest.raises(ConfigError, match=r"CL\[2\]=1.0 switches a protection off"):
        program.check_targets([DriveTarget("d", "can0", 1, {"CL[2]": 1.0})])
    assert program.check_targets([DriveTarget("d", "can0", 1, {"CL[2]": 1.0})], allow_disabled=True)
    with pytest.raises(ConfigError, match="MC is read-only"):
        program.check_targets([DriveTarget("d", "can0", 1, {"MC": 3.0})])
    with pytest.raises(ConfigError, match="outside int32"):
        program.check_targets([DriveTarget("d", "can0", 1, {"AC": 2**31})])
    with pytest.raises(ConfigError, match="not a whole number"):
        program.check_targets([DriveTarget("d", "can0", 1, {"AC": 1.5})])
    assert program.check_targets([DriveTarget("d", "can0", 1, {"AC": 1000, "LL[3]": -5})]) == []


def test_save_ledger_counts_per_serial_and_warns(tmp_path):
    ledger = SaveLedger(tmp_path / "ledger.json")
    assert ledger.record(0x5A000101, "drive1").count == 1
    assert ledger.record(0x5A000101, "drive1").count == 2
    assert ledger.record(0x5A000202, "drive2").count == 1
    assert ledger.count(0x5A000101) == 2
    assert json.loads((tmp_path / "ledger.json").read_text())["drives"]["0x5A000101"]["saves"] == 2
    assert save_warning("d", 1, 99) is None
    assert "100 times" in save_warning("d", 1, 100)
    assert save_warning("d", 1, 1001) and "find out" in save_warning("d", 1, 1001)
    assert save_warning("d", 1, 950) is None


# --------------------------------------------------------------------------- on the simulated arm

def test_dry_run_sends_no_write(state_home, cfg3):
    with ArmSession.open(cfg3, sim=SimArm.in_process(cfg3)) as session:
        plans = program.read_plans(session, targets_of(cfg3), need_serial=True)
        drives = session.sim.drives
        assert all(p.ok and len(p.changes) == 17 for p in plans)
        for d in drives.values():
            assert requests(d), "the plan reads the drive"
            assert [r for r in requests(d) if r.kind != "query"] == []
            assert sdo_downloads(d) == [] and d.od_writes == []


def test_apply_writes_exactly_the_changed_values_in_a_consistent_order(state_home, cfg3):
    targets = targets_of(cfg3)
    with ArmSession.open(cfg3, sim=SimArm.in_process(cfg3)) as session:
        c1 = client(session, "drive1")
        c1.nmt_start()
        c1.set("AC", 0, 500)  # already right: must not be written again
        c1.set("IL", 1, 21)
        d1 = session.sim.drives["drive1"]
        before = {k: d1.read_param(k) for k in targets[0].params}
        mark = {n: len(d.received) for n, d in session.sim.drives.items()}
        plans = program.read_plans(session, targets)
        program.check_apply(plans, motor_off=False)
        result = program.apply_plans(session, plans)
        assert result.ok and [o.status for o in result.outcomes] == ["programmed", "programmed"]
        for t, plan in zip(targets, plans, strict=True):
            d = session.sim.drives[t.drive]
            written = sets(d, mark[t.drive])
            expected = {k: v for k, v in t.params.items() if t.drive != "drive1" or k not in ("AC", "IL[1]")}
            unchanged = {q.key for q in plan.params if q.now == q.target}  # e.g. factory IL[5..6]: already 4
            assert t.drive != "drive1" or {"AC", "IL[1]"} <= unchanged
            expected = {k: v for k, v in expected.items() if k not in unchanged}
            assert dict(written) == pytest.approx(expected)
            assert len(written) == len(expected), "each change written once"
            assert [k for k, _ in written] == list(plan.write_order)
            assert executes(d, mark[t.drive]) == [], "no SV without --save"
        # replay drive1's writes from its state before: the order never broke LL<=VL<VH<=HL, PL>=CL
        state = dict(before)
        for key, value in sets(d1, mark["drive1"]):
            state[key] = value
            assert not program._broken_rules(state), (key, state)


def test_second_apply_save_on_a_programmed_arm_writes_nothing_and_sends_no_sv(state_home, cfg3):
    targets = targets_of(cfg3)
    with ArmSession.open(cfg3, sim=SimArm.in_process(cfg3)) as session:
        plans = program.read_plans(session, targets, need_serial=True)
        first = program.apply_plans(session, plans, save=True, ledger=SaveLedger())
        assert [o.status for o in first.outcomes] == ["saved", "saved"]
    with ArmSession.open(cfg3, sim=SimArm.in_process(cfg3)) as session:  # a new power cycle: only flash survived
        mark = {n: len(d.received) for n, d in session.sim.drives.items()}
        plans = program.read_plans(session, targets, need_serial=True)
        assert all(p.changes == [] for p in plans)
        second = program.apply_plans(session, plans, save=True, ledger=SaveLedger())
        assert [o.status for o in second.outcomes] == ["unchanged", "unchanged"]
        for name, d in session.sim.drives.items():
            assert sets(d, mark[name]) == [] and executes(d, mark[name]) == []
            assert d.save_count == 1
    assert SaveLedger().count(plans[0].serial) == 1


def test_apply_then_save_in_a_later_run_saves_what_ram_holds(state_home, cfg3):
    # A real arm keeps RAM between two commands: `--apply` then `--apply --save` finds nothing to
    # change, yet flash holds the old values. The ledger makes the second run send SV, once.
    targets = targets_of(cfg3)
    ledger = SaveLedger()
    with ArmSession.open(cfg3, sim=SimArm.in_process(cfg3)) as session:
        plans = program.read_plans(session, targets, need_serial=True)
        applied = program.apply_plans(session, plans, save=False, ledger=ledger)
        assert [o.status for o in applied.outcomes] == ["programmed", "programmed"]
        assert all(ledger.unsaved(p.serial) for p in plans)
        assert all(d.save_count == 0 for d in session.sim.drives.values())

        again = program.read_plans(session, targets, need_serial=True)
        assert all(p.changes == [] for p in again)
        due = program.mark_save_due(again, ledger)
        assert [p.save_due for p in due] == [True, True]
        mark = {n: len(d.received) for n, d in session.sim.drives.items()}
        saved = program.apply_plans(session, due, save=True, ledger=ledger)
        assert [o.status for o in saved.outcomes] == ["saved", "saved"]
        for name, d in session.sim.drives.items():
            assert sets(d, mark[name]) == [], "nothing to write again"
            assert executes(d, mark[name]) == ["SV"]
            assert d.save_count == 1
        assert not any(ledger.unsaved(p.serial) for p in plans)

        third = program.mark_save_due(program.read_plans(session, targets, need_serial=True), ledger)
        result = program.apply_plans(session, third, save=True, ledger=ledger)
        assert [o.status for o in result.outcomes] == ["unchanged", "unchanged"]
        assert all(d.save_count == 1 for d in session.sim.drives.values())
    with ArmSession.open(cfg3, sim=SimArm.in_process(cfg3)) as session:  # power cycle: the saved values are in flash
        plans = program.read_plans(session, targets)
        assert all(p.changes == [] for p in plans)


def _skew(session, drive: str, key: str, amount: float) -> None:
    d = session.sim.drives[drive]
    d.settings = dataclasses.replace(d.settings, store_skew=((key, amount),))


def test_an_adapter_error_on_one_drive_keeps_the_other_drives_report(state_home, cfg3, monkeypatch):
    # python-can raises CanError (not a SherpaError) when an adapter goes away mid-run.
    import can

    targets = targets_of(cfg3)
    with ArmSession.open(cfg3, sim=SimArm.in_process(cfg3)) as session:
        plans = program.read_plans(session, targets, need_serial=True)
        bad = program._client(session, targets[1])
        real_set = bad.set

        def failing_set(letters, index, value):
            if letters == "LL":
                raise can.CanError("adapter unplugged")
            return real_set(letters, index, value)

        monkeypatch.setattr(bad, "set", failing_set)
        result = program.apply_plans(session, plans, save=True, ledger=SaveLedger())
        by_drive = {o.drive: o for o in result.outcomes}
        assert by_drive["drive1"].status == "saved"
        failed = by_drive["drive2"]
        assert failed.status == "failed" and failed.error == "CanError: adapter unplugged"
        assert not failed.saved and session.sim.drives["drive2"].save_count == 0


def test_read_back_mismatch_stops_that_drive_without_sv(state_home, cfg3):
    targets = targets_of(cfg3)
    with ArmSession.open(cfg3, sim=SimArm.in_process(cfg3)) as session:
        _skew(session, "drive2", "LL[3]", 1)
        plans = program.read_plans(session, targets, need_serial=True)
        result = program.apply_plans(session, plans, save=True, ledger=SaveLedger())
        o1, o2 = result.outcomes
        assert o1.status == "saved"
        assert o2.status == "failed" and o2.mismatches == {"LL[3]": -204} and not o2.saved
        assert "LL[3] was written as -205 but reads back -204" in o2.error
        d2 = session.sim.drives["drive2"]
        assert executes(d2) == [] and d2.save_count == 0
        order = list(plans[1].write_order)
        assert [k for k, _ in sets(d2)] == order[: order.index("LL[3]") + 1], "nothing written after the mismatch"
        err = program.exit_problem(result)
        assert err is not None and err.exit_code == 1 and "drive2" in err.message


def test_sv_only_after_verification_and_values_survive_an_nmt_reset(state_home, cfg3):
    targets = targets_of(cfg3)
    with ArmSession.open(cfg3, sim=SimArm.in_process(cfg3)) as session:
        plans = program.read_plans(session, targets, need_serial=True)
        result = program.apply_plans(session, plans, save=True, ledger=SaveLedger())
        assert result.ok
        d1 = session.sim.drives["drive1"]
        reqs = requests(d1)
        sv = [i for i, r in enumerate(reqs) if r.kind == "execute"]
        assert [reqs[i].letters for i in sv] == ["SV"]
        last_key = plans[0].write_order[-1]
        last_set = max(i for i, r in enumerate(reqs) if r.kind == "set")
        readback = max(i for i, r in enumerate(reqs) if r.kind == "query" and key_of(r) == last_key and i < sv[0])
        assert last_set < readback < sv[0], "SV only after the last write was read back"
        c1 = client(session, "drive1")
        boots = d1.boots
        c1.reset_node(10.0)  # RAM from flash (reset communication would keep RAM: CiA 301)
        assert d1.boots == boots + 1
        for key, value in targets[0].params.items():
            letters, index = codec.parse_expr(key).letters, codec.parse_expr(key).index
            assert c1.get(letters, index) == value, key


def test_without_save_an_nmt_reset_loses_the_values(state_home, cfg3):
    with ArmSession.open(cfg3, sim=SimArm.in_process(cfg3)) as session:
        plans = program.read_plans(session, targets_of(cfg3, ["drive1"]))
        assert program.apply_plans(session, plans).ok
        c1 = client(session, "drive1")
        assert c1.get("LL", 3) == -205
        c1.reset_node(10.0)
        assert c1.get("LL", 3) == -1_000_000_000


def test_motor_on_is_refused_without_motor_off(state_home, cfg3):
    targets = targets_of(cfg3)
    with ArmSession.open(cfg3, sim=SimArm.in_process(cfg3)) as session:
        c1 = client(session, "drive1")
        c1.nmt_start()
        c1.motor_on()
        d1 = session.sim.drives["drive1"]
        mark = len(d1.received)
        plans = program.read_plans(session, targets)
        assert plans[0].motor_on and not plans[1].motor_on
        with pytest.raises(SafetyError, match=r"motor is on: drive1;.*nothing was written"):
            program.check_apply(plans, motor_off=False)
        assert sets(d1, mark) == [] and d1.motor_on
        program.check_apply(plans, motor_off=True)
        result = program.apply_plans(session, plans)
        assert result.ok and result.outcomes[0].motor_switched_off and not result.outcomes[1].motor_switched_off
        assert not d1.motor_on
        written = sets(d1, mark)
        assert written[0] == ("MO", 0), "the motor goes off before the first parameter"


def test_sv_without_an_answer_after_it_is_reported_as_sent_and_counted(state_home, cfg3, monkeypatch):
    # SV is never resent; if the drive stays silent after the blackout its flash may hold the new
    # values: the report must not say "NOT saved", and the flash-wear count must include it.
    from sherpa_cli.elmo.client import DriveClient
    from sherpa_cli.errors import DriveTimeoutError

    real_save = DriveClient.save

    def save_then_silence(self):
        real_save(self)
        raise DriveTimeoutError(f"{self.label}: no answer to MO (after SV) within 0.1 s")

    monkeypatch.setattr(DriveClient, "save", save_then_silence)
    targets = targets_of(cfg3)
    with ArmSession.open(cfg3, sim=SimArm.in_process(cfg3)) as session:
        plans = program.read_plans(session, targets, need_serial=True)
        ledger = SaveLedger()
        result = program.apply_plans(session, plans, save=True, ledger=ledger)
        for o, p in zip(result.outcomes, plans, strict=True):
            assert o.status == "failed" and o.sv_sent and not o.saved
            assert o.error.startswith("SV was sent but") and "unknown" in o.error
            assert o.save_count == 1 and ledger.count(p.serial) == 1
            assert executes(session.sim.drives[o.drive]) == ["SV"], "SV is sent once, never again"
        err = program.exit_problem(result)
        assert err is not None and err.exit_code == 1 and "SV sent, save not confirmed" in err.message


def test_a_ledger_that_cannot_be_written_does_not_hide_the_saves(state_home, cfg3, tmp_path):
    blocker = tmp_path / "not-a-dir"
    blocker.write_text("x")
    ledger = SaveLedger(blocker / "save-ledger.json")  # its directory cannot be created
    targets = targets_of(cfg3)
    with ArmSession.open(cfg3, sim=SimArm.in_process(cfg3)) as session:
        plans = program.read_plans(session, targets, need_serial=True)
        result = program.apply_plans(session, plans, ledger=ledger)
        assert result.ok and all(o.status == "programmed" for o in result.outcomes)
        assert all("save ledger" in o.save_warning and "not updated" in o.save_warning for o in result.outcomes)
    sim_state.power_cycle(cfg3)  # --sim keeps the arm powered; this test wants it power-cycled
    with ArmSession.open(cfg3, sim=SimArm.in_process(cfg3)) as session:  # a new power-up: RAM holds the old values again
        plans = program.read_plans(session, targets, need_serial=True)
        result = program.apply_plans(session, plans, save=True, ledger=ledger)
        assert result.ok and all(o.status == "saved" and o.saved for o in result.outcomes)
        assert all("not updated" in o.save_warning for o in result.outcomes)
        assert all(d.save_count == 1 for d in session.sim.drives.values())


def test_interrupt_from_progress_callback_leaves_no_drive_saved(state_home, cfg3):
    targets = targets_of(cfg3)
    seen = []

    def on_event(event):
        if event.kind == program.EV_WRITTEN:
            seen.append(event)
            if len(seen) == 5:
                raise KeyboardInterrupt

    with ArmSession.open(cfg3, sim=SimArm.in_process(cfg3)) as session:
        plans = program.read_plans(session, targets, need_serial=True)
        result = program.apply_plans(session, plans, save=True, ledger=SaveLedger(), on_event=on_event)
        assert result.interrupted and not result.ok
        for o in result.outcomes:
            d = session.sim.drives[o.drive]
            assert not o.saved and executes(d) == [] and d.save_count == 0 and d.flash == {}
            assert o.status in ("interrupted", "not started")
            assert [k for k, _ in sets(d)] == o.written, "the report names exactly what was written"
            assert set(o.verified) <= set(o.written)
        assert sum(len(o.written) for o in result.outcomes) < 34


def test_ctrl_c_in_the_waiting_thread_stops_drives_at_a_safe_point(state_home, cfg3):
    targets = targets_of(cfg3)
    fired = []

    def on_event(event):
        if event.kind == program.EV_VERIFIED and not fired:
            fired.append(event)
            # what Ctrl-C does: SIGINT to the main thread, which is waiting for the drives
            signal.pthread_kill(threading.main_thread().ident, signal.SIGINT)

    with ArmSession.open(cfg3, sim=SimArm.in_process(cfg3)) as session:
        plans = program.read_plans(session, targets, need_serial=True)
        result = program.apply_plans(session, plans, save=True, ledger=SaveLedger(), on_event=on_event)
        assert result.interrupted
        for o in result.outcomes:
            d = session.sim.drives[o.drive]
            assert executes(d) == [] and d.flash == {}
            assert o.status in ("interrupted", "not started")
            assert o.written == o.verified, "a drive stops between two writes, not inside one"
            assert [k for k, _ in sets(d)] == o.written


def test_an_unknown_name_is_refused_before_any_bus_is_opened(cli, cfg3):
    r = cli("--config", EXAMPLE3, "--sim", "program-limits", "drive9")
    assert r.exit_code == 2 and "unknown target 'drive9'" in r.stderr


# --------------------------------------------------------------------------- CLI

@pytest.fixture
def sim_arms(monkeypatch):
    """The in-process simulated arms the CLI creates, with optional faults per drive."""
    from sherpa_cli.sim.arm import SimArm

    arms: list = []
    faults: dict[str, dict] = {}  # drive -> SimSettings fields to replace
    original = SimArm.for_session.__func__

    def for_session(cls, cfg, channels, **kwargs):
        arm = original(cls, cfg, channels, **kwargs)
        for name, changes in faults.items():
            arm.drives[name].settings = dataclasses.replace(arm.drives[name].settings, **changes)
        arms.append(arm)
        return arm

    monkeypatch.setattr(SimArm, "for_session", classmethod(for_session))
    return arms, faults


def _cli_sets(arm) -> dict[str, list]:
    return {n: sets(d) for n, d in arm.drives.items()}


GOLDEN_CASES = [
    ("program-limits-example1-plan", ["--config", "configs/appendix-c/example1.yaml", "--sim", "program-limits"]),
    ("program-limits-example2-plan", ["--config", "configs/appendix-c/example2.yaml", "--sim", "program-limits"]),
    ("program-limits-example3-plan", ["--config", EXAMPLE3, "--sim", "program-limits"]),
    ("program-limits-example1-apply", ["--config", "configs/appendix-c/example1.yaml", "--sim", "program-limits",
                                       "--apply"]),
    ("program-limits-example3-apply", ["--config", EXAMPLE3, "--sim", "program-limits", "drive2", "--apply"]),
    ("program-limits-example2-save", ["--config", "configs/appendix-c/example2.yaml", "--sim", "program-limits",
                                      "--apply", "--save", "--yes"]),
    ("program-limits-example3-json", ["--config", EXAMPLE3, "--sim", "--json", "program-limits", "pair1",
                                      "--apply", "--save", "--yes"]),
    ("program-limits-save-without-apply", ["--config", EXAMPLE3, "--sim", "program-limits", "--save"]),
    ("program-limits-save-no-tty", ["--config", EXAMPLE3, "--sim", "program-limits", "--apply", "--save"]),
    ("program-limits-help", ["program-limits", "--help"]),
]


@pytest.mark.golden
@pytest.mark.parametrize("name,args", GOLDEN_CASES, ids=[c[0] for c in GOLDEN_CASES])
def test_program_limits_golden(cli, golden, sim_arms, name, args):
    result = cli(*args)
    assert "Traceback" not in result.stderr
    golden(f"{name}.txt", result.transcript())
    arms, _ = sim_arms
    if "--apply" not in args or ("--save" in args and "--yes" not in args):
        for arm in arms:
            assert all(v == [] for v in _cli_sets(arm).values()), "nothing written"


@pytest.mark.golden
def test_program_limits_save_then_again_writes_nothing(cli, golden, sim_arms):
    args = ["--config", EXAMPLE3, "--sim", "program-limits", "--apply", "--save", "--yes"]
    first = cli(*args)
    assert first.exit_code == 0, first.stderr
    golden("program-limits-example3-save.txt", first.transcript())
    again = cli(*args)
    golden("program-limits-example3-save-again.txt", again.transcript())
    arms, _ = sim_arms
    assert all(v == [] for v in _cli_sets(arms[-1]).values())
    assert all(executes(d) == [] for d in arms[-1].drives.values())


@pytest.mark.golden
def test_program_limits_mismatch_golden(cli, golden, sim_arms):
    arms, faults = sim_arms
    faults["drive1"] = {"store_skew": (("VH[3]", -1),)}
    result = cli("--config", EXAMPLE3, "--sim", "program-limits", "--apply", "--save", "--yes")
    assert result.exit_code == 1
    golden("program-limits-example3-mismatch.txt", result.transcript())
    assert executes(arms[0].drives["drive1"]) == []
    assert executes(arms[0].drives["drive2"]) == ["SV"]


def test_a_silent_drive_is_reported_and_nothing_is_written(cli, sim_arms, tmp_path):
    arms, _ = sim_arms
    config = tmp_path / "example3-dead.yaml"
    config.write_text((ROOT / EXAMPLE3).read_text() + "\nsim:\n  drives:\n    drive2: {die_at: 0.001}\n")
    dry = cli("--config", str(config), "--sim", "program-limits")
    assert dry.exit_code == 3 and "drive2: cannot be written: drive2 (node 2): no answer" in dry.stdout
    applied = cli("--config", str(config), "--sim", "program-limits", "--apply")
    assert applied.exit_code == 3 and "nothing was written" in applied.stderr
    assert sets(arms[-1].drives["drive1"]) == []


def test_appendix_c_example3_numbers_arrive_and_survive_the_power_cycle(cli):
    r = cli("--config", EXAMPLE3, "--sim", "program-limits", "--apply", "--save", "--yes")
    assert r.exit_code == 0, r.stderr
    keys = ["VL[3]", "VH[3]", "LL[3]", "HL[3]", "IL[1]", "IL[2]", "IL[3]", "IL[4]"]
    for drive in ("drive1", "drive2"):
        read = cli("--config", EXAMPLE3, "--sim", "--json", "cmd", drive, *keys)  # a new invocation
        values = {x["command"]: x["value"] for x in json.loads(read.stdout)["results"]}
        assert values == {"VL[3]": -190, "VH[3]": 190, "LL[3]": -205, "HL[3]": 205,
                          "IL[1]": 21, "IL[2]": 21, "IL[3]": 21, "IL[4]": 21}


def test_save_ledger_file_counts_cli_saves(cli, tmp_path):
    from sherpa_cli.sim.state import default_serial

    cfg = load_config(ROOT / EXAMPLE3)
    cli("--config", EXAMPLE3, "--sim", "program-limits", "--apply", "--save", "--yes")
    data = json.loads((tmp_path / "state" / "sherpa-cli" / "save-ledger.json").read_text())
    serial = f"0x{default_serial(cfg, 'drive1'):08X}"
    assert data["drives"][serial] == {"saves": 1, "last_name": "drive1"}


ARM_CASES = [
    ("program-limits-arm-plan", ["program-limits"]),
    ("program-limits-arm-apply", ["program-limits", "--apply"]),
    ("program-limits-arm-elbow-json", ["--json", "program-limits", "elbow_pitch", "--apply"]),
]


@pytest.mark.golden
@pytest.mark.realbus
@pytest.mark.parametrize("name,args", ARM_CASES, ids=[c[0] for c in ARM_CASES])
def test_program_limits_on_the_arm_golden(arm_golden, name, args):
    arm_golden(name, args)
