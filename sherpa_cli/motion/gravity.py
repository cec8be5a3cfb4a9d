"""Gravity-loaded joints: what switching their motor off does, said before a command does it.

A joint marked ``gravity: true`` in the config (a pitch joint with no brake) falls when its motor is
switched off. Every motion command ends with MO=0 unless it holds (`jog --hold`), and the drive's
own dead-man switches the motor off when the tool dies (motion.loss_action, 0x6007): the command
says so first, naming the joints, so nobody learns it from a falling arm.
"""

from __future__ import annotations

from collections.abc import Iterable

from sherpa_cli.config.model import ArmConfig


def gravity_joints(cfg: ArmConfig, joints: Iterable[str]) -> list[str]:
    """The gravity-loaded joints among ``joints`` (and the other joint of a pair: both ride on the motors)."""
    names = set(joints)
    for j in list(names):
        joint = cfg.joints.get(j)
        if joint is not None and joint.pair is not None:
            names.update(o.name for o in cfg.joints.values() if o.pair == joint.pair)
    return sorted(n for n in names if n in cfg.joints and cfg.joints[n].gravity)


def gravity_notice(cfg: ArmConfig, joints: Iterable[str], *, holds: bool = False) -> str | None:
    """One line to say before the motion, or None when no moved joint is gravity-loaded."""
    loaded = gravity_joints(cfg, joints)
    if not loaded:
        return None
    which = ", ".join(loaded)
    if holds:
        return (f"{which}: gravity-loaded: held after the move (--hold); Ctrl-C or `sherpa stop` switches the "
                "motor off and the joint falls unless a brake holds it")
    return (f"{which}: gravity-loaded: the motor is switched off at the end and the joint falls unless a brake "
            "holds it (also when the tool dies: the drive's dead-man switches it off); --hold keeps it held")
