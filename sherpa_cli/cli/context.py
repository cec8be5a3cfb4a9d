"""Per-invocation state shared by all commands: global options, the output sink, the loaded config."""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Iterable, Iterator

import typer

from sherpa_cli.cli.output import Output
from sherpa_cli.errors import UsageError

if TYPE_CHECKING:
    from sherpa_cli.config.model import ArmConfig
    from sherpa_cli.ops.session import ArmSession


@dataclass
class AppState:
    config_path: Path
    config_given: bool
    json_mode: bool
    debug: bool
    out: Output
    sim: bool = False
    bus_map: list[str] = field(default_factory=list)
    bus_map_from_env: bool = False
    _config: "ArmConfig | None" = field(default=None, repr=False)

    @classmethod
    def create(cls, *, config_path: Path, config_given: bool, json_mode: bool, debug: bool,
               no_color: bool, sim: bool = False, bus_map: list[str] | None = None,
               bus_map_from_env: bool = False) -> "AppState":
        return cls(config_path=config_path, config_given=config_given, json_mode=json_mode,
                   debug=debug, out=Output.create(json_mode=json_mode, no_color=no_color),
                   sim=sim, bus_map=list(bus_map or []), bus_map_from_env=bus_map_from_env)

    @contextmanager
    def session(self, buses: Iterable[str] | None = None) -> Iterator["ArmSession"]:
        """Open the arm's buses (or the simulated arm with --sim) for one command."""
        from sherpa_cli.bus.busmap import apply_bus_map, parse_bus_map
        from sherpa_cli.ops.session import ArmSession

        cfg = self.load_config()
        mapping = parse_bus_map(self.bus_map)
        if mapping and self.sim and not self.bus_map_from_env:
            raise UsageError("--sim and --bus-map exclude each other: --sim already maps every bus "
                             "to the in-process simulator")
        if mapping and not self.sim:
            cfg = apply_bus_map(cfg, mapping)
        arm = None
        if self.sim:
            from sherpa_cli.sim.arm import SimArm

            arm = SimArm.in_process(cfg)  # injected: ops never import the simulator
        with ArmSession.open(cfg, sim=arm, buses=buses) as session:
            yield session

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
