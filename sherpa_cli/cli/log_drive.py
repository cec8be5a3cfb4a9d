"""`sherpa log record --source drive`: the drives' own recorders (ops/drive_record.py, docs/log.md)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Literal, cast

from sherpa_cli.cli.context import AppState
from sherpa_cli.errors import UsageError


def record_from_drive(st: AppState, targets: Sequence[str] | None, duration: float, output: Sequence[Path], *,
                      source: str, trigger: str, poll: bool, live: bool) -> None:
    """Check the options, record, write the CSV only once every drive's upload is in."""
    from sherpa_cli.bus.targets import drive_refs
    from sherpa_cli.elmo.recorder import RecorderSettings, plan_recording
    from sherpa_cli.log.recording import write_csv
    from sherpa_cli.ops.drive_record import record_drives

    if source != "drive":
        raise UsageError(f"--source {source}: expected can or drive")
    if trigger not in ("now", "bg"):
        raise UsageError(f"--trigger {trigger}: expected now or bg")
    if poll or live:
        raise UsageError("--source drive records in the drives, not over the bus: --poll and --foxglove do not apply")
    paths = list(output)
    if len(paths) != 1 or paths[0].suffix.lower() != ".csv":
        raise UsageError("--source drive writes one CSV file: give one -o FILE.csv")
    if not paths[0].parent.is_dir():
        raise UsageError(f"{paths[0]}: the directory does not exist")
    plan_recording(duration, RecorderSettings())  # a time the recorder cannot hold: refused before the bus opens
    cfg = st.load_config()
    refs = drive_refs(cfg, targets, configured_only=True)
    with st.session(buses=list(dict.fromkeys(r.bus for r in refs))) as session:
        if trigger == "bg":
            st.out.info("armed: waiting for the next BG (start the move now)")
        result = record_drives(session, refs, duration, trigger=cast(Literal["now", "bg"], trigger))
    write_csv(result.recording, paths[0])
    rate = 1.0 / result.period_s
    if st.json_mode:
        st.out.json({"file": str(paths[0]), "rows": len(result.recording.times), "rate_hz": round(rate, 3),
                     "gap": result.plan.gap, "drives": [{"drive": n, "samples": c} for n, c in result.samples.items()]})
        return
    for name, count in result.samples.items():
        st.out.line(f"{name}: {count} samples at {rate:.1f} Hz (RG={result.plan.gap})")
    st.out.line(f"wrote {paths[0]} ({len(result.recording.times)} rows)")


