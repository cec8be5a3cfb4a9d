"""`sherpa sim`: the simulated arm as its own process, for a second terminal or a second machine."""

from __future__ import annotations

import contextlib
import math
import threading
from collections.abc import Iterator

import typer

from sherpa_cli.cli.context import state
from sherpa_cli.errors import SherpaError, UsageError
from sherpa_cli.words import plural

MAX_SERVE_S = 30 * 24 * 3600.0  # --duration: a month; longer is a typo (leave it out to serve until Ctrl-C)


@contextlib.contextmanager
def _stop_on_sigterm(stop: threading.Event) -> Iterator[None]:
    """SIGTERM sets ``stop`` while the simulator serves; the handler before is put back afterwards
    (the CLI runs in-process in tests and recipes: a handler left behind outlives the command)."""
    import signal

    if threading.current_thread() is not threading.main_thread():  # signal handlers live there only
        yield
        return
    before = signal.signal(signal.SIGTERM, lambda signum, frame: stop.set())
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, before)


def sim(
    ctx: typer.Context,
    serve: str | None = typer.Option(
        None, "--serve", metavar="HOST:PORT",
        help="Serve each bus over python-can-remote on PORT, PORT+1, ... (bind 127.0.0.1 unless "
        "--allow-remote)."),
    allow_remote: bool = typer.Option(False, "--allow-remote", help="Allow --serve on a non-loopback address."),
    reset_state: bool = typer.Option(False, "--reset-state",
                                     help="Forget what the simulated drives saved (SV) and their RAM: factory flash, "
                                     "joints back at their power-up positions."),
    power_cycle: bool = typer.Option(False, "--power-cycle",
                                     help="Power the in-process simulated arm (--sim) off and on: RAM is lost "
                                     "(not homed, motors off, PDOs and dead-man objects at their defaults); "
                                     "flash and the joints' positions stay."),
    duration: float | None = typer.Option(None, "--duration", metavar="SECONDS",
                                             help="Stop by itself after this long (default: until Ctrl-C)."),
    event_log: str | None = typer.Option(None, "--event-log", metavar="FILE",
                                            help="Append one JSON line per motor on/off and heartbeat-loss event "
                                            "(drive, node, t = time.monotonic(), wall = time.time(), event)."),
) -> None:
    """Run the simulated arm until Ctrl-C, as drives on a bus would be.

    With --serve the buses are served over python-can-remote and the command prints the
    --bus-map a second terminal must use. With the global --bus-map (e.g.
    can0=socketcan:vcan0) the drives answer on those interfaces, e.g. kernel vcan.
    The drives' flash (what SV saved) persists between runs in the state directory. The
    in-process arm of --sim stays powered between commands (its RAM too); --power-cycle
    switches it off and on, --reset-state returns it to the state it was delivered in.

    \b
    Examples:
      sherpa sim --serve 127.0.0.1:54701
      sherpa --bus-map can0=socketcan:vcan0,can1=socketcan:vcan1,can2=socketcan:vcan2 sim
      sherpa sim --power-cycle
      sherpa sim --reset-state
    """
    from sherpa_cli.bus.busmap import apply_bus_map, bus_kwargs, parse_bus_map
    from sherpa_cli.sim import serve as serving
    from sherpa_cli.sim import state as sim_state

    st = state(ctx)
    cfg = st.load_config()
    if st.sim:
        raise UsageError("sherpa sim is the simulator itself; --sim does not apply to it")
    # an exported SHERPA_BUS_MAP points clients at a served sim; it must not stop serving one
    mapping = parse_bus_map(st.bus_map) if not (serve and st.bus_map_from_env) else {}
    if serve and mapping:
        raise UsageError("give either --serve (python-can-remote) or --bus-map (interfaces), not both")
    if reset_state:
        path = sim_state.state_path(cfg)
        removed = sim_state.reset(cfg)
        sim_state.reset_ram(cfg)
        st.out.line(f"simulated arm '{cfg.name}': factory flash ({'removed ' if removed else 'no saved state at '}{path})")
        if not serve and not mapping:
            return
    if power_cycle:
        was = sim_state.power_cycle(cfg)
        st.out.line(f"simulated arm '{cfg.name}': power cycled (RAM lost; flash and positions kept)" if was else
                    f"simulated arm '{cfg.name}': was not powered (nothing in {sim_state.ram_path(cfg)})")
        if not serve and not mapping:
            return
    if duration is not None and not (math.isfinite(duration) and 0 < duration <= MAX_SERVE_S):
        # inf reached threading's wait as an OverflowError, nan served not at all and exited 0
        raise UsageError(f"--duration must be > 0 and at most {MAX_SERVE_S:g} seconds, got {duration}",
                         hint="leave --duration out to serve until Ctrl-C")
    if serve:
        host, port = serving.parse_host_port(serve, len(cfg.buses))
        serving.check_bind_address(host, allow_remote)
        served = serving.serve(cfg, host, port, event_log=event_log)
        bus_map = ",".join(f"{bus}={target}" for bus, target in served.bus_map.items())
        lines = [
            f"simulated arm '{cfg.name}': {plural(len(cfg.drives), 'drive')} on {plural(len(cfg.buses), 'bus', 'buses')}, "
            f"served over python-can-remote on {host}:{port}..{port + len(cfg.buses) - 1}",
            "in another terminal:",
            f"  export SHERPA_BUS_MAP={bus_map}",
            f"  sherpa --config {st.config_path} cmd {next(iter(cfg.drives))} PX",
            f"or give each command --bus-map {bus_map}",
            f"flash (SV) persists in {sim_state.state_path(cfg)}; Ctrl-C stops the simulator",
        ]
        stopper = served.stop
        arm = served.arm
    elif mapping:
        mapped = apply_bus_map(cfg, mapping)
        endpoints = {name: bus_kwargs(mapped.buses[name]) for name in mapping}
        arm = serving.run_on_buses(cfg, endpoints, event_log=event_log)
        lines = [f"simulated arm '{cfg.name}': drives answering on "
                 + ", ".join(f"{b}={t}" for b, t in mapping.items()),
                 f"flash (SV) persists in {sim_state.state_path(cfg)}; Ctrl-C stops the simulator"]
        stopper = arm.stop
    else:
        raise UsageError("nothing to run the simulator on: give --serve HOST:PORT, or --bus-map "
                         "BUS=INTERFACE:CHANNEL (e.g. can0=socketcan:vcan0)",
                         hint="for one command against the simulator, use the global --sim instead")
    for line in lines:
        st.out.line(line)
    import sys

    sys.stdout.flush()
    stop = threading.Event()
    with _stop_on_sigterm(stop):
        try:
            if stop.wait(duration):
                st.out.info("terminated: stopping the simulated arm")
        except KeyboardInterrupt:
            st.out.info("stopping the simulated arm")
        finally:
            stopper()  # saves the drives' flash: a service manager's SIGTERM must not lose an SV
    if arm.errors:
        # each was logged with its traceback when it happened; the exit says so in one line, as every
        # other error of the CLI (a signal's stop must not end in a traceback)
        first = arm.errors[0]
        raise SherpaError(f"the simulated arm had {plural(len(arm.errors), 'internal fault')}; the first: "
                          f"{type(first).__name__}: {first}", hint="the log above shows where each happened")
