"""`sherpa ft show|bias [SENSOR]`: the ATI force/torque sensor's readings, and zeroing it."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable
from typing import TYPE_CHECKING

import typer

from sherpa_cli.cli.context import state
from sherpa_cli.cli.options import Apply
from sherpa_cli.errors import UsageError

if TYPE_CHECKING:
    from sherpa_cli.config.model import DeviceConfig
    from sherpa_cli.devices.ft_sensor import Wrench

app = typer.Typer(help="The force/torque sensor: stream its readings, zero it (bias).", no_args_is_help=True)

# between samples; tests replace it so no test waits on wall time
sleep: Callable[[float], None] = time.sleep
MAX_RATE = 200.0  # Hz: ops/ft.py MAX_RATE_HZ (not imported here: `sherpa --help` stays fast)
HEADER = f"{'Fx':>8} {'Fy':>8} {'Fz':>8} N  {'Tx':>8} {'Ty':>8} {'Tz':>8} N·m  {'sample':>6}  status"

Sensor = typer.Argument(None, metavar="[SENSOR]", help="The ft_sensor device (default: the arm's only one).",
                        show_default=False)


def _n(value: float, digits: int) -> float:
    return round(value, digits) + 0.0  # never "-0.00": a sign that rounding left without a number


def row(w: Wrench) -> str:
    """One sample as a fixed-width line: forces in N (2 decimals), torques in N·m (3)."""
    return (f"{_n(w.fx, 2):8.2f} {_n(w.fy, 2):8.2f} {_n(w.fz, 2):8.2f}    {_n(w.tx, 3):8.3f} {_n(w.ty, 3):8.3f} "
            f"{_n(w.tz, 3):8.3f}      {w.sample:>6}  {w.status}")


def describe(dev: DeviceConfig) -> str:
    ft = dev.ft
    assert ft is not None
    limits = ", ".join(x for x in (f"|F| <= {ft.force_limit:g} N" if ft.force_limit else "",
                                   f"|T| <= {ft.torque_limit:g} N·m" if ft.torque_limit else "") if x) or "no limits"
    return (f"F/T sensor {dev.name}: {dev.bus} base 0x{ft.base_id:03X} (replies 0x{ft.base_id + 5:03X}, "
            f"0x{ft.base_id + 6:03X}), frame {ft.frame}, {limits}")


@app.command("show")
def show(
    ctx: typer.Context,
    sensor: str | None = Sensor,
    duration: float | None = typer.Option(None, "--for", metavar="S",
                                          help="Stop after S seconds' worth of samples (S x --rate); default: Ctrl-C."),
    rate: float = typer.Option(10.0, "--rate", metavar="HZ", help=f"Samples per second (at most {MAX_RATE:g})."),
) -> None:
    """Stream the sensor's readings: Fx Fy Fz in N, Tx Ty Tz in N·m, the sample number and the status
    word, one line per sample. Only reads (a request frame per sample); nothing is written.

    \b
    Examples:
      sherpa ft show --for 2
      sherpa ft show wrist_ft --rate 50
    """
    from sherpa_cli.api import Arm
    from sherpa_cli.devices.ft_sensor import sensor_named

    st = state(ctx)
    if not 0 < rate <= MAX_RATE:
        raise UsageError(f"--rate {rate}: expected samples per second > 0 and <= {MAX_RATE:g}")
    if duration is not None and not 0 < duration <= 86400:
        raise UsageError(f"--for {duration}: expected seconds > 0 and <= 86400")
    if st.json_mode and duration is None:  # the JSON is written at the end: an endless stream has none
        raise UsageError("--json needs --for: the samples are written as one document at the end",
                         hint="sherpa --json ft show --for 1")
    cfg = st.load_config()
    dev = sensor_named(cfg, sensor)
    count = None if duration is None else max(1, round(duration * rate))
    samples = []
    with st.session(buses=[dev.bus]) as session:
        if not st.json_mode:
            st.out.line(describe(dev))
            st.out.line(HEADER)
        with contextlib.suppress(KeyboardInterrupt):  # Ctrl-C is how an endless stream ends
            # the module's sleep is looked up at each wait (tests step it)
            for w in Arm(session).wrenches(dev.name, count=count, rate=rate, sleep=lambda t: sleep(t)):
                if st.json_mode:
                    samples.append({**{k: round(v, 4) for k, v in w.axes().items()}, "sample": w.sample,
                                    "status": w.status.raw})
                else:
                    st.out.line(row(w))
    if st.json_mode:
        st.out.json({"device": dev.name, "frame": dev.ft.frame if dev.ft else "", "samples": samples})


@app.command("bias")
def bias(ctx: typer.Context, sensor: str | None = Sensor, apply: Apply = False) -> None:
    """Zero the sensor at its present load (the bias command 0x04 to its base id). Without --apply a
    dry run: one reading, and the frame that would be sent.

    The bias holds until the sensor is powered off or biased again; with a payload on the wrist its
    weight is zeroed too, so bias with the wrist where the force limits should count from.

    \b
    Examples:
      sherpa ft bias
      sherpa ft bias wrist_ft --apply
    """
    from sherpa_cli.api import Arm
    from sherpa_cli.devices.ft_sensor import sensor_named

    st = state(ctx)
    cfg = st.load_config()
    dev = sensor_named(cfg, sensor)
    with st.session(buses=[dev.bus]) as session:
        result = Arm(session).ft_bias(dev.name, apply=apply)
    if st.json_mode:
        st.out.json(result.as_json())
        return
    st.out.line(describe(dev))
    st.out.line(HEADER)
    st.out.line(f"{row(result.before)}  (before)")
    if result.after is None:
        st.out.line(f"dry run: bias frame {result.frame} not sent; add --apply to zero the sensor at this load")
        return
    st.out.line(f"{row(result.after)}  (after bias {result.frame})")
