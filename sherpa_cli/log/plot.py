"""PNG plots of a recording (matplotlib, Agg backend, imported only here and only when plotting).

Plots a technician reads at a glance: joint units in titles and axes (never a raw drive
command like ``JV=57``); the command time, the MO/UM switch window and the settling time drawn on
the trace; the legend beside the data, never over it; a fixed figure size that fits a screen
(:data:`FIG_SIZE`); plain tick labels (no ``1e-16`` offset) and a minimum span per signal
(:data:`MIN_SPAN`), so a joint that holds still shows as a flat line, not as magnified quantisation.
The functions return the matplotlib ``Figure`` they saved, so tests read its artist tree.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from sherpa_cli.errors import UsageError
from sherpa_cli.log.recording import SIGNALS, UNITS, Recording
from sherpa_cli.log.step_metrics import StepMetrics

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

MISSING = "log plot needs matplotlib, an optional extra of sherpa-cli"
MISSING_HINT = "pip install 'sherpa-cli[plot]' (or pip install matplotlib)"

FIG_SIZE = (10.0, 6.0)  # inches: 1000 x 600 px at DPI, whatever the number of joints
DPI = 100
SIGNAL_NAMES = {"pos": "position", "vel": "velocity", "cur": "current"}
# the smallest y span an axis shows (rad, rad/s, A): a still joint's few counts of noise stay flat
MIN_SPAN = {"pos": 0.02, "vel": 0.05, "cur": 0.05}
MODE_UNITS = {"position": "rad", "velocity": "rad/s", "torque": "A"}


def have_matplotlib() -> bool:
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return False
    return True


def check_plot_path(path: str | Path | None, option: str = "--plot") -> None:
    """Refuse, before anything moves or is measured, a plot that could not be drawn: not a .png name,
    matplotlib missing, or a path that can never be written (UsageError)."""
    if path is None:
        return
    from sherpa_cli.output_files import check_output_path

    if not str(path).lower().endswith(".png"):
        raise UsageError(f"{option} {path}: expected a .png file name")
    if not have_matplotlib():
        raise UsageError(f"{option} needs matplotlib, an optional extra of sherpa-cli; nothing was moved",
                         hint=MISSING_HINT)
    check_output_path(path, option, "the plot")  # a missing directory is made when the plot is saved


def save_png(fig: Figure, path: str | Path) -> None:
    """``fig`` as a PNG at ``path``, its missing directories made first (savefig makes none)."""
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(str(path), format="png")


@dataclass(frozen=True)
class StepMarks:
    """What a step experiment draws on its trace: the command at ``t = 0`` and the MO/UM switch
    window ``[0, switch_s]`` (the drive had to switch its unit mode or its motor first, Fig. 9.1)."""

    mode: str  # position | velocity | torque
    value: float  # the step as asked, in joint units (rad, rad/s, A)
    switch_s: float = 0.0


def step_title(joint: str, marks: StepMarks) -> str:
    """``elbow_pitch: velocity step +0.1 rad/s; MO/UM switch 30 ms`` -- joint units, not ``JV=57``."""
    switch = f"MO/UM switch {1000 * marks.switch_s:.0f} ms" if marks.switch_s > 0 else "no mode switch"
    return f"{joint}: {marks.mode} step {marks.value:+g} {MODE_UNITS.get(marks.mode, '')}; {switch}"


def figure() -> Figure:
    try:
        import matplotlib
    except ImportError:
        raise UsageError(MISSING, hint=MISSING_HINT) from None
    matplotlib.use("Agg", force=True)
    from matplotlib.figure import Figure  # a Figure without pyplot: no global state, no GUI

    return Figure(figsize=FIG_SIZE, dpi=DPI, layout="constrained")


def plain_axis(ax: Axes, values: Sequence[float], min_span: float) -> None:
    """No offset or scientific notation on y, and at least ``min_span`` shown around the data."""
    ax.ticklabel_format(axis="y", useOffset=False, style="plain")
    finite = [v for v in values if math.isfinite(v)]
    if not finite:
        return
    lo, hi = min(finite), max(finite)
    if hi - lo < min_span:
        mid = (lo + hi) / 2
        ax.set_ylim(mid - min_span / 2, mid + min_span / 2)


def legend_outside(ax: Axes) -> None:
    """The legend right of the axes, in the figure's margin: it never covers the trace."""
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, fontsize="small", frameon=False)


def plot_recording(rec: Recording, joints: list[str], path: Path, *,
                   metrics: Mapping[tuple[str, str], StepMetrics] | None = None, title: str | None = None,
                   marks: StepMarks | None = None) -> Figure:
    """One column per joint, one row per signal present (position, velocity, current); step
    metrics (keyed by (joint, signal)) drawn on their signal's axes and listed in its legend;
    ``marks``: a step experiment's command and switch window on every axes. Returns the Figure."""
    fig = figure()
    signals = [s for s in SIGNALS if any(rec.series(j, s) for j in joints)]
    axes = fig.subplots(max(1, len(signals)), max(1, len(joints)), squeeze=False, sharex=True)
    for col, joint in enumerate(joints):
        for row, signal in enumerate(signals):
            ax = axes[row][col]
            series = rec.series(joint, signal)
            unit = UNITS[SIGNALS[signal]]
            if series is None:
                ax.set_visible(False)
                continue
            ax.plot(series[0], series[1], lw=1.0, label=f"{joint} {SIGNAL_NAMES[signal]}")
            ax.set_ylabel(f"{SIGNAL_NAMES[signal]} [{unit}]")
            ax.grid(True, alpha=0.3)
            plain_axis(ax, series[1], MIN_SPAN[signal])
            if marks is not None:
                _draw_command(ax, marks)
            m = (metrics or {}).get((joint, signal))
            if m is not None:
                _draw_metrics(ax, m, unit)
            legend_outside(ax)
        axes[-1][col].set_xlabel("time since the command [s]" if marks is not None else "time [s]")
        axes[0][col].set_title(joint)
    if title:
        fig.suptitle(title)
    fig.savefig(str(path), format="png")
    return fig


