"""`sim: buses:` how a simulated bus and the host's CAN controller on it differ from a healthy one.

Only the simulator reads it (sim/buscontroller.py): an unplugged adapter (``present: false``), a
link that is down, another bit rate than the config's, the controller's state and counters at
power-up, error frames the bus keeps producing, a bus-off at a given time (and the recovery after
``restart_ms``), and heartbeats of another master (a host node id already taken)::

    sim:
      buses:
        can1: {state: error-passive, tec: 136}
        can2: {errors: [no-ack], error_period: 0.05}
        can0: {foreign_heartbeats: [126]}
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from sherpa_cli.config.yamlnodes import Locs, Section, as_int, as_seq, as_str, named_items
from sherpa_cli.errors import ConfigError

# the controller states the simulator can start in (as `ip -details link` spells them, lower case)
SIM_BUS_STATES = ("error-active", "error-warning", "error-passive", "bus-off", "stopped")
# the error kinds it can produce: bus/errframes.py KINDS (tests/test_bus_errframes.py keeps them equal)
SIM_ERROR_KINDS = ("tx-timeout", "lost-arbitration", "rx-overflow", "tx-overflow", "warning", "passive", "active",
                   "bit", "form", "stuff", "crc", "overload", "protocol", "transceiver", "no-ack", "bus-off",
                   "bus-error", "restarted")
SIM_BUS_KEYS = ("present", "up", "bitrate", "sample_point", "restart_ms", "berr_reporting", "state", "tec", "rec",
                "errors", "error_period", "bus_off_at", "foreign_heartbeats", "heartbeat_period")


@dataclass(frozen=True)
class SimBusConfig:
    """One simulated bus's controller (the host adapter's view of the bus)."""

    present: bool = True  # False: no such interface (an unplugged adapter)
    up: bool = True  # False: the link is down
    bitrate: int | None = None  # the adapter's bit rate; None: the config's
    sample_point: float = 0.875
    restart_ms: int = 100  # 0: stays BUS-OFF until the link is brought up again
    berr_reporting: bool = True
    state: str = "error-active"
    tec: int | None = None  # None: what the state implies (0, 96, 128 or 256)
    rec: int | None = None
    errors: tuple[str, ...] = ()  # error kinds the bus produces again and again
    error_period: float = 0.05  # s between two rounds of them
    bus_off_at: float | None = None  # s after start: the controller goes BUS-OFF
    foreign_heartbeats: tuple[int, ...] = ()  # node ids another master sends heartbeats (state 0x05) from
    heartbeat_period: float = 0.05  # s between two of those heartbeats


def parse_sim_buses(top: Section, locs: Locs, bus_names: Iterable[str], sim_keys: Iterable[str]) -> dict[str, SimBusConfig]:
    """The ``sim: buses:`` section; names must be configured buses, kinds and states known ones."""
    sim = top.section("sim", sim_keys)
    if sim is None or sim.get("buses") is None:
        return {}
    known = set(bus_names)
    out: dict[str, SimBusConfig] = {}
    for name, node in named_items(sim.req("buses"), "bus"):
        sec = Section(node, SIM_BUS_KEYS, what="a mapping of simulated bus faults like {state: bus-off}")
        locs.put(("sim", "buses", name), node.loc)
        if name not in known:
            raise ConfigError(f"sim fault for unknown bus '{name}'", node.loc,
                              hint="configured buses: " + ", ".join(sorted(known)))
        d = SimBusConfig()
        state = sec.str("state", d.state).lower()
        if state not in SIM_BUS_STATES:
            raise ConfigError(f"unknown bus state '{state}'", sec.loc("state"),
                              hint="one of: " + ", ".join(SIM_BUS_STATES))
        errors: list[str] = []
        if sec.get("errors") is not None:
            for item in as_seq(sec.req("errors"), "a list of error kinds like [no-ack, stuff]"):
                kind = as_str(item)
                if kind not in SIM_ERROR_KINDS:
                    raise item.error(f"unknown error kind '{kind}'", hint="one of: " + ", ".join(SIM_ERROR_KINDS))
                errors.append(kind)
        beats: list[int] = []
        if sec.get("foreign_heartbeats") is not None:
            for item in as_seq(sec.req("foreign_heartbeats"), "a list of node ids like [126]"):
                node_id = as_int(item)
                if not 1 <= node_id <= 127:
                    raise item.error(f"node id {node_id} must be 1..127")
                beats.append(node_id)
        cfg = SimBusConfig(
            present=sec.bool("present", d.present), up=sec.bool("up", d.up), bitrate=sec.int("bitrate"),
            sample_point=sec.num("sample_point", d.sample_point), restart_ms=sec.int("restart_ms", d.restart_ms),
            berr_reporting=sec.bool("berr_reporting", d.berr_reporting), state=state, tec=sec.int("tec"),
            rec=sec.int("rec"), errors=tuple(errors), error_period=sec.num("error_period", d.error_period),
            bus_off_at=sec.num("bus_off_at"), foreign_heartbeats=tuple(beats),
            heartbeat_period=sec.num("heartbeat_period", d.heartbeat_period))
        limits: tuple[tuple[str, int | None, int, int], ...] = (
            ("bitrate", cfg.bitrate, 1, 8_000_000), ("restart_ms", cfg.restart_ms, 0, 60_000),
            ("tec", cfg.tec, 0, 511), ("rec", cfg.rec, 0, 255))
        for key, whole, low, high in limits:
            if whole is not None and not low <= whole <= high:
                raise ConfigError(f"{key} {whole} must be {low}..{high}", sec.loc(key))
        for key, seconds in (("error_period", cfg.error_period), ("heartbeat_period", cfg.heartbeat_period)):
            if not 0.001 <= seconds <= 60:
                raise ConfigError(f"{key} {seconds} s must be 0.001..60", sec.loc(key))
        if not 0 < cfg.sample_point < 1:
            raise ConfigError(f"sample_point {cfg.sample_point} must be between 0 and 1", sec.loc("sample_point"))
        if cfg.bus_off_at is not None and not 0 <= cfg.bus_off_at <= 1e6:
            raise ConfigError(f"bus_off_at {cfg.bus_off_at} s must be 0..1e6", sec.loc("bus_off_at"))
        out[name] = cfg
    return out


def dump_sim_buses(buses: Mapping[str, SimBusConfig]) -> dict[str, dict[str, object]]:
    """The ``sim: buses:`` section back as plain data (only what differs from the defaults)."""
    import dataclasses

    base = SimBusConfig()
    out: dict[str, dict[str, object]] = {}
    for name, b in buses.items():
        values = {f.name: getattr(b, f.name) for f in dataclasses.fields(b) if getattr(b, f.name) != getattr(base, f.name)}
        out[name] = {k: list(v) if isinstance(v, tuple) else v for k, v in values.items()}
    return out
