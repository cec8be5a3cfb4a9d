"""PNG plots of a recording (matplotlib, Agg backend, imported only here and only when plotting)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

from sherpa_cli.errors import UsageError
from sherpa_cli.log.recording import SIGNALS, UNITS, Recording
from sherpa_cli.log.step_metrics import StepMetrics

if TYPE_CHECKING:
    from matplotlib.axes import Axes

MISSING = "log plot needs matplotlib, an optional extra of sherpa-cli"
MISSING_HINT = "pip install 'sherpa-cli[plot]' (or pip install matplotlib)"


def have_matplotlib() -> bool:
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return False
    return True


def plot_recording(rec: Recording, joints: list[str], path: Path, *,
                   metrics: Mapping[tuple[str, str], StepMetrics] | None = None, title: str | None = None) -> None:
    """One column per joint, one row per signal present (position, velocity, current); step
    metrics (keyed by (joint, signal)) drawn on their signal's axes and written in its legend."""
    try:
        import matplotlib
    except ImportError:
        raise UsageError(MISSING, hint=MISSING_HINT) from None
    matplotlib.use("Agg", force=True)
    from matplotlib.figure import Figure  # a Figure without pyplot: no global state, no GUI

    signals = [s for s in SIGNALS if any(rec.series(j, s) for j in joints)]
    fig = Figure(figsize=(6 * len(joints), 2.6 * len(signals)), dpi=100, layout="constrained")
    axes = fig.subplots(len(signals), len(joints), squeeze=False, sharex=True)
    for col, joint in enumerate(joints):
        for row, signal in enumerate(signals):
            ax = axes[row][col]
            series = rec.series(joint, signal)
            unit = UNITS[SIGNALS[signal]]
            if series is None:
                ax.set_visible(False)
                continue
            ax.plot(series[0], series[1], lw=1.0, label=f"{joint} {signal}")
            ax.set_ylabel(f"{signal} [{unit}]")
            ax.grid(True, alpha=0.3)
            m = (metrics or {}).get((joint, signal))
            if m is not None:
                _draw_metrics(ax, m, unit)
            ax.legend(loc="best", fontsize="small")
        axes[-1][col].set_xlabel("time [s]")
        axes[0][col].set_title(joint)
    if title:
        fig.suptitle(title)
    fig.savefig(str(path), format="png")


def _draw_metrics(ax: Axes, m: StepMetrics, unit: str) -> None:
    ax.axvline(0.0, color="grey", lw=0.8, ls=":", label="command")
    ax.axhline(m.final, color="green", lw=0.8, ls="--", label=f"final {m.final:.4g} {unit}")
    if m.target is not None:
        ax.axhline(m.target, color="black", lw=0.8, ls=":", label=f"target {m.target:.4g} {unit}")
    if m.dead_time is not None:
        ax.axvline(m.dead_time, color="orange", lw=0.8, label=f"dead time {1000 * m.dead_time:.1f} ms")
    if m.settling_time is not None:
        ax.axvline(m.settling_time, color="red", lw=0.8, label=f"settled (2 %) {1000 * m.settling_time:.1f} ms")
    text = [f"rise 10-90 %: {'-' if m.rise_time is None else f'{1000 * m.rise_time:.1f} ms'}",
            f"overshoot: {m.overshoot:.1f} %"]
    if m.steady_state_error is not None:
        text.append(f"steady-state error: {m.steady_state_error:.3g} {unit}")
    for line in text:  # in the legend, so it never covers the curve or the legend
        ax.plot([], [], " ", label=line)
