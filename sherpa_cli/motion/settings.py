"""What the motion guard needs to know, read once from the config's ``motion:`` section."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from sherpa_cli.errors import UsageError
from sherpa_cli.motion.blocked import StallWatch, min_progress_for, torque_min_progress
from sherpa_cli.motion.drive_watch import DEFAULT_EMCY_WARNING_CODES
from sherpa_cli.motion.stopping import recovery_speed

if TYPE_CHECKING:
    from sherpa_cli.config.model import ArmConfig

PROFILE_KEYS = ("SP", "AC", "DC")  # the profile a motion command may scale


@dataclass(frozen=True)
class MotionSettings:
    """What the guard needs to know; :meth:`from_config` reads the config's ``motion:`` section."""

    host_node_id: int = 126
    host_id_pool: tuple[int, ...] = ()  # more ids a command takes when host_node_id is in use
    consumer_time_ms: int = 500
    heartbeat_period_ms: int = 0  # 0: a quarter of consumer_time_ms
    host_id_listen_ms: int = 0  # 0: consumer_time_ms plus one heartbeat period (motion/host_ids.py)
    loss_action: int = 2
    comm_error_behaviour: int = 2
    stop_method: str = "auto"  # auto | st | jv0
    standstill_timeout: float = 2.0
    standstill_velocity: int = 2  # counts/s: |VX| at most this is standstill
    liveness_timeout: float = 1.0
    velocity_unit_mode: int = 5
    recovery_speed: float = 0.5  # share of the slowest moved joint's velocity limit
    recovery_fallback_speed: int = 100  # counts/s where no joint has a limit
    stall_time: float = 1.0  # s without progress that make a commanded move 'blocked' (0: off)
    poll_interval: float = 0.01  # s between polls while waiting (the bus's poll_interval_ms)
    request_bound: float = 0.2  # s one interpreter request can take at worst (timeout x attempts)
    emcy_warning_codes: tuple[int, ...] = DEFAULT_EMCY_WARNING_CODES  # EMCYs that do not stop a motion
    # EMCYs the command answers itself (a PVT stream's queue-low and its normal end): neither acted on
    # by the guard nor logged as a warning
    emcy_answered_codes: tuple[int, ...] = ()
    deadman_check_interval: float = 0.5  # s between reads of a moving drive's 0x1016:1
    bus_error_passive: str = "stop"  # stop | warn: an ERROR-PASSIVE bus during motion (motion/bus_watch.py)
    bus_check_interval: float = 0.1  # s between reads of the command's buses' controller state
    heartbeat_realtime: bool = True  # SCHED_FIFO for the heartbeat thread where the OS permits (deadman.py)
    force_check_interval: float = 0.02  # s between samples of each F/T sensor a guarded move watches

    @property
    def heartbeat_period(self) -> float:
        return (self.heartbeat_period_ms or self.consumer_time_ms / 4) / 1000

    @property
    def host_id_listen(self) -> float:
        """s a command listens to the pool's ids before it takes one (motion/host_ids.py)."""
        return (self.host_id_listen_ms or self.consumer_time_ms + self.heartbeat_period * 1000) / 1000

    def host_id_listen_for(self, private: bool) -> float:
        """s to listen before taking an id, on buses private to this process or shared."""
        return self.host_id_listen_private if private else self.host_id_listen

    @property
    def host_id_listen_private(self) -> float:
        """s on buses private to this process (the in-process simulated arm's): no other process or
        host is there, so no command killed before can have armed a drive on them; what is left to
        hear is a producer of the simulated arm itself, which two heartbeat periods do."""
        return min(self.host_id_listen, 2 * self.heartbeat_period)

    @property
    def host_ids(self) -> tuple[int, ...]:
        """The ids a command may send its heartbeat as, in the order they are taken."""
        return (self.host_node_id, *(i for i in self.host_id_pool if i != self.host_node_id))

    @property
    def consumer_entry(self) -> int:
        return self.consumer_entry_for(self.host_node_id)

    def consumer_entry_for(self, host_id: int) -> int:
        """0x1016:1 watching ``host_id``: host id << 16 | time ms."""
        return (host_id & 0x7F) << 16 | (self.consumer_time_ms & 0xFFFF)

    @classmethod
    def from_config(cls, cfg: ArmConfig, buses: Iterable[str] | None = None) -> MotionSettings:
        m, p = cfg.motion, cfg.protocol
        names = list(buses) if buses is not None else list(cfg.buses)
        poll_ms = min((cfg.buses[b].poll_interval_ms for b in names if b in cfg.buses), default=10)
        return cls(host_node_id=m.host_node_id, host_id_pool=tuple(m.host_id_pool),
                   consumer_time_ms=m.consumer_time_ms,
                   heartbeat_period_ms=m.heartbeat_period_ms, host_id_listen_ms=m.host_id_listen_ms, loss_action=m.loss_action,
                   comm_error_behaviour=m.comm_error_behaviour, stop_method=m.stop_method,
                   standstill_timeout=m.standstill_timeout, standstill_velocity=m.standstill_velocity,
                   liveness_timeout=m.liveness_timeout,
                   velocity_unit_mode=m.velocity_unit_mode, recovery_speed=m.recovery_speed,
                   recovery_fallback_speed=m.recovery_fallback_speed, stall_time=m.stall_time, poll_interval=poll_ms / 1000,
                   request_bound=p.reply_timeout * (1 + p.retries),
                   emcy_warning_codes=tuple(m.emcy_warning_codes), deadman_check_interval=m.deadman_check_interval,
                   bus_error_passive=m.bus_error_passive, bus_check_interval=m.bus_check_interval,
                   heartbeat_realtime=m.heartbeat_realtime)


    def recovery_speed_for(self, vel_limits: Iterable[int | None]) -> int:
        """counts/s of the move back after a limit breach (motion/stopping.py recovery_speed)."""
        return recovery_speed(vel_limits, self.recovery_speed, self.recovery_fallback_speed)

    def stall_watch(self, speed_counts_per_s: float) -> StallWatch:
        """The stall watch of a move at this speed (motion/blocked.py)."""
        return StallWatch(self.stall_time, min_progress_for(speed_counts_per_s, self.stall_time))

    def torque_stall_watch(self) -> StallWatch:
        """The stall watch of a torque move: no motor faster than standstill for the stall time."""
        return StallWatch(self.stall_time, torque_min_progress(self.standstill_velocity, self.stall_time))


def check_torque_for(duration: float, limit: float | None = None) -> None:
    """A torque move's --for within ``motion.max_torque_for``."""
    from sherpa_cli.config.model import MotionConfig

    bound = MotionConfig().max_torque_for if limit is None else limit
    if duration > bound:
        raise UsageError(f"--for {duration:g} s is longer than motion.max_torque_for ({bound:g} s): in torque mode "
                         "no drive limit acts, the time is the last guard", hint="raise motion.max_torque_for in the "
                         "config (at most 60 s) for a longer torque move")
