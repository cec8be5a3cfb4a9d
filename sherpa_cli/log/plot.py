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
    target: float | None = None  # where the step goes (position: start + value), as the legend's target line


def value_text(value: float, unit: str) -> str:
    """A level as the legends and the titles write it: the same digits in both."""
    return f"{value:.4g} {unit}"


def switch_text(switch_s: float) -> str:
    """The MO/UM switch window as its legend entry and the title name it."""
    return f"MO/UM switch {1000 * switch_s:.0f} ms"


def step_title(joint: str, marks: StepMarks) -> str:
    """``elbow_pitch: velocity step +0.1 rad/s; MO/UM switch 30 ms`` -- joint units, not ``JV=57``.
    A position step is relative: where it goes is said too, as the legend's target line says it
    (``position step -2 rad (to -1 rad)``), so the title never reads as a different step."""
    unit = MODE_UNITS.get(marks.mode, "")
    switch = switch_text(marks.switch_s) if marks.switch_s > 0 else "no mode switch"
    goal = f" (to {value_text(marks.target, unit)})" if marks.mode == "position" and marks.target is not None else ""
    return f"{joint}: {marks.mode} step {marks.value:+g} {unit}{goal}; {switch}"


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
                   metrics: Mapping[tuple[str, str], StepMetrics] | None = None,
                   title: str | None = None, marks: StepMarks | None = None, label: str = "measured",
                   overlay: tuple[str, Recording] | None = None) -> Figure:
    """One column per joint, one row per signal present (position, velocity, current); step
    metrics (keyed by (joint, signal)) drawn on their signal's axes and listed in its legend;
    ``marks``: a step experiment's command and switch window on every axes; ``label``: the
    recording's legend entry; ``overlay``: (its legend entry, another recording of the same joints)
    drawn thin on the same axes (a step's CAN recording beside the drive's). Returns the Figure."""
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
            ax.plot(series[0], series[1], lw=1.0, label=label)
            other = overlay[1].series(joint, signal) if overlay is not None else None
            if overlay is not None and other is not None:
                ax.plot(other[0], other[1], lw=0.7, color="grey", alpha=0.8, label=overlay[0])
            ax.set_ylabel(f"{SIGNAL_NAMES[signal]} [{unit}]")
            ax.grid(True, alpha=0.3)
            plain_axis(ax, [*series[1], *(other[1] if other is not None else [])], MIN_SPAN[signal])
            if marks is not None:
                _draw_command(ax, marks)
            m = (metrics or {}).get((joint, signal))
            if m is not None:
                _draw_metrics(ax, m, unit)
            legend_outside(ax)
        axes[-1][col].set_xlabel("time since the command [s]" if marks is not None else "time [s]")
        if title is None or len(joints) > 1:  # one joint under a title is named once, in the title
            axes[0][col].set_title(joint)
    if title:
        fig.suptitle(title)
    fig.savefig(str(path), format="png")
    return fig


def _draw_command(ax: Axes, marks: StepMarks) -> None:
    ax.axvline(0.0, color="black", lw=0.9, ls="--", label="command (t = 0)")
    if marks.switch_s > 0:
        ax.axvspan(0.0, marks.switch_s, color="orange", alpha=0.2, lw=0, label=switch_text(marks.switch_s))


def _draw_metrics(ax: Axes, m: StepMetrics, unit: str) -> None:
    if m.settled:
        ax.axhline(m.final, color="green", lw=0.8, ls="--", label=f"final {value_text(m.final, unit)}")
        band = 0.02 * abs(m.final - m.initial)
        if band > 0:
            ax.axhspan(m.final - band, m.final + band, color="green", alpha=0.08, lw=0, label="settling band (2 %)")
    if m.target is not None:
        ax.axhline(m.target, color="black", lw=0.8, ls=":", label=f"target {value_text(m.target, unit)}")
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


@dataclass(frozen=True)
class PairRow:
    """One joint's panel of a pair plot: what it draws and the words for it, from one set of values."""

    name: str
    symbol: str  # Σ | Δ
    values: Sequence[float]
    held: bool
    level: float  # rad: the target, or where the held joint started
    level_label: str  # the legend's entry of ``level``: the title says the same
    title: str


def pair_rows(trace: PairTrace) -> tuple[PairRow, PairRow]:
    """Σ and Δ: the held joint's level is where it started (its target is that within a count of
    rounding), the other's its target; each level is written once and used by legend and titles."""
    rows = []
    for name, symbol, ys, target in ((trace.sigma, "Σ", trace.sigma_rad, trace.sigma_target),
                                     (trace.delta, "Δ", trace.delta_rad, trace.delta_target)):
        held = name == trace.held
        level = (ys[0] if ys else target) if held else target
        label = f"held at {level:+.4f} rad" if held else f"target {level:+.4f} rad"
        rows.append(PairRow(name, symbol, ys, held, level, label, f"{symbol} {name}" + (" (held)" if held else "")))
    return rows[0], rows[1]


