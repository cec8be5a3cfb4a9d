"""`sherpa params restore`: a `dump-params` file back into the drives, through the program engine.

What is restored: every parameter of a drive's ``params`` block that is a writable setting,
UM and other non-Appendix-C parameters included. What is not: the identity block (a drive's
serial number, versions, ...), read-only values, and commands or counters that belong to a
moment rather than to the drive's setup (MO, PX, PY, PA, PR, JV, TC, HM, RM): writing them
back would switch a motor on, move it, or shift its position counter. They show in the plan
as "not written". Parameters the dump could not read are listed as warnings.

The dump must come from the same drive: its serial number (0x1018:4) is compared with the
one the drive reports before anything is written; ``other_serial`` allows a dump of another
drive (a replaced drive, a spare set up like its twin).
"""

from __future__ import annotations

from pathlib import Path

from sherpa_cli.config.model import ArmConfig
from sherpa_cli.elmo.commands import COMMANDS, parse_param_key
from sherpa_cli.errors import ConfigError, Location, SafetyError
from sherpa_cli.ops.params_file import ParamDump
from sherpa_cli.ops.program import DriveTarget

# Letters of commands that hold a moment's state, not a setting (see the module text).
NOT_RESTORED = {
    "MO": "switches the motor; never restored",
    "PX": "position counter; restoring it would shift the joint's position",
    "PY": "position counter; restoring it would shift the joint's position",
    "PA": "motion target, not a setting",
    "PR": "motion target, not a setting",
    "JV": "motion command, not a setting",
    "TC": "motion command, not a setting",
    "HM": "homing state, not a setting",
    "RM": "reference mode, not a setting",
}


def restore_targets(cfg: ArmConfig, dump: ParamDump, source: Path, *,
                    other_serial: bool = False) -> tuple[list[DriveTarget], list[str]]:
    """What to write per drive of the dump, and warnings. Raises before any I/O on a mismatch
    between the dump and the config, or on a dump without a serial number (unless ``other_serial``)."""
    where = Location(str(source))
    targets: list[DriveTarget] = []
    warnings: list[str] = []
    if not dump.drives:
        raise ConfigError("the dump holds no drives", where)
    for name, d in dump.drives.items():
        c = cfg.drives.get(name)
        if c is None:
            raise ConfigError(f"drive {name} of the dump is not in the config ({cfg.source or cfg.name})",
                              Location(str(source), path=f"drives.{name}"),
                              hint="restore with the config the dump was made with (--config)")
        if (c.bus, c.node) != (d.bus, d.node):
            raise ConfigError(f"drive {name} is {d.bus}:{d.node} in the dump but {c.bus}:{c.node} in the config",
                              Location(str(source), path=f"drives.{name}"))
        params, skipped = {}, {}
        for key, value in d.params.items():
            letters, _ = parse_param_key(key)
            spec = COMMANDS[letters]
            if spec.access != "rw":
                skipped[key] = "read-only"
            elif letters in NOT_RESTORED:
                skipped[key] = NOT_RESTORED[letters]
            else:
                params[key] = value
        for key, why in d.unreadable.items():
            warnings.append(f"{name}: {key} was not readable when dumped ({why}); it is not restored")
        serial = d.identity.get("serial")
        if serial is None and not other_serial:
            raise SafetyError(f"{name}: the dump holds no serial number, so it cannot be matched to the drive; "
                              f"nothing was written", hint="add --other-serial to restore it anyway")
        targets.append(DriveTarget(name, c.bus, c.node, params, skipped=skipped,
                                   expected_serial=None if other_serial else serial))
    return targets, warnings

