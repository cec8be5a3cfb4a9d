"""Is a joint calibrated (its drive's position counter means the joint's position)?

A joint with an absolute encoder (``abs_encoder`` in the config) always is. Any other joint's
motor counter (PX) starts at 0 at power-up, wherever the joint stands, so it is calibrated only
after homing since that power-up. Homing marks each drive it calibrated by writing 1 to
``UI[protocol.calibration_flag]`` (default UI[3]; the homed flag of [KX2]-style tools). UI is a
RAM variable: a reset or power cycle clears it, which is exactly when the calibration is lost.
Whether SV copies UI to flash is UNCONFIRMED for the Whistle; sherpa never saves right after
homing, and a drive that saved UI=1 would look homed after a reboot, so the index is a setting
and the program engine's SV clears the mark first (:func:`clear_for_save`, put back after).

A Σ or Δ joint depends on both motors of its pair: it is calibrated when both drives carry the
mark (or when both joints of the pair have an absolute encoder).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

from sherpa_cli.config.model import ArmConfig, JointConfig, JointRole

if TYPE_CHECKING:
    from sherpa_cli.elmo.client import DriveClient

CALIBRATED = 1
# a home that saw its switch (PX set from the switch's edge) and did not finish: not calibrated, but
# the next home may trust PX to know on which side of the switch the joint stands (ops/home.py)
SWITCH_SEEN = 2


@dataclass(frozen=True)
class Calibration:
    joint: str
    calibrated: bool
    reason: str  # "absolute encoder", "homed since power-up (UI[3]=1)", "not homed since power-up: ..."

    def as_dict(self) -> dict[str, object]:
        return {"joint": self.joint, "calibrated": self.calibrated, "reason": self.reason}


def absolute(cfg: ArmConfig, joint: JointConfig) -> bool:
    """True when the joint's position needs no homing (absolute encoder on it, or on both pair joints)."""
    if joint.role is JointRole.PLAIN:
        return joint.abs_encoder is not None
    pair = cfg.pairs[joint.pair]  # type: ignore[index]
    return all(cfg.joints[n].abs_encoder is not None for n in (pair.sigma, pair.delta))


def joint_drives(cfg: ArmConfig, joint: JointConfig) -> tuple[str, ...]:
    if joint.role is JointRole.PLAIN:
        return (joint.drive,) if joint.drive else ()
    pair = cfg.pairs[joint.pair]  # type: ignore[index]
    return (pair.drive_a, pair.drive_b)


def flag_key(cfg: ArmConfig) -> str:
    return f"UI[{cfg.protocol.calibration_flag}]"


def judge(cfg: ArmConfig, joint: JointConfig, flags: Mapping[str, int]) -> Calibration:
    """The decision on values already read: ``flags`` maps each drive of the joint to its UI flag."""
    if absolute(cfg, joint):
        return Calibration(joint.name, True, "absolute encoder")
    key = flag_key(cfg)
    missing = [d for d in joint_drives(cfg, joint) if flags.get(d) != CALIBRATED]
    if missing:
        shown = ", ".join(f"{d} {key}={flags.get(d, '?')}" for d in missing)
        if any(flags.get(d) == SWITCH_SEEN for d in missing):
            return Calibration(joint.name, False, f"not homed: a home that met its switch did not finish ({shown})")
        return Calibration(joint.name, False, f"not homed since power-up ({shown})")
    return Calibration(joint.name, True, f"homed since power-up ({key}={CALIBRATED})")


def read_calibration(cfg: ArmConfig, joint: JointConfig, client_of: Callable[[str], DriveClient], *,
                     resync: bool = False) -> Calibration:
    """Read the flag from each drive of the joint.

    An absolute joint read by its drive's auxiliary counter (``drive:PY``) is checked instead: its
    motor counter PX must mean the encoder's position, because the limits and the watch use PX, and
    PX restarts at 0 when the drive resets (a flash proof, a power cycle, an NMT reset) wherever the
    joint stands. It is never assumed: a moving command's entry passes ``resync``
    and PX is set from the encoder with the motor off (read back); a looking command (monitor,
    doctor) only says it does not match.
    """
    # a drive the config does not list (a joint built by hand) is Elmo's, as every drive by default
    kinds = {dc.type for d in joint_drives(cfg, joint) if (dc := cfg.drives.get(d)) is not None}
    others = sorted(k for k in kinds if k != "elmo")
    if others:
        # the homing flag and offsets live in Elmo user variables: another drive type has none here
        return Calibration(joint.name, False, f"on a {others[0]} drive, whose homing sherpa does not keep "
                                              "(docs/cia402.md): pass --uncalibrated to move by its counter")
    if absolute(cfg, joint):
        mismatch = _counter_mismatch(cfg, joint, client_of)
        if mismatch is None:
            return judge(cfg, joint, {})
        return _resynced(cfg, joint, client_of, *mismatch) if resync else Calibration(
            joint.name, False, f"its counter PX={mismatch[0]} does not match its absolute encoder ({mismatch[1]} "
            "counts): the drive's counter restarted (a reset or power cycle?); a moving command or `sherpa home` "
            "re-syncs it with the motor off")
    index = cfg.protocol.calibration_flag
    flags = {d: int(client_of(d).get("UI", index)) for d in joint_drives(cfg, joint)}
    return judge(cfg, joint, flags)


