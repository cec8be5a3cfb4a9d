"""Reading a trajectory from a file (docs/trajectory.md): a CSV or MCAP that `sherpa log record`
wrote, or a planner's CSV.

- A recording's CSV (log/recording.py): first column ``time_s``; the joints are the
  ``<joint>.pos_rad`` columns (rad); every other column (velocities, currents, motor counts) is
  left aside. A row where a joint's position is empty (a sample its drive did not deliver) is
  skipped: the path runs through the samples around it. A sample closer than half the
  recording's typical (median) interval to the one kept before it is left out too: the recorder
  sends the SYNCs already due back to back when it falls behind (at its start), and whole counts
  a few microseconds apart would read as an absurd speed.
- A planner's CSV: a header ``t,<joint>,<joint>,...``, then one row per sample, time in s and
  every joint's position in rad. Every cell must be a number.
- A recording's MCAP (`log record -o run.mcap`, log/mcap_out.py): its ``/joint_states`` messages,
  position in rad, time from their log time. A message lacking a joint's position (NaN) is
  skipped, and close samples are left out as in a recording's CSV. Reading it needs the robotics extra (mcap, mcap-ros2-support).

Times are taken from the first sample (it becomes 0). Positions become joint counts with the
joint's ``cpr`` (not rounded). Any file problem is one UsageError (exit 2) naming the file and
the line; the path itself is then checked by joints/trajectory.py ``check_trajectory``.
"""

from __future__ import annotations

import csv
import io
import itertools
import math
from pathlib import Path

from sherpa_cli.config.model import ArmConfig
from sherpa_cli.errors import UsageError
from sherpa_cli.joints.trajectory import Trajectory, check_joints, check_trajectory
from sherpa_cli.log.mcap_out import require_mcap
from sherpa_cli.log.recording import TIME
from sherpa_cli.log.ros_msgs import TOPIC_JOINTS
from sherpa_cli.units import TAU

PLANNER_TIME = "t"
POSITION_SUFFIX = ".pos_rad"
FORMATS_HINT = ("a planner's CSV has the header `t,<joint>,...` (s, rad); `sherpa log record -o FILE.csv` "
                "or `-o FILE.mcap` writes a recording")


def load_trajectory(path: Path, cfg: ArmConfig, *, period: float | None = None,
                    check: bool = True) -> Trajectory:
    """The trajectory in ``path`` (module docstring), checked against ``cfg``'s joints
    (:func:`~sherpa_cli.joints.trajectory.check_trajectory`; with ``period`` its resampled
    velocities too) unless ``check`` is False."""
    path = Path(path)
    if not path.exists():
        raise UsageError(f"{path}: no such file")
    if not path.is_file():
        raise UsageError(f"{path}: not a file")
    traj = _read_mcap(path, cfg) if path.suffix.lower() == ".mcap" else _read_csv(path, cfg)
    if check:
        check_trajectory(cfg, traj, source=str(path), period=period)
    return traj


def _counts(rad: float, cpr: int) -> float:
    return rad * cpr / TAU


def _read_csv(path: Path, cfg: ArmConfig) -> Trajectory:
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError:
        raise UsageError(f"{path}: not a CSV text file (not UTF-8 text)", hint=FORMATS_HINT) from None
    except OSError as exc:
        raise UsageError(f"{path}: cannot be read ({exc.strerror or exc})") from None
    if "\x00" in text:
        raise UsageError(f"{path}: not a CSV text file (it holds NUL bytes)", hint=FORMATS_HINT)
    reader = csv.reader(io.StringIO(text, newline=""))
    try:
        header = next((row for row in reader if row), None)
        if header is None:
            raise UsageError(f"{path}: empty: no header and no samples", hint=FORMATS_HINT)
        header = [cell.strip() for cell in header]
        header_line = reader.line_num
        if header[0] not in (TIME, PLANNER_TIME):
            raise UsageError(f"{path}:{header_line}: no time column: the first column is {header[0]!r}, expected "
                             f"'{PLANNER_TIME}' (a planner's CSV) or '{TIME}' (a `sherpa log record` CSV)",
                             hint=FORMATS_HINT)
        recorded = [i for i, name in enumerate(header) if name.endswith(POSITION_SUFFIX) and i > 0]
        if recorded:
            columns = recorded
            joints = [header[i][: -len(POSITION_SUFFIX)] for i in recorded]
        else:
            columns = list(range(1, len(header)))
            joints = header[1:]
        if not joints:
            raise UsageError(f"{path}:{header_line}: the header names no joint column after {header[0]!r}",
                             hint=FORMATS_HINT)
        for i, name in zip(columns, joints, strict=True):
            if not name:
                raise UsageError(f"{path}:{header_line}: column {i + 1} has no name")
        check_joints(cfg, joints, source=f"{path}:{header_line}")
        cprs = [cfg.joints[j].cpr for j in joints]
        times: list[float] = []
        series: list[list[float]] = [[] for _ in joints]
        rows: list[int] = []
        for row in reader:
            if not row:
                continue  # a blank line
            line = reader.line_num
            if len(row) != len(header):
                raise UsageError(f"{path}:{line}: {len(row)} cells, the header has {len(header)}")
            cells = [row[i].strip() for i in columns]
            if recorded and any(not c for c in cells):
                continue  # a sample a drive did not deliver
            t = _number(path, line, header[0], row[0].strip())
            if not math.isfinite(t):
                raise UsageError(f"{path}:{line}: the time {row[0].strip()!r} is not a finite number")
            values = [_number(path, line, name, cell) for name, cell in zip(joints, cells, strict=True)]
            times.append(t)
            rows.append(line)
            for out, value, cpr in zip(series, values, cprs, strict=True):
                out.append(_counts(value, cpr))
    except csv.Error as exc:
        raise UsageError(f"{path}:{reader.line_num}: not a readable CSV ({exc})", hint=FORMATS_HINT) from None
    if not times:
        raise UsageError(f"{path}: no samples after the header"
                         + (" (every row lacks a joint position)" if recorded else ""))
    return _trajectory(joints, times, series, rows, thin=bool(recorded))