def pair_title(trace: PairTrace) -> str:
    """``diffdrive move diff: Σ target +0.5000 rad, Δ held at +0.1000 rad (group)``: each joint's
    level in its legend's words; the joints are named once, in their panels' titles."""
    what = ", ".join(f"{r.symbol} {r.level_label}" for r in pair_rows(trace))
    return f"diffdrive move {trace.pair}: {what}" + (f" ({trace.subtitle})" if trace.subtitle else "")


def plot_pair(trace: PairTrace, path: Path | str) -> Figure:
    """Σ above Δ over time, the targets and the command drawn, the held joint with at least
    ``held_span`` of y range and its peak excursion marked. Returns the Figure."""
    fig = figure()
    axes = fig.subplots(2, 1, squeeze=False, sharex=True)
    for r, row in zip(pair_rows(trace), axes, strict=True):
        ax = row[0]
        ys = r.values
        ax.plot(trace.times, ys, lw=1.0, label="measured")
        ax.axvline(0.0, color="black", lw=0.9, ls="--", label="command (t = 0)")
        if r.held:
            ax.axhline(r.level, color="grey", lw=0.8, ls=":", label=r.level_label)
            if trace.held_excursion > 0:
                ax.axhspan(r.level - trace.held_excursion, r.level + trace.held_excursion, color="red", alpha=0.12,
                           lw=0, label=f"peak excursion ±{trace.held_excursion:.4f} rad")
            plain_axis(ax, [*ys, r.level - trace.held_excursion, r.level + trace.held_excursion],
                       max(trace.held_span, 4 * trace.held_excursion))
        else:
            ax.axhline(r.level, color="grey", lw=0.8, ls="--", label=r.level_label)
            plain_axis(ax, [*ys, r.level], MIN_SPAN["pos"])
        ax.set_ylabel(f"{r.symbol} position [rad]")
        ax.set_title(r.title, fontsize="medium")
        ax.grid(True, alpha=0.3)
        legend_outside(ax)
    axes[-1][0].set_xlabel("time since the command [s]")
    fig.suptitle(pair_title(trace))
    save_png(fig, path)
    return fig


# --------------------------------------------------------------------------- runs of one step compared

@dataclass(frozen=True)
class StepRun:
    """One run of a step compared with others (`tune step`: the drive's own gains, then trial gains)."""

    label: str  # its legend entry, e.g. "own gains (KP[2]=1)": the title says the same
    value: float  # the step as asked (joint units)
    times: Sequence[float]  # s since the command
    values: Sequence[float]  # the stepped signal (joint units)
    metrics: StepMetrics


def along_step(run: StepRun) -> list[float]:
    """The signal as distance moved along the run's own step from where it began (a position step
    back the other way rises like the first): runs compare on one axis."""
    sign = -1.0 if run.value < 0 else 1.0
    return [sign * (v - run.metrics.initial) for v in run.values]


def runs_title(joint: str, mode: str, runs: Sequence[StepRun]) -> str:
    """``tune step elbow_pitch: position +0.2 rad with own gains (KP[3]=30), -0.2 rad with trial
    (KP[3]=40)``: each run's step and its legend entry."""
    unit = MODE_UNITS.get(mode, "")
    return f"tune step {joint}: {mode} " + ", ".join(f"{r.value:+g} {unit} with {r.label}" for r in runs)


def plot_step_runs(joint: str, mode: str, signal: str, runs: Sequence[StepRun], path: Path | str) -> Figure:
    """The runs' stepped signal on one axes (position: moved along each run's step), the command at
    t = 0 and each run's figures in its legend entry. Returns the Figure."""
    fig = figure()
    ax = fig.subplots(1, 1)
    unit = UNITS[SIGNALS[signal]]
    shown: list[float] = []
    for run in runs:
        ys = along_step(run) if mode == "position" else list(run.values)
        shown.extend(ys)
        m = run.metrics
        figures = [f"rise {'-' if m.rise_time is None else f'{1000 * m.rise_time:.1f} ms'}"]
        if m.settled:
            figures.append(f"overshoot {m.overshoot:.1f} %")
            figures.append(f"settled {'-' if m.settling_time is None else f'{1000 * m.settling_time:.1f} ms'}")
        else:
            figures.append("not settled")
        ax.plot(run.times, ys, lw=1.0, label=f"{run.label}: {', '.join(figures)}")
    ax.axvline(0.0, color="black", lw=0.9, ls="--", label="command (t = 0)")
    ax.set_ylabel(f"{SIGNAL_NAMES[signal]} moved along the step [{unit}]" if mode == "position"
                  else f"{SIGNAL_NAMES[signal]} [{unit}]")
    ax.set_xlabel("time since the command [s]")
    ax.grid(True, alpha=0.3)
    plain_axis(ax, shown, MIN_SPAN[signal])
    legend_outside(ax)
    fig.suptitle(runs_title(joint, mode, runs))
    save_png(fig, path)
    return fig
