"""The one target policy: which drives a name means, and which motors and joints it would move.

A name on the command line is, in this order of lookup:

- a **drive** of the config (``shoulder_2a``): that drive;
- a **joint** (``elbow_pitch``): a plain joint's drive; a Σ or Δ joint of a differential pair
  names *both* motors of the pair, since neither moves that joint alone;
- a **pair** (``shoulder_diff``): both motors, and its Σ and Δ joints;
- an **address** ``BUS:NODE`` (``can0:20``): the configured drive there, else an ad-hoc drive
  (commands that work on configured drives only refuse it).

Drives come in config order within a target; :func:`resolve` and :func:`drive_refs` never
repeat a drive. Commands that talk to exactly one drive (``sherpa cmd``) use
:func:`single_drive`, which refuses a name that means two motors. Every command resolves its
names here; nothing else in the tool decides what a name means.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from enum import Enum

from sherpa_cli.config.model import ArmConfig, DriveConfig, JointConfig, JointRole, PairConfig
from sherpa_cli.errors import UsageError

MAX_NODE = 127


class TargetKind(str, Enum):  # noqa: UP042  StrEnum would change str()/format() of a member ('drive', not 'TargetKind.DRIVE')
    DRIVE = "drive"
    JOINT = "joint"
    PAIR = "pair"
    ADDRESS = "address"  # BUS:NODE as typed


@dataclass(frozen=True)
class DriveRef:
    """A drive addressed by the user: configured (``config`` set) or ad hoc as BUS:NODE."""

    name: str
    bus: str
    node: int
    config: DriveConfig | None = None

    @property
    def address(self) -> str:
        return f"{self.bus}:{self.node}"

    @property
    def key(self) -> tuple[str, int]:
        """What identifies the drive on the wire: (bus, node)."""
        return (self.bus, self.node)


@dataclass(frozen=True)
class Target:
    """What one name means: the drives (config order) and, for motion, the joints it moves.

    ``joints``: a plain joint, or the Σ/Δ joint named; for a pair both its joints; for a
    configured drive the joint(s) its motor moves (a pair motor moves Σ and Δ). Empty for an
    ad-hoc BUS:NODE. ``pair`` is the differential pair involved, if any.
    """

    text: str
    kind: TargetKind
    drives: tuple[DriveRef, ...]
    joints: tuple[JointConfig, ...] = ()
    pair: PairConfig | None = None

    @property
    def drive_names(self) -> tuple[str, ...]:
        return tuple(d.name for d in self.drives)

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints)

    @property
    def configured(self) -> bool:
        """Every drive of the target is a drive of the config."""
        return all(d.config is not None for d in self.drives)


# --------------------------------------------------------------------------- building blocks

def drive_ref(cfg: ArmConfig, name: str) -> DriveRef:
    """The DriveRef of a configured drive (by its name)."""
    d = cfg.drives[name]
    return DriveRef(d.name, d.bus, d.node, d)


def _in_config_order(cfg: ArmConfig, names: Iterable[str]) -> tuple[DriveRef, ...]:
    order = {name: i for i, name in enumerate(cfg.drives)}
    wanted = [n for n in dict.fromkeys(names) if n in cfg.drives]
    return tuple(drive_ref(cfg, n) for n in sorted(wanted, key=order.__getitem__))


def _pair_joints(cfg: ArmConfig, pair: PairConfig) -> tuple[JointConfig, ...]:
    return tuple(cfg.joints[j] for j in (pair.sigma, pair.delta) if j in cfg.joints)


def _drive_target(cfg: ArmConfig, text: str, kind: TargetKind, name: str) -> Target:
    joint = cfg.joint_of_drive(name)
    pair = cfg.pair_of_drive(name)
    if joint is not None:
        joints: tuple[JointConfig, ...] = (joint,)
    elif pair is not None:
        joints = _pair_joints(cfg, pair)
    else:
        joints = ()
    return Target(text, kind, (drive_ref(cfg, name),), joints, pair)


def _joint_target(cfg: ArmConfig, text: str, joint: JointConfig) -> Target:
    if joint.role is JointRole.PLAIN:
        if joint.drive and joint.drive in cfg.drives:
            return Target(text, TargetKind.JOINT, (drive_ref(cfg, joint.drive),), (joint,), None)
    else:
        pair = cfg.pairs.get(joint.pair) if joint.pair else None
        if pair is not None:
            return Target(text, TargetKind.JOINT, _in_config_order(cfg, (pair.drive_a, pair.drive_b)),
                          (joint,), pair)
    raise UsageError(f"joint '{text}' has no drive in the config", hint="see `sherpa config check`")


def _pair_target(cfg: ArmConfig, text: str, pair: PairConfig) -> Target:
    return Target(text, TargetKind.PAIR, _in_config_order(cfg, (pair.drive_a, pair.drive_b)),
                  _pair_joints(cfg, pair), pair)


def _address_target(cfg: ArmConfig, text: str, bus: str, node_text: str) -> Target:
    if bus not in cfg.buses:
        raise UsageError(f"target '{text}': no bus '{bus}' in the config",
                         hint=f"configured buses: {', '.join(cfg.buses)}")
    if not (node_text.isascii() and node_text.isdigit()) or not 1 <= int(node_text) <= MAX_NODE:
        raise UsageError(f"target '{text}': node id must be 1..{MAX_NODE}")
    node = int(node_text)
    for d in cfg.drives.values():
        if d.bus == bus and d.node == node:
            return _drive_target(cfg, text, TargetKind.ADDRESS, d.name)
    return Target(text, TargetKind.ADDRESS, (DriveRef(f"{bus}:{node}", bus, node, None),))


def unknown_target(cfg: ArmConfig, text: str) -> UsageError:
    """The error for a name that is nothing in the config, with the closest names as a hint."""
    names = [*cfg.drives, *cfg.joints, *cfg.pairs]
    close = difflib.get_close_matches(text, names, n=3)
    if close:
        hint = "did you mean " + (", ".join(close[:-1]) + " or " if len(close) > 1 else "") + close[-1] + "?"
    else:
        hint = "see `sherpa config check` for the names"
    return UsageError(f"unknown target '{text}': not a drive, joint, pair or BUS:NODE of the config", hint=hint)


# --------------------------------------------------------------------------- the policy

def resolve_one(cfg: ArmConfig, text: str) -> Target:
    """What one name means (see the module's docstring for the order of lookup)."""
    if text in cfg.drives:
        return _drive_target(cfg, text, TargetKind.DRIVE, text)
    if text in cfg.joints:
        return _joint_target(cfg, text, cfg.joints[text])
    if text in cfg.pairs:
        return _pair_target(cfg, text, cfg.pairs[text])
    bus, sep, node_text = text.partition(":")
    if sep:
        return _address_target(cfg, text, bus, node_text)
    raise unknown_target(cfg, text)


def _require_configured(target: Target) -> Target:
    if not target.configured:
        ref = target.drives[0]
        raise UsageError(f"target '{target.text}': no configured drive at {ref.address}",
                         hint="this command works on the drives of the config only; `sherpa scan` lists "
                         "what is on the bus")
    return target


def resolve(cfg: ArmConfig, names: Sequence[str] | None, *, configured_only: bool = False) -> list[Target]:
    """The targets of ``names`` in the order given, each once; ``None`` or empty: every configured drive.

    Every name is checked before anything is returned, so a command refuses a bad name before
    it opens a bus. ``configured_only`` refuses a BUS:NODE where the config has no drive.
    """
    if not names:
        return [_drive_target(cfg, n, TargetKind.DRIVE, n) for n in cfg.drives]
    out: list[Target] = []
    seen: set[tuple] = set()
    for text in names:
        t = resolve_one(cfg, text)
        if configured_only:
            _require_configured(t)
        key = (tuple(d.key for d in t.drives), t.joint_names)
        if key not in seen:
            seen.add(key)
            out.append(t)
    return out


def unique_drives(targets: Iterable[Target]) -> list[DriveRef]:
    """The drives of ``targets`` in order, each (bus, node) once."""
    refs: dict[tuple[str, int], DriveRef] = {}
    for t in targets:
        for ref in t.drives:
            refs.setdefault(ref.key, ref)
    return list(refs.values())


def drive_refs(cfg: ArmConfig, names: Sequence[str] | None, *, configured_only: bool = False,
               elmo_only: str | None = None) -> list[DriveRef]:
    """Every drive the names mean, in order, without repeats; default every configured drive.

    ``elmo_only`` (the command, for the message): the command speaks Elmo's interpreter or its
    parameters. A drive of another type (docs/drives.md) that was named is refused; the default
    "every drive" means every Elmo drive."""
    refs = unique_drives(resolve(cfg, names, configured_only=configured_only))
    if elmo_only is None:
        return refs
    others = [r for r in refs if r.config is not None and r.config.type != "elmo"]
    if others and names:
        kinds = sorted({r.config.type for r in others if r.config is not None})
        raise UsageError(f"{', '.join(r.name for r in others)}: {' and '.join(kinds)} "
                         f"drive{'s' if len(others) > 1 else ''}: `sherpa {elmo_only}` is for Elmo drives",
                         hint="docs/drives.md says what each drive type does")
    return [r for r in refs if r not in others]


def drive_names(cfg: ArmConfig, names: Sequence[str] | None, *, elmo_only: str | None = None) -> list[str]:
    """Configured drive names for ``names`` (BUS:NODE must be a configured drive); default all
    (``elmo_only``: as :func:`drive_refs`)."""
    return [ref.name for ref in drive_refs(cfg, names, configured_only=True, elmo_only=elmo_only)]


def single_drive(cfg: ArmConfig, text: str, *, elmo_only: str | None = None) -> DriveRef:
    """The one drive a name means, for commands that talk to exactly one drive (``sherpa cmd``).

    A pair, or a Σ/Δ joint, is refused: it is moved by two drives.
    """
    t = resolve_one(cfg, text)
    if len(t.drives) != 1:
        raise UsageError(f"'{text}' is moved by two drives ({', '.join(t.drive_names)}); name one of them")
    if elmo_only is not None:
        drive_refs(cfg, [text], elmo_only=elmo_only)  # a drive of another type refused by name
    return t.drives[0]


def pair_of(cfg: ArmConfig, text: str) -> PairConfig:
    """The differential pair a name means: the pair, its Σ/Δ joint, or one of its drives."""
    t = resolve_one(cfg, text)
    if t.pair is None:
        pairs = ", ".join(cfg.pairs)
        raise UsageError(f"'{text}' is not part of a differential pair",
                         hint=f"pairs of the config: {pairs}" if pairs else "the config defines no pair")
    return t.pair