def _draw_command(ax: Axes, marks: StepMarks) -> None:
    ax.axvline(0.0, color="black", lw=0.9, ls="--", label="command (t = 0)")
    if marks.switch_s > 0:
        ax.axvspan(0.0, marks.switch_s, color="orange", alpha=0.2, lw=0,
                   label=f"MO/UM switch {1000 * marks.switch_s:.0f} ms")


def _draw_metrics(ax: Axes, m: StepMetrics, unit: str) -> None:
    if m.settled:
        ax.axhline(m.final, color="green", lw=0.8, ls="--", label=f"final {m.final:.4g} {unit}")
        band = 0.02 * abs(m.final - m.initial)
        if band > 0:
            ax.axhspan(m.final - band, m.final + band, color="green", alpha=0.08, lw=0, label="settling band (2 %)")
    if m.target is not None:
        ax.axhline(m.target, color="black", lw=0.8, ls=":", label=f"target {m.target:.4g} {unit}")
    if m.dead_time is not None:
        ax.axvline(m.dead_time, color="orange", lw=0.8, label=f"dead time {1000 * m.dead_time:.1f} ms")
    if m.settling_time is not None and m.settled:
        ax.axvline(m.settling_time, color="red", lw=0.8, label=f"settled (2 %) {1000 * m.settling_time:.1f} ms")
    text = [f"rise 10-90 %: {'-' if m.rise_time is None else f'{1000 * m.rise_time:.1f} ms'}"]
    if m.settled:
        text.append(f"overshoot: {m.overshoot:.1f} %")
        if m.steady_state_error is not None:
            text.append(f"steady-state error: {m.steady_state_error:.3g} {unit}")
    else:
        text.append("not settled: no overshoot or steady-state error")
    for line in text:  # in the legend, so it never covers the curve
        ax.plot([], [], " ", label=line)


# --------------------------------------------------------------------------- a differential pair

@dataclass(frozen=True)
class PairTrace:
    """Both joints of a pair over a move (rad), like the seed's Figs. 9.10/9.11."""

    pair: str
    sigma: str
    delta: str
    times: Sequence[float]  # s since the command
    sigma_rad: Sequence[float]
    delta_rad: Sequence[float]
    sigma_target: float  # rad
    delta_target: float
    held: str | None = None  # the joint that should have held still (None: both were asked to move)
    held_excursion: float = 0.0  # rad, its peak distance from where it started
    held_span: float = 0.02  # rad: the least y span the held joint is shown with (a few counts)
    subtitle: str = ""  # e.g. "group, feedback"


def plot_pair(trace: PairTrace, path: Path | str) -> Figure:
    """Σ above Δ over time, the targets and the command drawn, the held joint with at least
    ``held_span`` of y range and its peak excursion marked. Returns the Figure."""
    fig = figure()
    axes = fig.subplots(2, 1, squeeze=False, sharex=True)
    rows = ((trace.sigma, "Σ", trace.sigma_rad, trace.sigma_target),
            (trace.delta, "Δ", trace.delta_rad, trace.delta_target))
    for (name, symbol, ys, target), row in zip(rows, axes, strict=True):
        ax = row[0]
        held = name == trace.held
        ax.plot(trace.times, ys, lw=1.0, label=f"{name} measured")
        ax.axvline(0.0, color="black", lw=0.9, ls="--", label="command (t = 0)")
        if held:
            start = ys[0] if ys else target
            ax.axhline(start, color="grey", lw=0.8, ls=":", label=f"held at {start:+.4f} rad")
            if trace.held_excursion > 0:
                ax.axhspan(start - trace.held_excursion, start + trace.held_excursion, color="red", alpha=0.12,
                           lw=0, label=f"peak excursion ±{trace.held_excursion:.4f} rad")
            plain_axis(ax, [*ys, start - trace.held_excursion, start + trace.held_excursion],
                        max(trace.held_span, 4 * trace.held_excursion))
        else:
            ax.axhline(target, color="grey", lw=0.8, ls="--", label=f"target {target:+.4f} rad")
            plain_axis(ax, [*ys, target], MIN_SPAN["pos"])
        ax.set_ylabel(f"{symbol} {name} [rad]")
        ax.set_title(f"{symbol} {name}" + (" (held)" if held else ""), fontsize="medium")
        ax.grid(True, alpha=0.3)
        legend_outside(ax)
    axes[-1][0].set_xlabel("time since the command [s]")
    what = f"diffdrive move {trace.pair}: Σ {trace.sigma} to {trace.sigma_target:+.4f} rad, " \
           f"Δ {trace.delta} to {trace.delta_target:+.4f} rad"
    fig.suptitle(what + (f" ({trace.subtitle})" if trace.subtitle else ""))
    save_png(fig, path)
    return fig