def _trajectory(joints: list[str], times: list[float], series: list[list[float]], rows: list[int] | None,
                *, thin: bool) -> Trajectory:
    """The samples as a Trajectory from time 0; ``thin``: without the samples too close to the one
    before (module docstring). A time that goes back is kept for check_trajectory to name."""
    keep = list(range(len(times)))
    gaps = sorted(b - a for a, b in itertools.pairwise(times) if b > a)
    if thin and gaps:
        least = gaps[len(gaps) // 2] / 2
        keep = [0]
        for i in range(1, len(times)):
            gap = times[i] - times[keep[-1]]
            # a time that goes back is kept, to be refused; one that repeats (the CSV's microseconds) is a
            # catch-up SYNC like the others
            if gap >= least or gap < 0:
                keep.append(i)
        if keep[-1] != len(times) - 1:
            # the end stays the recording's end
            keep[-1 if len(keep) > 1 else len(keep):] = [len(times) - 1]
    t0 = times[0]
    return Trajectory(tuple(joints), tuple(times[i] - t0 for i in keep),
                      tuple(tuple(s[i] for i in keep) for s in series),
                      tuple(rows[i] for i in keep) if rows is not None else ())


def _number(path: Path, line: int, column: str, cell: str) -> float:
    if not cell:
        raise UsageError(f"{path}:{line}: column {column!r} is empty; every cell must be a number")
    try:
        if not cell.isascii():  # float() reads other scripts' digits
            raise ValueError
        return float(cell)
    except ValueError:
        raise UsageError(f"{path}:{line}: column {column!r}: {cell!r} is not a number") from None


def _read_mcap(path: Path, cfg: ArmConfig) -> Trajectory:
    require_mcap(str(path))
    from mcap.exceptions import McapError
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    joints: list[str] | None = None
    stamps: list[int] = []
    series: list[list[float]] = []
    try:
        with path.open("rb") as fh:
            reader = make_reader(fh, decoder_factories=[DecoderFactory()])
            for _schema, _channel, message, ros in reader.iter_decoded_messages(topics=[TOPIC_JOINTS],
                                                                              log_time_order=True):
                names, positions = list(ros.name), list(ros.position)
                if joints is None:
                    joints = names
                    check_joints(cfg, joints, source=f"{path}: {TOPIC_JOINTS}")
                    series = [[] for _ in joints]
                by_name = dict(zip(names, positions, strict=False))
                values = [by_name.get(j, math.nan) for j in joints]
                if any(math.isnan(v) for v in values):
                    continue  # a sample a drive did not deliver
                stamps.append(message.log_time)
                for out, value, name in zip(series, values, joints, strict=True):
                    out.append(_counts(value, cfg.joints[name].cpr))
    except UsageError:
        raise
    except (McapError, ValueError, KeyError, TypeError, EOFError, OSError, AttributeError) as exc:
        raise UsageError(f"{path}: not a readable .mcap recording ({type(exc).__name__}: {exc})",
                         hint=FORMATS_HINT) from None
    if joints is None:
        raise UsageError(f"{path}: no {TOPIC_JOINTS} messages: not a recording of joints", hint=FORMATS_HINT)
    if not stamps:
        raise UsageError(f"{path}: no {TOPIC_JOINTS} message has every joint's position")
    t0 = stamps[0]
    return _trajectory(joints, [(s - t0) / 1e9 for s in stamps], series, None, thin=True)
