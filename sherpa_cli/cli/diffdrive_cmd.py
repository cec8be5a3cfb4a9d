"""`sherpa diffdrive limits|convert`: the Σ/Δ maths of a differential pair, without a bus."""

from __future__ import annotations

from typing import Any, Optional

import typer

from sherpa_cli.cli.context import state
from sherpa_cli.errors import UsageError

app = typer.Typer(no_args_is_help=True, help="Differential pairs: Σ = m_a + m_b, Δ = m_a - m_b.")

PairArg = typer.Argument(..., metavar="PAIR", help="Pair name, or its Σ/Δ joint or one of its drives.")


@app.command("limits")
def limits(ctx: typer.Context, pair: str = PairArg) -> None:
    """Show a pair's Σ/Δ ranges and the motor ranges derived from them, with the rule used."""
    from sherpa_cli.joints.limits import explain_pair
    from sherpa_cli.ops.targets import pair_of

    st = state(ctx)
    cfg = st.load_config()
    ex = explain_pair(cfg, pair_of(cfg, pair))
    if st.json_mode:
        st.out.json(ex.as_dict())
        return
    out = st.out
    out.line(f"pair {ex.pair}: drive a = {ex.drive_a} (lower node id), drive b = {ex.drive_b}")
    out.line(f"  Σ joint {ex.sigma} = m_a + m_b,  Δ joint {ex.delta} = m_a - m_b  (counts)")
    out.table("Joint ranges (counts)", ["joint", "full range", "overshoot range"],
              [[f"Σ {ex.sigma}", _rng(ex.sigma_full), _rng(ex.sigma_overshoot)],
               [f"Δ {ex.delta}", _rng(ex.delta_full), _rng(ex.delta_overshoot)]])
    out.table("Motor ranges (counts)", ["drive", "VL[3] .. VH[3] (full)", "LL[3] .. HL[3] (overshoot)"],
              [[f"a {ex.drive_a}", _rng(ex.motor_a_full), _rng(ex.motor_a_overshoot)],
               [f"b {ex.drive_b}", _rng(ex.motor_b_full), _rng(ex.motor_b_overshoot)]])
    out.table("Motor speed and acceleration (both motors)", ["limit", "value"],
              [["VH[2] = -VL[2] (counts/s)", _opt(ex.motor_speed_limit)],
               ["HL[2] = -LL[2] (counts/s)", _opt(ex.motor_speed_trip)],
               ["AC (counts/s²)", _opt(ex.motor_accel)],
               ["DC (counts/s²)", _opt(ex.motor_decel)]], right=(1,))
    out.line("Rule:")
    for line in ex.rule.splitlines():
        out.line(f"  {line}")
    for note in ex.notes:
        out.line(f"note: {note}")


def _rng(r: tuple[int, int]) -> str:
    return f"{r[0]} .. {r[1]}"


def _opt(v: int | None) -> str:
    return "-" if v is None else str(v)


