"""`sherpa identify [TARGET ...]`: identity, state and position of each drive, and what does not fit."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import typer

from sherpa_cli.cli.context import AppState, state
from sherpa_cli.cli.options import Targets
from sherpa_cli.cli.output import fmt_value
from sherpa_cli.words import plural

if TYPE_CHECKING:
    from sherpa_cli.ops.ft import SensorReading
    from sherpa_cli.ops.identify import DeviceIdentity, IdentifyReport


def identify(
    ctx: typer.Context,
    targets: Targets = None,
    verbose: bool = typer.Option(False, "--verbose", "-v", help="Each drive's identity and state in full "
                                 "(a table per drive) before the summary."),
) -> None:
    """Read who each drive is (SDO 0x1000, 0x1008, 0x1009, 0x100A, 0x1018) and its state (MO, UM, SR, MF, PX).

    Ends with one line per drive (device, firmware, motor, faults, joint position, check).
    Flags a drive whose device name does not match the model the config names, and drives
    whose firmware or product code differ from the other drives of the same model.
    Buses are read at the same time. Exit 1 when something is flagged, 3 when a drive
    does not answer (the others are still shown).

    \b
    Examples:
      sherpa identify
      sherpa identify --verbose elbow_1a
      sherpa identify shoulder_diff elbow_1a --json
    """
    from sherpa_cli.api import Arm
    from sherpa_cli.bus.targets import drive_names
    from sherpa_cli.errors import ExitCode
    from sherpa_cli.ops.ft import read_sensors
    from sherpa_cli.ops.identify import IdentifyReport, identify_devices

    st = state(ctx)
    cfg = st.load_config()
    # `devices:` (a CANopen encoder, ...) by name or BUS:NODE; the rest resolve as drives
    named = [d.name for d in cfg.devices.values()] if not targets else \
        [cfg.device_by_source(t).name for t in targets if cfg.device_by_source(t) is not None]  # type: ignore[union-attr]
    devices = [n for n in named if cfg.devices[n].canopen]
    sensors = [cfg.devices[n] for n in named if not cfg.devices[n].canopen]  # F/T sensors: a reading, no SDO
    rest = [t for t in targets or [] if cfg.device_by_source(t) is None]
    drives = drive_names(cfg, rest, elmo_only="identify") if rest or not targets else []
    buses = sorted({cfg.drives[d].bus for d in drives} | {cfg.devices[d].bus for d in devices}
                   | {d.bus for d in sensors})
    with st.session(buses=buses) as session:
        report = Arm(session).identify(drives) if drives else IdentifyReport(())  # only devices named
        found = identify_devices(session, devices) if devices else []
        readings = read_sensors(session, sensors) if sensors else []
    if st.json_mode and (found or readings):
        extra: dict[str, object] = {"devices": [d.as_json() for d in found]}
        if readings:
            extra["ft_sensors"] = [r.as_json() for r in readings]
        st.out.json({**report.as_json(), **extra})
    else:
        if drives or not (found or readings):
            _render(st, report, verbose=verbose or st.verbose)
        _render_devices(st, found)
        _render_sensors(st, readings)
    if (any(d.error for d in found) or any(r.wrench is None for r in readings)) and not report.errors:
        raise typer.Exit(int(ExitCode.PROBLEM))
    if report.errors:
        first = report.errors[0]
        if len(report.errors) > 1 and hasattr(first, "hint"):
            others = ", ".join(d.drive for d in report.drives if d.error)
            first.hint = f"drives that did not answer: {others}"
        raise first
    if report.findings:
        raise typer.Exit(int(ExitCode.PROBLEM))


def _render_devices(st: AppState, found: Sequence[DeviceIdentity]) -> None:
    if st.json_mode:
        return
    for d in found:
        title = f"{d.device} ({d.bus}:{d.node}) - {d.type}"
        if d.error:
            st.out.table(title, ["field", "value", "meaning"], [["error", "not read", d.error]])
            continue
        rows = [["device type", _hex(d.device_type), f"CiA {d.device_type & 0xFFFF}" if d.device_type else ""],
                ["vendor id", _hex(d.vendor_id), ""], ["device name", d.name or "-", "0x1008"]]
        if d.position is not None:
            meaning = f"{d.joint} = {d.joint_position} with its offset" if d.joint else "no joint uses it"
            rows.append(["position", str(d.position), f"0x6004; {meaning}"])
        st.out.table(title, ["field", "value", "meaning"], rows)


def _render_sensors(st: AppState, readings: Sequence[SensorReading]) -> None:
    """An F/T sensor has no identity objects: its protocol, ids and calibration, and one reading."""
    if st.json_mode:
        return
    cfg = st.load_config()
    for r in readings:
        ft = cfg.devices[r.device].ft
        assert ft is not None
        rows = [["protocol", "ATI Net F/T CAN", "short data: request 0x02, bias 0x04"],
                ["ids", f"0x{r.base_id:03X}", f"replies on 0x{r.base_id + 5:03X} and 0x{r.base_id + 6:03X}"],
                ["calibration", f"{ft.counts_per_force:g} / {ft.counts_per_torque:g}", "counts per N / per N·m (config)"]]
        w = r.wrench
        if w is None:
            rows.append(["reading", "no answer", r.problem or ""])
        else:
            rows.append(["force", " ".join(f"{round(v, 2) + 0.0:.2f}" for v in (w.fx, w.fy, w.fz)),
                         f"Fx Fy Fz N, |F| {w.force:.2f}"])  # + 0.0: never "-0.00"
            rows.append(["torque", " ".join(f"{round(v, 3) + 0.0:.3f}" for v in (w.tx, w.ty, w.tz)),
                         f"Tx Ty Tz N·m, |T| {w.torque:.3f}"])
            rows.append(["status", str(w.status), f"sample {w.sample}"])
        st.out.table(f"{r.device} ({r.bus}:0x{r.base_id:03X}) - ft_sensor", ["field", "value", "meaning"], rows)


def _hex(value: float | None, width: int = 8) -> str:
    # register values are integers; the state dict is typed int | float as the codec decodes
    return "-" if value is None else f"0x{int(value) & 0xFFFFFFFF:0{width}X}"


def _render(st: AppState, report: IdentifyReport, *, verbose: bool = False) -> None:
    if st.json_mode:
        st.out.json(report.as_json())
        return
    if verbose:
        _render_details(st, report)
    _render_summary(st, report)
    findings = report.findings
    failed = [d.drive for d in report.drives if d.error]
    read = len(report.drives) - len(failed)
    for drive, finding in findings:
        st.out.line(f"{drive}: {finding}")
    summary = f"{read} of {plural(len(report.drives), 'drive')} identified"
    summary += f", {plural(len(findings), 'finding')}" if findings else ", no mismatch in model or firmware"
    if failed:
        summary += f"; not answering: {', '.join(failed)}"
    if not verbose:
        summary += " (--verbose: each drive in full)"
    st.out.line(summary)


def _render_summary(st: AppState, report: IdentifyReport) -> None:
    """One line per drive: who it is, its motor and faults, where its joint is, and whether it fits."""
    from sherpa_cli.elmo import faults

    rows = []
    for d in report.drives:
        if d.error:
            rows.append([d.drive, f"{d.bus}:{d.node}", "-", "-", "-", "-", "-", "NO ANSWER"])
            continue
        s = d.state
        mo, um, sr, mf = (s.get(k) for k in ("MO", "UM", "SR", "MF"))
        motor = "-" if mo is None else ("on" if mo == 1 else "off")
        if um is not None:
            motor += f", UM={fmt_value(um)}"
        problems = len(faults.sr_problems(sr)) if isinstance(sr, int) else 0
        status = ("MF " + _hex(mf)) if isinstance(mf, int) and mf else ("SR: check" if problems else "ok")
        where = "-"
        if d.joint is not None:
            where = f"{d.joint.joint} {d.joint.rad:.4f} rad" if d.joint.uncalibrated is None else \
                f"{d.joint.joint} ? (not calibrated)"
        elif st.load_config().pair_of_drive(d.drive) is not None:
            where = "pair motor"
        check = plural(len(d.findings), "finding") if d.findings else "ok"
        rows.append([d.drive, f"{d.bus}:{d.node}", str(d.identity.get("device_name") or "-"),
                     str(d.identity.get("software_version") or "-"), motor, status, where, check])
    st.out.table(plural(len(rows), "drive"), ["drive", "address", "device", "firmware", "motor", "faults", "joint",
                                            "check"], rows, drop=(3, 2, 4, 6, 5), one_line=True)
    for d in report.drives:
        if d.joint is not None and d.joint.uncalibrated is not None:
            st.out.line(f"{d.drive}: {d.joint.joint} {d.joint.uncalibrated}")


def _render_details(st: AppState, report: IdentifyReport) -> None:
    from sherpa_cli.bus.canopen_names import VENDORS
    from sherpa_cli.elmo import faults
    from sherpa_cli.elmo.userprog import describe_ps

    for d in report.drives:
        title = f"{d.drive} ({d.bus}:{d.node})" + (f" - config model {d.model}" if d.model else "")
        if d.error:
            st.out.table(title, ["field", "value", "meaning"], [["error", "not read", d.error]])
            continue
        ident = d.identity
        notes = d.identity_notes

        def text(key: str, shown: str, meaning: str = "") -> list[str]:
            # called only within this iteration: the loop variables are the current drive's
            return [key.replace("_", " "), shown if ident.get(key) is not None else "-",  # noqa: B023
                    notes.get(key, meaning)]  # noqa: B023

        vendor = ident.get("vendor_id")
        rows = [
            text("device_name", str(ident.get("device_name"))),
            text("software_version", str(ident.get("software_version")), "0x100A, firmware"),
            text("hardware_version", str(ident.get("hardware_version")), "0x1009"),
            text("vendor_id", _hex(vendor), VENDORS.get(vendor, "") if vendor is not None else ""),
            text("product_code", _hex(ident.get("product_code"))),
            text("revision", _hex(ident.get("revision"))),
            text("serial", _hex(ident.get("serial"))),
            text("device_type", _hex(ident.get("device_type")), "0x1000"),
        ]
        s = d.state
        mo = s.get("MO")
        rows.append(["MO", fmt_value(mo), "motor on" if mo == 1 else "motor off"])
        um = s.get("UM")
        rows.append(["UM", fmt_value(um), faults.UNIT_MODES.get(int(um), "unknown unit mode") if um is not None else ""])
        sr = s.get("SR")
        rows.append(["SR", _hex(sr), "; ".join(faults.describe_sr(sr)) if isinstance(sr, int) else ""])
        mf = s.get("MF")
        rows.append(["MF", _hex(mf), "; ".join(faults.describe_mf(mf) or ["no motor failure"])
                     if isinstance(mf, int) else ""])
        if "PS" in s:
            rows.append(["PS", fmt_value(s["PS"]), describe_ps(int(s["PS"]))])
        else:
            rows.append(["PS", "-", describe_ps(None)])
        px = s.get("PX")
        where = ""
        pair = st.load_config().pair_of_drive(d.drive)
        if d.joint is None and pair is not None:
            where = f"motor of pair {pair.name}; name both drives to see {pair.sigma} and {pair.delta}"
        if d.joint is not None:
            where = f"{d.joint.joint} at {d.joint.counts} counts = {d.joint.rad:.4f} rad"
            if d.joint.formula:
                where += f" ({d.joint.formula})"
            if d.joint.uncalibrated:
                where = f"{d.joint.joint} {d.joint.uncalibrated}"
        rows.append(["PX", f"{fmt_value(px)} counts", where])
        st.out.table(title, ["field", "value", "meaning"], rows)
