"""The seed's Section 9 in numbers: the runs of `recipes/seed-section9.yaml` summarised and set
against bands taken from the seed's text (docs/section9.md, docs/section9/bands.yaml).

The recipe leaves one directory per `log step` run and one JSON report per `diffdrive move`
(:data:`RUNS`); :func:`summarize` reads them and gives each figure a key (``fig9_1.switch_ms``),
:func:`check` compares them with the bands. Times are from the command (t = 0), as in the seed's
plots; speeds in rad/s, positions in rad.
"""

from __future__ import annotations

import bisect
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sherpa_cli.errors import UsageError
from sherpa_cli.log.recording import Recording
from sherpa_cli.log.step_compare import RunFigures, figures

# the recipe's outputs, by what they reproduce
STEPS = {"fig9-1": "9.1", "fig9-2": "9.2", "fig9-3": "9.3", "fig9-4-1a": "9.4/9.5 (1 A)",
         "fig9-4-20a": "9.4/9.5 (20 A)", "fig9-6": "9.6", "fig9-8": "9.8"}
MOVES = {"fig9-10-naive": "9.10", "fig9-10-group": "9.10 (common start)", "fig9-10-feedback": "9.10 (feedback)",
         "fig9-11-naive": "9.11", "fig9-11-group": "9.11 (common start)", "fig9-11-feedback": "9.11 (feedback)"}
RUNS = (*STEPS, *MOVES)
DEPART = 0.9  # a move decelerates once its speed is below this share of its peak
FALL = 0.9  # a speed is falling once it is below this share of its peak


@dataclass(frozen=True)
class Band:
    key: str
    figure: str
    quote: str  # the seed's sentence the band comes from
    low: float
    high: float
    unit: str
    reading: str  # how the sentence becomes these numbers
    seed: str = ""  # the seed's number (or words) for it
    tool: str = ""  # the tool's number on the seed profile (tests/test_section9.py's run), and where it departs

    def holds(self, value: float | None) -> bool:
        return value is not None and math.isfinite(value) and self.low <= value <= self.high