@app.command("convert")
def convert(
    ctx: typer.Context,
    pair: str = PairArg,
    sigma: Optional[float] = typer.Option(None, "--sigma", help="Σ joint position."),
    delta: Optional[float] = typer.Option(None, "--delta", help="Δ joint position."),
    motor_a: Optional[float] = typer.Option(None, "--motor-a", help="Motor a position (counts)."),
    motor_b: Optional[float] = typer.Option(None, "--motor-b", help="Motor b position (counts)."),
    unit: str = typer.Option("counts", "--unit", help="Unit of --sigma/--delta and of the output: counts or rad."),
) -> None:
    """Convert Σ/Δ joint positions to motor positions, or motor positions to Σ/Δ.

    Give either --sigma and --delta, or --motor-a and --motor-b. Joint positions may be in
    counts or radians (--unit rad, each joint's own cpr); motor positions are always counts.
    """
    from sherpa_cli.joints import diffpair, units
    from sherpa_cli.joints.limits import explain_pair
    from sherpa_cli.ops.targets import pair_of

    st = state(ctx)
    cfg = st.load_config()
    ex = explain_pair(cfg, pair_of(cfg, pair))
    if unit not in ("counts", "rad"):
        raise UsageError(f"--unit: '{unit}' is not a unit here; expected 'counts' or 'rad'")
    for option, value in (("--sigma", sigma), ("--delta", delta), ("--motor-a", motor_a), ("--motor-b", motor_b)):
        _finite(value, option, unit if option in ("--sigma", "--delta") else "counts")
    joint_given = sigma is not None or delta is not None
    motor_given = motor_a is not None or motor_b is not None
    if joint_given == motor_given:
        raise UsageError("diffdrive convert: give either --sigma and --delta, or --motor-a and --motor-b")
    s_cpr, d_cpr = cfg.joints[ex.sigma].cpr, cfg.joints[ex.delta].cpr
    if joint_given:
        if sigma is None or delta is None:
            raise UsageError("diffdrive convert: --sigma and --delta go together")
        if unit == "rad":
            s_exact, d_exact = units.rad_to_counts(sigma, s_cpr), units.rad_to_counts(delta, d_cpr)
            # radians rarely land on a Σ/Δ pair of equal parity; take the nearest reachable one
            s_counts, d_counts = diffpair.nearest_reachable(s_exact, d_exact)
            if (s_counts, d_counts) != (s_exact, d_exact):
                st.out.warn(f"Σ={s_exact}, Δ={d_exact} counts differ in parity (no whole motor positions); "
                            f"using the nearest reachable Σ={s_counts}, Δ={d_counts}")
        else:
            s_counts, d_counts = _whole(sigma, "--sigma"), _whole(delta, "--delta")
        m_a, m_b = diffpair.to_motors(s_counts, d_counts)
    else:
        if motor_a is None or motor_b is None:
            raise UsageError("diffdrive convert: --motor-a and --motor-b go together")
        m_a, m_b = _whole(motor_a, "--motor-a"), _whole(motor_b, "--motor-b")
        s_counts, d_counts = diffpair.to_joints(m_a, m_b)
    inside_joints = diffpair.inside_joint_limits(m_a, m_b, ex.sigma_full, ex.delta_full)
    box = diffpair.motor_box(ex.sigma_full, ex.delta_full)
    result: dict[str, Any] = {
        "pair": ex.pair,
        "sigma": {"joint": ex.sigma, "counts": s_counts, "rad": round(units.counts_to_rad(s_counts, s_cpr), 6)},
        "delta": {"joint": ex.delta, "counts": d_counts, "rad": round(units.counts_to_rad(d_counts, d_cpr), 6)},
        "motor_a": {"drive": ex.drive_a, "counts": m_a},
        "motor_b": {"drive": ex.drive_b, "counts": m_b},
        "inside_joint_full_ranges": inside_joints,
        "inside_motor_box": box.contains(m_a, m_b),
    }
    if st.json_mode:
        st.out.json(result)
        return
    st.out.table(None, ["", "name", "counts", "rad"], [
        ["Σ", ex.sigma, s_counts, f"{result['sigma']['rad']:.6f}"],
        ["Δ", ex.delta, d_counts, f"{result['delta']['rad']:.6f}"],
        ["motor a", ex.drive_a, m_a, ""],
        ["motor b", ex.drive_b, m_b, ""],
    ], right=(2, 3))
    if not inside_joints:
        st.out.warn(f"outside the full ranges of {ex.sigma} {_rng(ex.sigma_full)} / {ex.delta} {_rng(ex.delta_full)}")


POSITION_LIMIT = 2**31  # counts: a drive position is a 32-bit integer


def _finite(value: float | None, option: str, unit: str) -> None:
    """NaN, infinity and positions no drive can hold are refused before any arithmetic."""
    import math

    if value is None:
        return
    if not math.isfinite(value):
        raise UsageError(f"{option}: {value} is not a finite number")
    limit = POSITION_LIMIT if unit == "counts" else 2 * math.pi * POSITION_LIMIT  # cpr >= 1
    if abs(value) > limit:
        raise UsageError(f"{option}: {value:g} {unit} is outside the drive's 32-bit position range")


def _whole(value: float, option: str) -> int:
    if value != int(value):
        raise UsageError(f"{option}: {value} is not a whole number of counts (use --unit rad for radians)")
    return int(value)
