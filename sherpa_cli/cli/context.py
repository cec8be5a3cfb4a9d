"""Per-invocation state shared by all commands: global options, the output sink, the loaded config."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import typer

from sherpa_cli.cli.output import Output

if TYPE_CHECKING:
    from sherpa_cli.config.model import ArmConfig


@dataclass
class AppState:
    config_path: Path
    config_given: bool
    json_mode: bool
    debug: bool
    out: Output
    _config: "ArmConfig | None" = field(default=None, repr=False)

    @classmethod
    def create(cls, *, config_path: Path, config_given: bool, json_mode: bool, debug: bool,
               no_color: bool) -> "AppState":
        return cls(config_path=config_path, config_given=config_given, json_mode=json_mode,
                   debug=debug, out=Output.create(json_mode=json_mode, no_color=no_color))

    def load_config(self, path: Path | None = None) -> "ArmConfig":
        """The arm config (cached); a command's own FILE argument wins over --config."""
        from sherpa_cli.config import load_config

        if path is not None:
            return load_config(path)
        if self._config is None:
            self._config = load_config(self.config_path)
        return self._config


# The state of the invocation under way, so the error boundary can report through its sink.
CURRENT: "AppState | None" = None


def state(ctx: typer.Context) -> AppState:
    obj = ctx.find_root().obj
    assert isinstance(obj, AppState), "root callback did not run"
    return obj
