"""Per-invocation state shared by all commands: global options, the output sink, the loaded config."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import typer

from sherpa_cli.cli.output import Output
from sherpa_cli.errors import UsageError

if TYPE_CHECKING:
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.config.model import ArmConfig
    from sherpa_cli.sim.arm import SimArm
    from sherpa_cli.sim.stepped import SteppedTime


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
    config_looked: tuple[str, ...] = ()  # where the default config was looked for (no --config)
    allow_user_program: bool = False  # --allow-user-program: motion may start while a drive's program runs
    force_limit: float | None = None  # a moving command's --force-limit (N): the session's guards watch it
    verbose: bool = False  # --verbose: the details (each drive's identity, the objects a guard put back)
    _config: ArmConfig | None = field(default=None, repr=False)

    @classmethod
    def create(cls, *, config_path: Path, config_given: bool, json_mode: bool, debug: bool,
               no_color: bool, sim: bool = False, bus_map: list[str] | None = None,
               bus_map_from_env: bool = False, config_looked: tuple[str, ...] = (),
               verbose: bool = False) -> AppState:
        return cls(config_path=config_path, config_given=config_given, json_mode=json_mode,
                   debug=debug, out=Output.create(json_mode=json_mode, no_color=no_color),
                   sim=sim, bus_map=list(bus_map or []), bus_map_from_env=bus_map_from_env,
                   config_looked=config_looked, verbose=verbose)

    def use_force_limit(self, value: float | None) -> None:
        """A moving command's --force-limit, checked before anything else (the guards of its session
        watch it: motion/guard.py)."""
        from sherpa_cli.motion.force_watch import check_force_limit

        self.force_limit = None if value is None else check_force_limit(value, "--force-limit")

    @contextmanager
    def session(self, buses: Iterable[str] | None = None,
                sim_factory: Callable[[ArmConfig, Mapping[str, str]], SimArm] | None = None,
                best_effort: bool = False, sim_wait: float | None = None) -> Iterator[ArmSession]:
        """Open the arm's buses (or the simulated arm with --sim) for one command; ``sim_factory``
        builds the in-process arm instead of the default (SimArm.in_process's ``factory``);
        ``best_effort`` opens what can be opened (ArmSession.open); ``sim_wait``: how long a `--sim`
        command waits for another that holds the in-process arm (None: the simulator's default)."""
        from sherpa_cli.bus.busmap import apply_bus_map, parse_bus_map
        from sherpa_cli.bus.session import ArmSession

        shared = _shared_for(self)
        if shared is not None:
            from sherpa_cli.bus.health import check_buses  # only a recipe's session: not `sherpa scan`'s start

            # a recipe step: the recipe's one session, opened (all buses) at the first step that needs it
            if shared.session is None:
                shared.session = shared.stack.enter_context(shared.owner.session(sim_factory=shared.sim_factory()))
                shared.opens += 1
                if shared.stepped is not None:
                    use_stepped(shared.session, shared.stepped, shared.config)
                check_buses(shared.session, what="the recipe")  # bus/health.py: BUS-OFF, passive, bit rate
            yield shared.session
            return
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

            arm = SimArm.in_process(cfg, sim_factory)  # injected: ops never import the simulator
            arm.ram_wait = sim_wait
            arm.on_busy = self.out.warn
        with ArmSession.open(cfg, sim=arm, buses=buses, best_effort=best_effort) as session:
            session.allow_user_program = self.allow_user_program
            session.force_limit = self.force_limit
            yield session

    def load_config(self, path: Path | None = None) -> ArmConfig:
        """The arm config (cached); a command's own FILE argument wins over --config."""
        from sherpa_cli.config import load_config

        if path is not None:
            return load_config(path)
        if self._config is None:
            shared = _shared_for(self)
            if shared is not None:
                self._config = shared.config
            else:
                if not self.config_given and self.config_looked and not self.config_path.is_file():
                    raise UsageError("no arm config found; looked at " + ", ".join(self.config_looked),
                                      hint="pass --config FILE, set $SHERPA_CONFIG, or put sherpa-arm.yaml in "
                                      "the user config directory")
                self._config = load_config(self.config_path)
        return self._config


@dataclass
class SharedSession:
    """What a recipe's steps share: the config loaded once and the buses opened once.

    ``owner`` is the recipe command's own state; a step whose global options are the owner's
    (the runner passes them) uses its config and session instead of loading and opening again.
    """

    owner: AppState
    config: ArmConfig
    stack: ExitStack = field(default_factory=ExitStack)
    session: ArmSession | None = None
    opens: int = 0  # sessions opened for the recipe (0 or 1; tests count them)
    # a recipe with `sim_time: stepped` run with --sim: the shared simulated arm runs on this stepped
    # time (sim/stepped.py), so the figures its steps measure do not depend on the host's load
    stepped: SteppedTime | None = None

    def sim_factory(self) -> Callable[[ArmConfig, Mapping[str, str]], SimArm] | None:
        stepped = self.stepped
        if stepped is None:
            return None
        from sherpa_cli.sim.arm import SimArm

        return lambda cfg, channels: SimArm.for_session(cfg, channels, clock=stepped.clock)

    def close(self) -> None:
        self.stack.close()
        self.session = None


# Set by the recipe runner while it runs a recipe's steps in this process.
SHARED: SharedSession | None = None


def _shared_for(st: AppState) -> SharedSession | None:
    shared = SHARED
    if shared is None or shared.owner is st:
        return None
    o = shared.owner
    same = (st.config_path == o.config_path and st.sim == o.sim and ",".join(st.bus_map) == ",".join(o.bus_map))
    return shared if same else None


def shared_stepped(st: AppState) -> SteppedTime | None:
    """The stepped time of the recipe session ``st`` shares (`sim_time: stepped` with --sim), else None."""
    shared = _shared_for(st)
    return shared.stepped if shared is not None else None


def use_stepped(session: ArmSession, stepped: SteppedTime, cfg: ArmConfig) -> bool:
    """Whether ``session``'s simulated arm runs on ``stepped``'s clock; if so its drive clients wait on
    that clock too (set once, before the first client: a second set would charge a deaf request twice).
    ``cfg``: the arm config as loaded (a deaf request costs the real bus's reply timeout, not the
    simulator's patient one the session runs with)."""
    from sherpa_cli.sim.arm import SimArm

    arm = session.sim
    if not isinstance(arm, SimArm) or arm.clock is not stepped.clock:
        return False
    if session.client_overrides.get("clock") != stepped.now:
        p = cfg.protocol
        session.client_overrides.update(stepped.client_overrides(p.reply_timeout, p.retries, arm.unheard))
    return True


@contextmanager
def shared_session(owner: AppState, *, stepped: bool = False) -> Iterator[SharedSession]:
    """Share ``owner``'s config and (lazily opened) session with every command run inside;
    ``stepped`` (with --sim): the shared simulated arm on stepped time."""
    global SHARED
    outer = SHARED
    shared = SharedSession(owner, owner.load_config())
    if stepped and owner.sim:
        from sherpa_cli.sim.stepped import SteppedTime

        shared.stepped = SteppedTime()
    SHARED = shared
    try:
        yield shared
    finally:
        SHARED = outer
        shared.close()


# The state of the invocation under way, so the error boundary can report through its sink.
CURRENT: AppState | None = None


def state(ctx: typer.Context) -> AppState:
    obj = ctx.find_root().obj
    assert isinstance(obj, AppState), "root callback did not run"
    return obj
