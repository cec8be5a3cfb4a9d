"""`sherpa config check|convert`: validate a configuration and show what it describes."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

from sherpa_cli.cli.context import state
from sherpa_cli.errors import ExitCode
from sherpa_cli.words import plural

if TYPE_CHECKING:
    from sherpa_cli.cli.output import Output

app = typer.Typer(no_args_is_help=True, help="Validate and convert arm configurations.")

FileArg = typer.Argument(None, metavar="[FILE]", help="Config file; default: the global --config.")


@app.command("check")
def check(ctx: typer.Context, file: Path | None = FileArg) -> None:
    """Validate a config and print its buses, drives, joints, pairs and warnings.

    Exit 0 when valid (warnings allowed), 1 when the current limits break the catalog
    ratings or a derived drive parameter set would be refused by program-limits, 2 when
    the file is invalid.
    """
    from sherpa_cli.config.summary import summarize
    from sherpa_cli.joints.limits import config_findings

    st = state(ctx)
    cfg = st.load_config(file)
    findings = config_findings(cfg)  # what program-limits would refuse, so a passing check means it will not
    summary = summarize(cfg, findings)
    if st.json_mode:
        st.out.json(summary)
    else:
        _render(st.out, summary)
    if any(f["level"] == "error" for f in summary["findings"]):
        raise typer.Exit(ExitCode.PROBLEM)


def _render(out: Output, s: dict[str, Any]) -> None:
    out.line(f"config {s['source']}: {s['name']} -- valid")
    out.line(f"  {plural(len(s['buses']), 'bus', 'buses')}, {plural(len(s['drives']), 'drive')}, "
             f"{plural(len(s['joints']), 'joint')}, {plural(len(s['pairs']), 'differential pair')}")
    out.line()
    out.table("Buses", ["bus", "interface", "channel", "bitrate", "send gap µs", "poll ms", "drives"],
              [[b["name"], b["interface"] or "(python-can config)", b["channel"] or "-", b["bitrate"] or "-",
                b["send_interval_us"], b["poll_interval_ms"], b["drives"]] for b in s["buses"]],
              right=(3, 4, 5, 6))
    out.table("Drives", ["drive", "bus:node", "model", "motor", "moves"],
              [[d["name"], f"{d['bus']}:{d['node']}", d["model"] or "?", d["motor"] or "-", d["moves"] or "-"]
               for d in s["drives"]], drop=(3, 2))
    out.table("Joints (counts)", ["joint", "moved by", "cpr", "full range", "normal range", "overshoot range"],
              [[j["name"], j["drive"] or f"{j['pair']} ({j['role']})", j["cpr"], _rng(j["full_range"]),
                _rng(j["normal_range"]), _rng(j["overshoot_range"])]
               for j in s["joints"]], right=(2,))
    switches = [[j["name"], sw["input"], sw["kind"], sw["side"] or "-", sw["position"], ", ".join(sw["drives"])]
                for j in s["joints"] for sw in j["switches"]]
    if switches:
        out.table("Switches", ["joint", "input", "kind", "side", "position", "wired to"], switches,
                  right=(1, 4))
    if s["pairs"]:
        out.table("Differential pairs", ["pair", "drive a (lower id)", "drive b", "Σ joint", "Δ joint"],
                  [[p["name"], p["drive_a"], p["drive_b"], p["sigma"], p["delta"]] for p in s["pairs"]])
    if s.get("ft_sensors"):
        out.table("F/T sensors", ["sensor", "bus:base", "frame", "counts/N", "counts/N·m", "force limit",
                                  "torque limit"],
                  [[f["name"], f"{f['bus']}:0x{f['base_id']:03X}", f["frame"], f"{f['counts_per_force']:g}",
                    f"{f['counts_per_torque']:g}", "-" if f["force_limit"] is None else f"{f['force_limit']:g} N",
                    "-" if f["torque_limit"] is None else f"{f['torque_limit']:g} N·m"] for f in s["ft_sensors"]],
                  right=(3, 4, 5, 6))
    if s["warnings"]:
        out.line("Warnings:")
        for w in s["warnings"]:
            out.line(f"  - {w}")
    for f in s["findings"]:
        out.line(f"{f['level']}: {f['message']}")


def _rng(r: list[int]) -> str:
    return f"{r[0]}..{r[1]}"


@app.command("convert")
def convert(ctx: typer.Context, file: Path = typer.Argument(..., metavar="FILE",
                                                            help="Config to convert (e.g. the seed's rosparam file)."),
            to: str = typer.Option("native", "--to", metavar="native|rosparam",
                                   help="native: sherpa's YAML (default); rosparam: the seed's Appendix D.1 format.")
            ) -> None:
    """Print a config in another format: native sherpa YAML, or the seed's rosparam format (Appendix D.1).

    \b
    Examples:
      sherpa config convert configs/seed-d1.yaml                      # D.1 -> native
      sherpa config convert --to rosparam configs/sherpa-arm.yaml     # native -> D.1 (what it cannot hold: warnings)
    """
    from sherpa_cli.config import dump_native
    from sherpa_cli.errors import UsageError

    st = state(ctx)
    if to not in ("native", "rosparam"):
        raise UsageError(f"--to {to}: expected native or rosparam")
    cfg = st.load_config(file)
    if to == "rosparam":
        from sherpa_cli.config.software import dump_rosparam

        text, lost = dump_rosparam(cfg)
        if st.json_mode:
            import yaml

            st.out.json(yaml.safe_load(text))
        else:
            st.out.raw(text)
        for w in lost:
            st.out.warn(w)
        return
    text = dump_native(cfg)
    if st.json_mode:
        import yaml

        st.out.json(yaml.safe_load(text))
    else:
        st.out.raw(text)
    for w in cfg.warnings:
        st.out.warn(w)
