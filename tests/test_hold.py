"""`--hold` of a pair's Σ/Δ joint, a pair motor and `diffdrive move` (motion/hold.py),
on the matrix's simulated arm running on stepped time (sim/stepped.py): during the hold every motor
of the command is on and stands at the PA the hold gave it; MO=0 from elsewhere (what `sherpa stop`
ends with) ends the hold normally, Ctrl-C too; a fault ends it with an error naming the drive. The
invariant matrix (test_motion_matrix.py, rows *-hold) covers every way out of a hold."""

from __future__ import annotations

import json
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from test_motion_matrix import ARM, PAIR, RUN_FOR, SPEED, _prepare

from sherpa_cli.api import Arm
from sherpa_cli.bus.session import ArmSession
from sherpa_cli.bus.targets import drive_ref
from sherpa_cli.config import load_config
from sherpa_cli.errors import SafetyError
from sherpa_cli.motion.hold import HELD_UNTIL_CTRL_C, HELD_UNTIL_STOPPED
from sherpa_cli.ops.jog_result import JogResult
from sherpa_cli.sim.arm import SimArm
from sherpa_cli.sim.stepped import SteppedTime

LOOK_AT = RUN_FOR + 1.5  # s of stepped time after the start: the move is over, the motors held
END_AT = LOOK_AT + 0.5  # s: the hold is ended (MO=0, Ctrl-C or a fault)


def _jog(name: str) -> Callable[[ArmSession, SteppedTime], Any]:
    """A velocity jog with --hold through the API, on the stepped time (Arm.move takes the clock)."""
    def run(s: ArmSession, st: SteppedTime) -> Any:
        from sherpa_cli.motion.axis import resolve_axis
        from sherpa_cli.motion.request import parse_request

        axis = resolve_axis(s.cfg, name)
        req = parse_request(axis, "velocity", velocity=f"{-SPEED}counts/s", duration=RUN_FOR, hold=True)
        return Arm(s).move(axis, req, clock=st.now, sleep=st.sleep)
    return run


def _move(s: ArmSession, st: SteppedTime) -> Any:
    return Arm(s).diffdrive_move("diff", sigma="-200counts", delta="0counts", relative=True,
                                 velocity=f"{SPEED}counts/s", hold=True, timebase=st)


COMMANDS = {"sigma": _jog("pitch"), "delta": _jog("roll"), "pair_motor": _jog("pair_a"), "diffdrive": _move}


def _hold(command: str, end: str) -> tuple[Any, BaseException | None, dict[str, Any], dict[str, bool]]:
    """Run ``command`` with --hold; at LOOK_AT what the drives do is noted, at END_AT the hold is
    ended by ``end`` (``mo0``: MO=0 to every motor from another client, ``ctrl_c``, ``fault``)."""
    cfg = load_config(ARM)
    st = SteppedTime()
    arm = SimArm(cfg, {"can0": {"interface": "virtual", "channel": f"hold-{uuid.uuid4().hex[:8]}"}}, clock=st.clock)
    seen: dict[str, Any] = {}
    value, error = None, None
    with ArmSession.open(cfg, sim=arm) as s:
        s.client_overrides.update(st.client_overrides(cfg.protocol.reply_timeout, cfg.protocol.retries))
        _prepare(s, cfg)
        t0 = st.now()
        sleep = st.sleep

        def stepped(seconds: float) -> None:
            sleep(seconds)
            now = st.now() - t0
            if "at" not in seen and now >= LOOK_AT:
                with arm.lock:
                    seen["at"] = {d: (arm.drives[d].motor_on, arm.drives[d].motor.rounded, arm.drives[d].motor.v,
                                      arm.drives[d].ram.get("PA"), arm.drives[d].ram.get("UM")) for d in PAIR}
            if "at" in seen and "ended" not in seen and now >= END_AT:
                seen["ended"] = True
                if end == "ctrl_c":
                    raise KeyboardInterrupt
                if end == "fault":
                    with arm.lock:
                        arm.drives["pair_b"].trip()
                else:  # what `sherpa stop` from a second terminal ends with
                    for d in PAIR:
                        s.client(drive_ref(cfg, d)).motor_off()
        st.sleep = stepped  # type: ignore[method-assign]  # every wait of the command goes through it
        try:
            value = COMMANDS[command](s, st)
        except BaseException as exc:  # noqa: BLE001 - looked at by the tests
            error = exc
        with arm.lock:
            for d in arm.drives.values():
                d.advance_to(st.clock.now())
            off = {d: not arm.drives[d].motor_on for d in PAIR}
    return value, error, seen, off


