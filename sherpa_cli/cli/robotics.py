"""The robotics outputs of `log record`, `log step` and `monitor`: MCAP files chosen by the output's
suffix and the Foxglove live view (docs/log.md "MCAP" and "Foxglove"). The work is in
log/mcap_out.py, log/foxglove_live.py and log/record_extras.py; this module holds the shared options
and the wiring.
Nothing here imports mcap or foxglove-sdk at import time (`sherpa --help` stays fast).
"""

from __future__ import annotations

import time
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from sherpa_cli.errors import UsageError
from sherpa_cli.output_files import check_output_path

if TYPE_CHECKING:
    from sherpa_cli.cli.context import AppState
    from sherpa_cli.config.model import ArmConfig
    from sherpa_cli.log.foxglove_live import LiveView
    from sherpa_cli.log.record_extras import RecordExtras
    from sherpa_cli.log.recording import Recording

Foxglove = Annotated[bool, typer.Option(
    "--foxglove", help="Also publish live to Foxglove: foxglove-sdk's WebSocket server on --foxglove-at "
    "(open docs/foxglove/sherpa.json in Foxglove). Needs the robotics extra.")]
FoxgloveAt = Annotated[str, typer.Option(
    "--foxglove-at", metavar="HOST:PORT", help="Where the Foxglove server listens (a non-loopback address "
    "needs --allow-remote).")]
AllowRemote = Annotated[bool, typer.Option(
    "--allow-remote", help="Allow --foxglove-at on a non-loopback address (other machines see the arm).")]

RECORD_SUFFIXES = (".csv", ".mcap")
DEFAULT_AT = "127.0.0.1:8765"  # log/foxglove_live.py DEFAULT_BIND


def record_outputs(outputs: Sequence[Path]) -> dict[str, Path]:
    """suffix -> path of `log record -o` (each .csv / .mcap at most once); checks the robotics extra
    before anything is sent."""
    chosen: dict[str, Path] = {}
    for path in outputs:
        suffix = path.suffix.lower()
        if suffix not in RECORD_SUFFIXES:
            raise UsageError(f"-o {path}: only .csv and .mcap are written", hint="name the file run.csv or run.mcap")
        if suffix in chosen:
            raise UsageError(f"-o {path}: a {suffix} file is already given ({chosen[suffix]})")
        if not path.parent.exists():
            raise UsageError(f"-o {path}: directory {path.parent} does not exist")
        check_output_path(path, "-o", "the recording")
        chosen[suffix] = path
    if ".mcap" in chosen:
        from sherpa_cli.log.mcap_out import require_mcap

        require_mcap(f"-o {chosen['.mcap']}")
    return chosen


def check_live(on: bool, at: str, allow_remote: bool) -> tuple[str, int] | None:
    """(host, port) of --foxglove, None without it; refuses a bad or non-loopback address (without
    --allow-remote) and a missing foxglove-sdk, before anything is sent."""
    if not on:
        if at != DEFAULT_AT or allow_remote:
            raise UsageError("--foxglove-at and --allow-remote need --foxglove")
        return None
    from sherpa_cli.log.foxglove_live import check_bind, parse_bind, require_foxglove

    require_foxglove()
    host, port = parse_bind(at)
    check_bind(host, allow_remote)
    return host, port


@contextmanager
def live_view(st: AppState, on: bool, at: str, allow_remote: bool) -> Iterator[LiveView | None]:
    """The Foxglove server for the command's lifetime (None without --foxglove); its address is
    printed on stderr."""
    bind = check_live(on, at, allow_remote)
    if bind is None:
        yield None
        return
    from sherpa_cli.log.foxglove_live import LiveView

    with LiveView(*bind) as view:
        st.out.info(f"foxglove: {view.url} (layout docs/foxglove/sherpa.json)")
        yield view


def write_mcap(path: Path, rec: Recording, cfg: ArmConfig, *, time_zero_ns: int, extras: RecordExtras,
               info: Mapping[str, str], config_file: str, step_metrics: Mapping[str, Any] | None = None) -> None:
    from sherpa_cli.log.mcap_out import write_recording

    write_recording(path, rec, cfg, time_zero_ns=time_zero_ns, info=info, status=extras.status, emcy=extras.emcy,
                    step_metrics=step_metrics, config_file=config_file)


# -- monitor ---------------------------------------------------------------------------------------

class MonitorFeed:
    """`monitor --foxglove`: after each poll, the snapshot as joint states, motor counts, drive
    status, bus load, and each EMCY once."""

    def __init__(self, view: LiveView, cfg: ArmConfig) -> None:
        self.view, self.cfg = view, cfg
        self._seen: dict[str, Any] = {}

    def publish(self, rows: Sequence[Any]) -> None:
        from sherpa_cli.log.mcap_out import DriveState

        ns = time.time_ns()
        # every watched joint, in config order, null while its drive does not answer: the layout's
        # plots address joints by their index
        by_joint = {r.joint: r.position_rad for r in rows if r.joint is not None}
        names = [j for j in self.cfg.joints if j in by_joint]
        self.view.joint_states(names, [by_joint[j] for j in names], ns=ns)
        self.view.motor_counts([r.drive for r in rows], [r.px for r in rows], ns=ns)
        self.view.status([DriveState(r.drive, r.bus, r.node, mo=r.mo, um=r.um, sr=r.sr, mf=r.mf,
                                     problem=None if r.answering else (r.problem or "no answer")) for r in rows], ns=ns)
        self.view.bus_load(ns=ns)
        for r in rows:
            if r.emcy is not None and self._seen.get(r.drive) is not r.emcy:
                self._seen[r.drive] = r.emcy
                self.view.emcy(r.drive, r.emcy, ns=ns)