SYNC_TOLERANCE = 2  # counts PX may differ from the encoder's reading (a motor holding position)


def encoder_on_drive(joint: JointConfig) -> bool:
    """The joint is a plain one whose absolute encoder its own drive reads (``drive:PY``)."""
    enc = joint.abs_encoder
    return joint.role is JointRole.PLAIN and enc is not None and enc.source.upper() == "DRIVE:PY" \
        and joint.drive is not None


def counter_mismatch_text(joint: JointConfig, px: int, py: int) -> str | None:
    """Why the joint's counter ``px`` does not mean its encoder (``py`` + offset), or None when it does
    (within SYNC_TOLERANCE): for the looking commands, which show it and write nothing."""
    assert joint.abs_encoder is not None
    expected = py + joint.abs_encoder.offset
    if abs(px - expected) <= SYNC_TOLERANCE:
        return None
    return (f"not calibrated: its counter PX={px} does not match its absolute encoder ({expected} counts); a "
            "moving command or `sherpa home` re-syncs it")


def _counter_mismatch(cfg: ArmConfig, joint: JointConfig,
                      client_of: Callable[[str], DriveClient]) -> tuple[int, int] | None:
    """(PX, the encoder's position) when a plain joint's counter does not mean its drive's absolute
    encoder (``drive:PY``), else None. An encoder on the bus (CiA 406) is read by `sherpa home`."""
    if not encoder_on_drive(joint):
        return None
    assert joint.drive is not None and joint.abs_encoder is not None
    c = client_of(joint.drive)
    px, expected = int(c.get("PX")), int(c.get("PY")) + joint.abs_encoder.offset
    return None if abs(px - expected) <= SYNC_TOLERANCE else (px, expected)


def _resynced(cfg: ArmConfig, joint: JointConfig, client_of: Callable[[str], DriveClient],
              px: int, expected: int) -> Calibration:
    """PX := the encoder's position, only with the motor off (a moving motor's counter is the servo's
    reference), read back."""
    assert joint.drive is not None and joint.abs_encoder is not None
    c = client_of(joint.drive)
    if int(c.get("MO")):
        return Calibration(joint.name, False, f"its counter PX={px} does not match its absolute encoder ({expected} "
                           "counts) and its motor is on: stop it (`sherpa stop`) so the counter can be re-synced")
    c.set("PX", 0, expected)
    now = int(c.get("PX"))
    back = int(c.get("PY")) + joint.abs_encoder.offset
    if abs(now - back) > SYNC_TOLERANCE:
        return Calibration(joint.name, False, f"its counter could not be re-synced with its absolute encoder "
                           f"(PX={now} after PX={expected} was written, encoder {back})")
    return Calibration(joint.name, True, f"absolute encoder (counter re-synced: PX was {px}, now {now})")


def mark_calibrated(cfg: ArmConfig, client: DriveClient) -> None:
    """For `home`: the drive's position counter now means the joint position, until its next reset."""
    client.set("UI", cfg.protocol.calibration_flag, CALIBRATED)


def mark_switch_seen(cfg: ArmConfig, client: DriveClient) -> None:
    """For `home`, once its search met the switch: PX counts from the switch until the next reset."""
    client.set("UI", cfg.protocol.calibration_flag, SWITCH_SEEN)


def switch_seen(cfg: ArmConfig, client: DriveClient) -> bool:
    """Whether an unfinished home left :data:`SWITCH_SEEN` (since the drive's last reset)."""
    return int(client.get("UI", cfg.protocol.calibration_flag)) == SWITCH_SEEN


def clear_calibrated(cfg: ArmConfig, client: DriveClient) -> None:
    """For `home`, before it arms the drive's homing: a re-home that fails after it reset PX must
    not leave the old mark on a counter that no longer means the joint."""
    client.set("UI", cfg.protocol.calibration_flag, 0)


def clear_for_save(cfg: ArmConfig, client: DriveClient) -> int:
    """Before SV: whether SV copies UI to flash is UNCONFIRMED, and a flash holding the mark would
    make the joint look homed after a power cycle (PX = 0 wherever it stands). Clears the mark in
    RAM if set; returns what it was, for :func:`restore_after_save`."""
    index = cfg.protocol.calibration_flag
    was = int(client.get("UI", index))
    if was:
        client.set("UI", index, 0)
    return was


def restore_after_save(cfg: ArmConfig, client: DriveClient, was: int) -> None:
    """After a confirmed SV: the mark back in RAM (SV does not touch PX, so it still holds)."""
    if was:
        client.set("UI", cfg.protocol.calibration_flag, was)