def _moved(command: str) -> tuple[str, ...]:
    return ("pair_a",) if command == "pair_motor" else PAIR


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_while_held_every_motor_is_on_and_stands_at_its_target_and_mo0_ends_the_hold_normally(command):
    value, error, seen, off = _hold(command, "mo0")
    assert error is None, repr(error)
    assert value.held_until == HELD_UNTIL_STOPPED
    held_at = value.held_at
    assert set(held_at) == set(_moved(command))
    for d in _moved(command):
        on, position, v, pa, um = seen["at"][d]
        assert on and um == 5 and pa == held_at[d], (d, seen["at"][d])  # held in position mode at its PA
        assert abs(position - held_at[d]) <= 1 and abs(v) <= 2.0, (d, seen["at"][d])  # standing there
    assert all(off.values())  # the guard's exit switched every motor off
    data = value.as_json() if isinstance(value, JogResult) else value.as_dict()  # a jog, or diffdrive move
    assert data["hold"] == {"at": held_at, "ended_by": HELD_UNTIL_STOPPED}
    json.dumps(data)


@pytest.mark.parametrize("command", ["sigma", "diffdrive"])
def test_ctrl_c_ends_the_hold_normally_and_the_result_says_where_it_ended(command):
    value, error, seen, off = _hold(command, "ctrl_c")
    assert error is None, repr(error)
    assert value.held_until == HELD_UNTIL_CTRL_C and all(off.values())
    assert all(seen["at"][d][0] for d in _moved(command))  # on while held, before the Ctrl-C
    ends = value.motors_end
    assert all(abs(ends[d] - value.held_at[d]) <= 1 for d in _moved(command)), (ends, value.held_at)


@pytest.mark.parametrize("command", ["delta", "diffdrive"])
def test_a_fault_during_the_hold_is_an_error_naming_the_drive(command):
    _value, error, _seen, off = _hold(command, "fault")
    assert isinstance(error, SafetyError) and "pair_b" in str(error), repr(error)
    assert all(off.values())


def test_the_dry_runs_say_the_motors_are_held(cli):
    dry = cli("--config", str(ARM), "jog", "pitch", "--velocity", "-0.1", "--for", "0.4", "--hold")
    assert dry.exit_code == 0, dry.transcript()
    assert "then hold where it stands until Ctrl-C or `sherpa stop`" in dry.stdout
    plain = cli("--config", str(ARM), "jog", "pitch", "--velocity", "-0.1", "--for", "0.4")
    assert "then stop and switch off" in plain.stdout
    move = cli("--config", str(ARM), "--sim", "diffdrive", "move", "diff", "--sigma", "-200counts", "--relative",
               "--uncalibrated", "--hold")
    assert move.exit_code == 0, move.transcript()
    assert "then hold where they stand until Ctrl-C or `sherpa stop`" in move.stdout


def test_a_pair_motor_names_the_gravity_loaded_joints_it_moves(cli, tmp_path):
    import yaml

    data = yaml.safe_load(Path("configs/sherpa-arm.yaml").read_text())
    pair = next(iter(data["pairs"].values()))
    pair["sigma"]["gravity"] = True
    sigma, motor = pair["sigma"]["name"], pair["drives"][0]
    path = tmp_path / "arm.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    assert cli("--config", str(path), "config", "check").exit_code == 0
    moved = cli("--config", str(path), "--sim", "jog", motor, "--velocity", "0.02", "--for", "0.2", "--apply")
    assert moved.exit_code == 0, moved.transcript()
    assert f"{sigma}: gravity-loaded: the motor is switched off at the end" in moved.stderr
