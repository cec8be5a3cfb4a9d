"""Named poses against the arm: how far it stands from one, and teaching one from where it stands.

A pose is taught into the config file the tool loaded, by editing the text of its one entry
(config/yaml_edit.py): the user's comments, order and layout survive. The new text is loaded and
checked like any config before it replaces the file, so a pose the config would refuse (a joint
outside its normal range) is never written.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from sherpa_cli.config import load_config_text
from sherpa_cli.config.model import ArmConfig, Pose
from sherpa_cli.config.yaml_edit import YamlEditError, set_entry
from sherpa_cli.config.yamlnodes import read_input, suggest
from sherpa_cli.errors import ConfigError, UsageError
from sherpa_cli.joints.units import counts_to_rad
from sherpa_cli.ops.state import ArmState
from sherpa_cli.output_files import write_output

__all__ = ["PoseDiff", "PoseJoint", "SavedPose", "diff_pose", "pose_named", "save_pose"]


def pose_named(cfg: ArmConfig, name: str) -> Pose:
    """The pose ``name``; a UsageError naming the nearest pose and listing them otherwise."""
    pose = cfg.poses.get(name)
    if pose is not None:
        return pose
    close = suggest(name, list(cfg.poses))
    raise UsageError(f"pose '{name}' is not in the config" + (f"; did you mean '{close}'?" if close else ""),
                     hint=f"poses: {', '.join(cfg.poses)}" if cfg.poses else
                     "the config has no `poses:` section (docs/move.md); teach one: sherpa pose save NAME")


@dataclass(frozen=True)
class PoseJoint:
    """One joint of a pose beside where it stands (rad; counts alongside). ``now`` is None for a
    joint whose position is not known (not calibrated)."""

    joint: str
    target: float
    target_counts: int
    now: float | None
    now_counts: int | None
    calibration: str

    @property
    def off_counts(self) -> int | None:
        """Where it stands minus the pose, in counts (None: not known)."""
        return None if self.now_counts is None else self.now_counts - self.target_counts

    @property
    def off(self) -> float | None:
        """Where it stands minus the pose, in rad (None: not known)."""
        return None if self.now is None else self.now - self.target


@dataclass(frozen=True)
class PoseDiff:
    pose: str
    joints: tuple[PoseJoint, ...]

    @property
    def unknown(self) -> tuple[str, ...]:
        """Joints whose position is not known (not calibrated)."""
        return tuple(j.joint for j in self.joints if j.now is None)

    @property
    def at_pose(self) -> bool:
        """Every joint known and within one count of the pose."""
        return all(j.off_counts is not None and abs(j.off_counts) <= 1 for j in self.joints)


def diff_pose(cfg: ArmConfig, pose: Pose, state: ArmState) -> PoseDiff:
    """Each joint of ``pose`` beside where ``state`` has it."""
    rows = []
    for name, counts in pose.counts.items():
        j = state[name]
        cpr = cfg.joints[name].cpr
        rows.append(PoseJoint(name, counts_to_rad(counts, cpr), counts,
                              j.position if j.calibrated else None, j.position_counts if j.calibrated else None,
                              j.calibration))
    return PoseDiff(pose.name, tuple(rows))


@dataclass(frozen=True)
class SavedPose:
    """What `pose save` wrote: the pose in rad and counts per joint, into which file."""

    name: str
    path: str
    values: dict[str, float]  # rad, as written
    counts: dict[str, int]  # the same, as the config reads them back
    replaced: bool  # the pose existed and was overwritten


def save_pose(cfg: ArmConfig, name: str, state: ArmState, *, replace: bool = False) -> SavedPose:
    """Write pose ``name`` = where the joints of ``state`` stand into the config file ``cfg`` came
    from. Refused, with nothing written: an uncalibrated joint (its position is not known), a pose
    that exists unless ``replace``, a config that did not come from a file, and a result the config
    would refuse."""
    if cfg.source is None or not Path(cfg.source).is_file():
        raise UsageError("pose save writes into the config file, and this config came from none",
                         hint="give the file with --config")
    unknown = [j.name for j in state.joints if not j.calibrated]
    if unknown:
        raise UsageError(f"pose {name}: {', '.join(unknown)} not calibrated: where they stand is not known",
                         hint="home them first (sherpa home), or leave them out with --joints")
    exists = name in cfg.poses
    if exists and not replace:
        raise UsageError(f"pose {name!r} exists ({cfg.poses[name].where}); nothing written",
                         hint="--replace overwrites it")
    path = Path(cfg.source)
    values = {j.name: j.position for j in state.joints}
    text = read_input(path)
    try:
        new = set_entry(text, "poses", name, values)
    except YamlEditError as exc:
        raise ConfigError(f"{path}: cannot add pose {name!r}: {exc}; nothing written") from None
    try:
        again = load_config_text(new, str(path))
    except ConfigError as exc:
        raise ConfigError(f"pose {name}: the config would refuse it, nothing written: {exc.message}",
                          hint="move the joints inside their normal ranges (sherpa limits show)") from None
    counts = dict(again.poses[name].counts)
    off = {j.name: counts[j.name] - j.position_counts for j in state.joints if counts[j.name] != j.position_counts}
    if off:  # rad written to 9 digits reads back to the same count on any configured joint
        raise ConfigError(f"pose {name}: reads back off by {off} counts; nothing written")
    write_output(path, new, "--config", what="the config")
    return SavedPose(name, str(path), values, counts, exists)