def _number(value: object, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise UsageError(f"{where}: expected a number, got {value!r}")
    return float(value)


def load_bands(path: Path) -> list[Band]:
    """docs/section9/bands.yaml: ``bands:`` a list of {key, figure, quote, min, max, unit, reading, seed, tool}."""
    import yaml

    try:
        doc = yaml.safe_load(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise UsageError(f"--bands {path}: cannot read it: {exc.strerror or exc}") from None
    except yaml.YAMLError as exc:
        raise UsageError(f"--bands {path}: not YAML: {exc}") from None
    items = doc.get("bands") if isinstance(doc, dict) else None
    if not isinstance(items, list) or not items:
        raise UsageError(f"{path}: expected a list under 'bands:'")
    out = []
    for i, item in enumerate(items):
        where = f"{path}: bands[{i}]"
        if not isinstance(item, dict) or not {"key", "figure", "quote", "min", "max", "unit"} <= item.keys():
            raise UsageError(f"{where}: needs key, figure, quote, min, max and unit")
        low, high = _number(item["min"], f"{where}.min"), _number(item["max"], f"{where}.max")
        if low > high:
            raise UsageError(f"{where}: min {low:g} is above max {high:g}")
        out.append(Band(str(item["key"]), str(item["figure"]), " ".join(str(item["quote"]).split()), low, high,
                        str(item["unit"]), " ".join(str(item.get("reading", "")).split()),
                        " ".join(str(item.get("seed", "")).split()), " ".join(str(item.get("tool", "")).split())))
    return out


def _speed_at(rec: Recording, joint: str) -> tuple[list[float], list[float]]:
    series = rec.series(joint, "vel")
    if series is None:
        raise UsageError(f"{joint}: the run has no velocity column")
    return series


def falls_at(run: tuple[RunFigures, Recording], until: float | None) -> float | None:
    """Fig. 9.5's "dropping after around 100ms": when the speed starts to fall while the move still
    cruises -- the time (from the command) of its peak before ``until`` (the 20 A run's deceleration),
    if the speed then falls below FALL of that peak before ``until``; None if it does not fall (a speed
    that levels off, as a stiff supply's, is no drop)."""
    if until is None:
        return None
    t, v = _speed_at(run[1], run[0].joint)
    window = [i for i in range(len(t)) if 0 < t[i] <= until]
    if not window:
        return None
    peak = max(window, key=lambda i: abs(v[i]))
    fell = any(abs(v[i]) < FALL * abs(v[peak]) for i in window if i > peak)
    return t[peak] if fell else None


SEED_SWITCH = ("MO=0", "UM=", "MO=1")  # the seed's software: motor off, the mode changed, motor on


def seed_switch_ms(run: RunFigures) -> float | None:
    """The MO/UM switch's time in ms if the run switched as the seed's software did (Fig. 9.1: "first
    the motor is turned off, the mode changed, and finally the motor is turned on"); None otherwise."""
    steps = run.switch_steps
    if len(steps) != len(SEED_SWITCH) or not all(s.startswith(p) for s, p in zip(steps, SEED_SWITCH, strict=True)):
        return None
    return 1000 * run.switch_s


def _at(times: list[float], values: list[float], t: float) -> float | None:
    """``values`` at ``t``, linear between samples; None outside the record."""
    i = bisect.bisect_left(times, t)
    if i >= len(times) or (i == 0 and times[0] != t):
        return None
    if times[i] == t:
        return values[i]
    t0, t1 = times[i - 1], times[i]
    return values[i - 1] + (values[i] - values[i - 1]) * (t - t0) / (t1 - t0)


def slowing_at(run: tuple[RunFigures, Recording]) -> float | None:
    """When the speed first falls below 90 % of its peak after the peak (the deceleration), from t = 0."""
    t, v = _speed_at(run[1], run[0].joint)
    peak = max(range(len(v)), key=lambda i: abs(v[i]))
    return next((t[i] for i in range(peak, len(v)) if abs(v[i]) < DEPART * abs(v[peak])), None)


def _move(path: Path) -> dict[str, Any]:
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise UsageError(f"{path}: cannot read it ({exc.strerror or exc}); expected `diffdrive move --report`") \
            from None
    except ValueError as exc:
        raise UsageError(f"{path}: not JSON ({exc})") from None
    if not isinstance(doc, dict) or "coupling" not in doc or "sigma" not in doc:
        raise UsageError(f"{path}: not the report of `sherpa diffdrive move --report`")
    return doc


def _held(doc: Mapping[str, Any]) -> tuple[float, float]:
    """(peak excursion in rad, |end - start| in encoder counts) of the joint that should have held still."""
    c = doc["coupling"]
    held = c.get("held")
    side = "sigma" if doc["sigma"]["joint"] == held else "delta"
    j = doc[side]
    return float(c["held_excursion"]["rad"]), float(abs(j["end"] - j["start"]))


def summarize(folder: Path) -> dict[str, float | None]:
    """Every figure the bands name, keyed as in docs/section9/bands.yaml."""
    missing = [n for n in STEPS if not (folder / n).is_dir()] + [f"{n}.json" for n in MOVES
                                                                  if not (folder / f"{n}.json").is_file()]
    if missing:
        raise UsageError(f"{folder}: missing {', '.join(missing)}",
                         hint="run recipes/seed-section9.yaml with --set out=DIR first")
    runs = {n: figures(folder / n) for n in STEPS}
    f = {n: r[0] for n, r in runs.items()}
    moves = {n: _move(folder / f"{n}.json") for n in MOVES}
    out: dict[str, float | None] = {
        "fig9_1.switch_ms": seed_switch_ms(f["fig9-1"]),
        "fig9_2.switch_ms": 1000 * f["fig9-2"].switch_s,
        "fig9_3.switch_ms": seed_switch_ms(f["fig9-3"]),
        "fig9_3.speed_rad_s": f["fig9-3"].steady_speed,
        "fig9_3.ripple": f["fig9-3"].steady_ripple,
        "fig9_5.drop_1a_ms": None,
        "fig9_5.slowing_20a_ms": None,
        "fig9_4.peak_ratio": abs(f["fig9-4-1a"].peak_speed) / abs(f["fig9-4-20a"].peak_speed)
        if f["fig9-4-20a"].peak_speed else None,
        "fig9_6.speed_rad_s": f["fig9-6"].steady_speed,
        "fig9_6.ripple": f["fig9-6"].steady_ripple,
        "fig9_8.speed_rad_s": f["fig9-8"].steady_speed,
        "fig9_8.speed_sd_rad_s": None if f["fig9-8"].steady_ripple is None or f["fig9-8"].steady_speed is None
        else f["fig9-8"].steady_ripple * abs(f["fig9-8"].steady_speed),
    }
    slow = slowing_at(runs["fig9-4-20a"])
    out["fig9_5.slowing_20a_ms"] = None if slow is None else 1000 * slow
    drop = falls_at(runs["fig9-4-1a"], slow)
    out["fig9_5.drop_1a_ms"] = None if drop is None else 1000 * drop
    for fig, name in (("fig9_10", "delta"), ("fig9_11", "sigma")):
        peak, end = _held(moves[f"{fig.replace('_', '-')}-naive"])
        out[f"{fig}.{name}_excursion_rad"] = peak
        out[f"{fig}.{name}_returned_counts"] = end
        for how in ("group", "feedback"):  # the tool's common start, and with its feedback
            other, _ = _held(moves[f"{fig.replace('_', '-')}-{how}"])
            out[f"{fig}.reduction_{how}"] = other / peak if peak > 0 else None
    return out


def check(numbers: Mapping[str, float | None], bands: list[Band]) -> list[tuple[Band, float | None, bool]]:
    """Each band with the number it bounds and whether it holds (a number the summary lacks fails)."""
    return [(b, numbers.get(b.key), b.holds(numbers.get(b.key))) for b in bands]


def bands_table(bands: list[Band]) -> str:
    """The Markdown table of the bands, as docs/section9.md shows it (a test keeps the two equal)."""
    lines = ["| figure | number | the seed | the tool | band | the seed's sentence | how it is read |",
             "|---|---|---|---|---|---|---|"]
    for b in bands:
        lines.append(f"| {b.figure} | `{b.key}` | {b.seed} | {b.tool} | {b.low:g} .. {b.high:g} {b.unit} | "
                     f"\"{b.quote}\" | {b.reading} |")
    return "\n".join(lines) + "\n"
