"""`sherpa log step --compare RUN...`: several `log step` runs side by side.

A run is the directory `log step -o DIR` wrote (metrics.json and recording.csv). Each run gets
its step metrics as recorded and the figures the seed's Section 9 reads off its plots
(:class:`RunFigures`): the speed's peak and when it came, the mean speed and its ripple over the
last part of the record (a velocity step's constant speed, Figs. 9.3/9.6; a torque step's
speed, Fig. 9.8), and when a position move began to slow down (Fig. 9.5: a 1 A supply "after
around 100ms", the 20 A supply "after around 400ms"). Times are from the start of the motion
(the end of the dead time), so a mode switch before it does not shift them.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sherpa_cli.errors import UsageError
from sherpa_cli.log.recording import Recording, read_csv

if TYPE_CHECKING:
    from matplotlib.figure import Figure

STEADY_SHARE = 0.5  # the last half of what was recorded after the motion began is its steady part
SLOWING = 0.9  # a move slows down once its speed falls below this share of the peak


@dataclass(frozen=True)
class RunFigures:
    """What one run shows; speeds in rad/s, times in s."""

    name: str  # the run's directory name
    path: str
    joint: str
    mode: str
    value: float
    switch_s: float
    switch_steps: list[str]
    settled: bool
    metrics: dict[str, Any]
    motion_start_s: float | None  # t of the motion's start (the dead time), from the command
    peak_speed: float  # rad/s, signed as the move
    peak_speed_after_s: float | None  # s from the motion's start to the peak speed
    slowing_after_s: float | None  # s from the motion's start until the speed fell below 90 % of its peak
    steady_speed: float | None  # mean speed over the steady part
    steady_ripple: float | None  # standard deviation over the steady part / |mean|

    def as_json(self) -> dict[str, Any]:
        return {k: (round(v, 6) if isinstance(v, float) else v) for k, v in asdict(self).items()}


def load_run(path: Path) -> tuple[dict[str, Any], Recording]:
    """A `log step` run directory: its metrics.json and recording.csv."""
    if not path.is_dir():
        raise UsageError(f"{path}: not a directory of `sherpa log step -o DIR`")
    files = {name: path / name for name in ("metrics.json", "recording.csv")}
    for name, file in files.items():
        if not file.is_file():
            raise UsageError(f"{path}: has no {name}; expected a directory written by `sherpa log step -o DIR`")
    try:
        meta = json.loads(files["metrics.json"].read_text(encoding="utf-8"))
    except ValueError as exc:
        raise UsageError(f"{files['metrics.json']}: not JSON ({exc})") from None
    if not isinstance(meta, dict) or not {"joint", "mode", "metrics"} <= meta.keys():
        raise UsageError(f"{files['metrics.json']}: not the metrics of a `log step` run (joint, mode, metrics)")
    return meta, read_csv(files["recording.csv"])


def figures(path: Path) -> tuple[RunFigures, Recording]:
    meta, rec = load_run(path)
    joint = str(meta["joint"])
    vel = rec.series(joint, "vel")
    dead = meta["metrics"].get("dead_time")
    start = float(dead) if isinstance(dead, (int, float)) else 0.0
    peak = 0.0
    peak_after = slowing = steady = ripple = None
    if vel is not None:
        after = [(t, v) for t, v in zip(*vel, strict=True) if t >= start]
        if after:
            sign = -1.0 if float(meta.get("value", 1.0)) < 0 else 1.0
            t_peak, peak = max(after, key=lambda tv: sign * tv[1])
            peak_after = t_peak - start
            slowing = next((t - start for t, v in after if t > t_peak and sign * v < SLOWING * sign * peak), None)
            tail_from = after[-1][0] - STEADY_SHARE * (after[-1][0] - after[0][0])
            tail = [v for t, v in after if t >= tail_from]
            if len(tail) > 1:
                steady = sum(tail) / len(tail)
                sd = math.sqrt(sum((v - steady) ** 2 for v in tail) / (len(tail) - 1))
                ripple = sd / abs(steady) if steady else None
    fig = RunFigures(name=path.name, path=str(path), joint=joint, mode=str(meta["mode"]),
                     value=float(meta.get("value", 0.0)), switch_s=float(meta.get("switch_s", 0.0)),
                     switch_steps=list(meta.get("switch_steps", [])), settled=bool(meta.get("settled", False)),
                     metrics=dict(meta["metrics"]), motion_start_s=dead if isinstance(dead, (int, float)) else None,
                     peak_speed=peak, peak_speed_after_s=peak_after, slowing_after_s=slowing, steady_speed=steady,
                     steady_ripple=ripple)
    return fig, rec


def compare(paths: Sequence[Path]) -> list[tuple[RunFigures, Recording]]:
    if len(paths) < 1:
        raise UsageError("--compare needs at least one run directory (of `sherpa log step -o DIR`)")
    return [figures(p) for p in paths]


def plot_compare(runs: Sequence[tuple[RunFigures, Recording]], path: Path) -> Figure:
    """Every run's position and velocity over time since its command, one line per run, its
    metrics in the legend (outside the data). Returns the matplotlib Figure."""
    from sherpa_cli.log.plot import figure, legend_outside, plain_axis

    fig = figure()
    axes = fig.subplots(2, 1, squeeze=False, sharex=True)
    rows = (("pos", "position change", "rad"), ("vel", "velocity", "rad/s"))
    for row, (signal, label, unit) in enumerate(rows):
        ax = axes[row][0]
        values: list[float] = []
        for f, rec in runs:
            series = rec.series(f.joint, signal)
            if series is None:
                continue
            if signal == "pos":  # from where each run's joint stood at t = 0: runs from other places overlay
                before = [v for t, v in zip(*series, strict=True) if t < 0] or series[1][:1]
                series = (series[0], [v - before[-1] for v in series[1]])
            values.extend(series[1])
            what = f"{f.name}: {f.mode} {f.value:+g}"
            if signal == "vel":
                what += f", peak {f.peak_speed:+.3f} rad/s"
                if f.steady_speed is not None and f.mode != "position":
                    what += f", steady {f.steady_speed:+.3f} rad/s"
            else:
                what += "" if f.settled else " (not settled)"
            ax.plot(series[0], series[1], lw=1.0, label=what)
        ax.axvline(0.0, color="black", lw=0.9, ls="--", label="command (t = 0)")
        ax.set_ylabel(f"{label} [{unit}]")
        ax.grid(True, alpha=0.3)
        plain_axis(ax, values, 0.02 if signal == "pos" else 0.05)
        legend_outside(ax)
    axes[-1][0].set_xlabel("time since the command [s]")
    fig.suptitle("log step: " + ", ".join(f.name for f, _ in runs))
    fig.savefig(str(path), format="png")
    return fig
