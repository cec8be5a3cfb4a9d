"""Arm configuration: YAML (native schema or the seed's rosparam format) -> frozen ArmConfig.

``load_config(path)`` / ``load_config_text(text, filename)`` return a validated config or
raise ConfigError naming file, line and key path; ``dump_native(cfg)`` writes native YAML.
The format is recognised by its content: a top-level ``ros_can_interface`` key means rosparam.
May import errors only: everything else builds on the config.
"""

from __future__ import annotations

from pathlib import Path

from sherpa_cli.config.model import ArmConfig
from sherpa_cli.errors import ConfigError, Location

__all__ = ["ArmConfig", "ConfigError", "dump_native", "load_config", "load_config_text"]


def load_config(path: str | Path) -> ArmConfig:
    from sherpa_cli.config.yamlnodes import read_input

    p = Path(path)
    try:
        text = read_input(p)
    except FileNotFoundError:
        raise ConfigError("config file not found", Location(str(p)),
                          hint="give one with --config FILE or $SHERPA_CONFIG") from None
    except IsADirectoryError:
        raise ConfigError("is a directory, expected a YAML config file", Location(str(p))) from None
    except UnicodeDecodeError as exc:
        raise ConfigError(f"not a UTF-8 text file ({exc.reason} at byte {exc.start})", Location(str(p))) from None
    except OSError as exc:
        raise ConfigError(f"cannot read config file: {exc.strerror}", Location(str(p))) from None
    return load_config_text(text, str(p))


def load_config_text(text: str, filename: str = "<input>") -> ArmConfig:
    from sherpa_cli.config.native import load_native
    from sherpa_cli.config.rosparam import is_rosparam, load_rosparam
    from sherpa_cli.config.validate import validate
    from sherpa_cli.config.yamlnodes import parse_yaml

    root = parse_yaml(text, filename)
    if root.kind != "map":
        raise ConfigError("expected a mapping of configuration keys at the top level (name:, buses:, drives:, ...)",
                          root.loc)
    if is_rosparam(root):
        cfg, locs, warnings = load_rosparam(root, filename)
        return validate(cfg, locs, warnings, warn_no_model=False)
    cfg, locs, warnings = load_native(root, filename)
    return validate(cfg, locs, warnings)


def dump_native(cfg: ArmConfig) -> str:
    from sherpa_cli.config.dump import dump_native as _dump

    return _dump(cfg)
