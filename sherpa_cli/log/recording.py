"""A recording of joint motion: one timestamp per sample, named columns, and its CSV form.

Columns: ``time_s`` (s; 0 = the step's command in `log step`, else the first sample), then per
joint ``<joint>.pos_rad``, ``<joint>.vel_rad_s`` (and ``<joint>.cur_a`` for a plain joint when
current is sampled), then per drive the motor's ``<drive>.px`` and ``<drive>.vx`` in counts,
counts/s (and ``<drive>.iq_a``); a joint's CANopen encoder (devices/encoder.py) adds ``<device>.pos``
(counts) and ``<joint>.ext_pos_rad``. A sample a drive did not deliver is an empty cell.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path

from sherpa_cli.errors import UsageError

TIME = "time_s"
SIGNALS = {"pos": "pos_rad", "vel": "vel_rad_s", "cur": "cur_a"}
UNITS = {"pos_rad": "rad", "vel_rad_s": "rad/s", "cur_a": "A"}


@dataclass
class Recording:
    times: list[float] = field(default_factory=list)
    columns: dict[str, list[float]] = field(default_factory=dict)  # name -> values (nan = missing)

    def joints(self) -> list[str]:
        return list(dict.fromkeys(name.split(".", 1)[0] for name in self.columns
                                  if name.split(".", 1)[1] in UNITS))

    def sample_rows(self) -> list[int]:
        """The rows that hold a sample: a position of a recorded joint (the rows an MCAP's
        /joint_states has), or of a drive when no joint is recorded. The one count of a recording's
        samples: the report, the MCAP's metadata and a step's metrics all take it from here."""
        names = [f"{j}.pos_rad" for j in self.joints()] or [n for n in self.columns if n.endswith(".px")]
        columns = [self.columns[n] for n in names if n in self.columns]
        return [i for i in range(len(self.times)) if any(not math.isnan(c[i]) for c in columns)]

    def joint(self, name: str) -> JointSeries:
        """One joint's samples, typed: position (rad), velocity (rad/s), current (A)."""
        return joint_series(self, name)

    def drive(self, name: str) -> DriveSeries:
        """One drive's motor samples, typed: position and velocity in counts, current (A)."""
        return drive_series(self, name)

    def series(self, joint: str, signal: str) -> tuple[list[float], list[float]] | None:
        values = self.columns.get(f"{joint}.{SIGNALS[signal]}")
        if values is None:
            return None
        pairs = [(t, v) for t, v in zip(self.times, values, strict=True) if not math.isnan(v)]
        return [p[0] for p in pairs], [p[1] for p in pairs]


def write_csv(rec: Recording, path: Path) -> None:
    with CsvWriter(path, list(rec.columns)) as out:
        out.write(rec)


class CsvWriter:
    """A recording's CSV written as it is made: the header at once, then each batch of rows
    (:meth:`write`) flushed to the file, so a killed recording leaves a readable file up to its
    last batch (`log record`, log/record.py ``Recorder(sink=...)``). Rows are formatted exactly
    as :func:`write_csv` formats a whole recording."""

    def __init__(self, path: Path, names: list[str]) -> None:
        self.path, self.names, self.rows = path, names, 0
        self._fh = path.open("w", newline="", encoding="utf-8")
        self._writer = csv.writer(self._fh)
        self._writer.writerow([TIME, *names])
        self._fh.flush()
        counts = tuple(name.endswith((".px", ".vx", ".pos")) for name in names)
        self._formats = ["{:.0f}" if c else "{:.6g}" for c in counts]

    def write(self, rec: Recording) -> None:
        columns = [rec.columns[name] for name in self.names]
        formats = self._formats
        for i, t in enumerate(rec.times):
            row = [f"{t:.6f}"]
            for fmt, values in zip(formats, columns, strict=True):
                v = values[i]
                row.append("" if v != v else fmt.format(v))
            self._writer.writerow(row)
        self.rows += len(rec.times)
        self._fh.flush()

    def close(self) -> None:
        self._fh.close()

    def __enter__(self) -> CsvWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def read_csv(path: Path) -> Recording:
    if not path.is_file():
        raise UsageError(f"{path}: no such recording")
    try:
        return _read_csv(path)
    except (UnicodeDecodeError, csv.Error) as exc:
        raise UsageError(f"{path}: not a sherpa recording ({exc})") from None


def _read_csv(path: Path) -> Recording:
    with path.open(newline="", encoding="utf-8") as fh:
        reader = csv.reader(fh)
        header = next(reader, None)
        if not header or header[0] != TIME:
            raise UsageError(f"{path}:1: not a sherpa recording (the first column must be {TIME})",
                             hint="record one with `sherpa log record ... -o FILE.csv`")
        rec = Recording(columns={name: [] for name in header[1:]})
        for number, row in enumerate(reader, 2):
            if len(row) != len(header):
                raise UsageError(f"{path}:{number}: {len(row)} cells, the header has {len(header)}")
            try:
                if not all(cell.isascii() for cell in row):  # float() reads other scripts' digits
                    raise ValueError("a cell is not a number in ASCII digits 0-9")
                rec.times.append(float(row[0]))
                for name, cell in zip(header[1:], row[1:], strict=True):
                    rec.columns[name].append(float(cell) if cell else math.nan)
                if not math.isfinite(rec.times[-1]):
                    raise ValueError(f"time {row[0]!r} is not a finite number")
            except ValueError as exc:
                raise UsageError(f"{path}:{number}: {exc}") from None
    if len(rec.times) < 2:
        raise UsageError(f"{path}: fewer than two samples")
    return rec


@dataclass(frozen=True)
class JointSeries:
    """One joint of a recording in joint units, a value per row of ``times`` (nan: no sample)."""

    name: str
    times: list[float]  # s
    position: list[float]  # rad
    velocity: list[float]  # rad/s
    current: list[float] | None  # A, when current was sampled


@dataclass(frozen=True)
class DriveSeries:
    """One drive's motor in a recording, in counts, a value per row of ``times`` (nan: no sample)."""

    name: str
    times: list[float]  # s
    position_counts: list[float]
    velocity_counts: list[float]  # counts/s
    current: list[float] | None  # A (IQ or 0x6078), when current was sampled


def joint_series(rec: Recording, name: str) -> JointSeries:
    """``name``'s columns of ``rec``; UsageError naming the recorded joints when it has none."""
    if f"{name}.{SIGNALS['pos']}" not in rec.columns:
        raise UsageError(f"{name}: not in the recording (it has {', '.join(rec.joints()) or 'no joints'})")
    return JointSeries(name, rec.times, rec.columns[f"{name}.pos_rad"], rec.columns[f"{name}.vel_rad_s"],
                       rec.columns.get(f"{name}.cur_a"))


def drive_series(rec: Recording, name: str) -> DriveSeries:
    """``name``'s motor columns of ``rec``; UsageError naming the recorded drives when it has none."""
    if f"{name}.px" not in rec.columns:
        drives = [n[:-3] for n in rec.columns if n.endswith(".px")]
        raise UsageError(f"{name}: not in the recording (it has {', '.join(drives) or 'no drives'})")
    return DriveSeries(name, rec.times, rec.columns[f"{name}.px"], rec.columns[f"{name}.vx"],
                       rec.columns.get(f"{name}.iq_a"))
