"""What a moving command's real run would refuse, judged in its dry run.

A dry run used to say "would move" and `--apply` then refused the joint as not homed. The dry run
now reads, without writing anything to the drive's settings, what the real run checks before it
arms anything: a drive in fault (MF, SR), a position goal outside the joint's normal range from
where the joint stands now, and a joint that is not calibrated (unless ``--uncalibrated``). It
only reads (NMT start, as `monitor` and `dump-params` do: the interpreter answers only in
Operational) and never raises for a refusal: it returns the reasons.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from sherpa_cli.bus.targets import DriveRef
from sherpa_cli.elmo.faults import fault_reason
from sherpa_cli.motion import calibration

if TYPE_CHECKING:
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.config.model import PairConfig
    from sherpa_cli.motion.axis import Axis
    from sherpa_cli.motion.request import MoveRequest
    from sherpa_cli.ops.diffdrive import PairTarget


def would_refuse(session: ArmSession, target: Axis, req: MoveRequest) -> list[str]:
    """The reasons the real run would refuse ``req`` (empty: it would go ahead)."""
    reasons: list[str] = []
    c = session.client(target.ref)
    c.nmt_start()
    mf, sr = int(c.get("MF")), int(c.get("SR"))
    fault = fault_reason(mf, sr)
    if fault:
        reasons.append(f"{c.label}: in fault: {fault}")
    joint = target.joint
    if joint is None or req.mode != "position":
        return reasons
    px = int(c.get("PX"))
    goal = req.goal(px)
    lo, hi = joint.normal_range
    if not lo <= goal <= hi:
        reasons.append(f"{joint.name}: target {goal} counts (from {px}) is outside the joint's normal range "
                       f"[{lo}, {hi}]")
    cal = calibration.read_calibration(session.cfg, joint, lambda name: c)
    if not cal.calibrated and not req.uncalibrated:
        reasons.append(f"{joint.name}: {cal.reason}: a position move needs a calibrated joint (home it first, "
                       "or --uncalibrated)")
    return reasons


def pair_would_refuse(session: ArmSession, pair: PairConfig, request: PairTarget) -> list[str]:
    """`diffdrive move`'s dry run: a motor in fault, and what :func:`ops.diffdrive.prepare` (positions,
    ranges, calibration; it writes nothing but NMT start) refuses."""
    from sherpa_cli.errors import SafetyError, UsageError
    from sherpa_cli.ops import diffdrive

    reasons: list[str] = []
    cfg = session.cfg
    for name in (pair.drive_a, pair.drive_b):
        d = cfg.drives[name]
        c = session.client(DriveRef(name, d.bus, d.node, d))
        c.nmt_start()
        fault = fault_reason(int(c.get("MF")), int(c.get("SR")))
        if fault:
            reasons.append(f"{c.label}: in fault: {fault}")
    try:
        plan, _ = diffdrive.prepare(session, pair, request)
        if request.source == "drive":
            from sherpa_cli.elmo.recorder import RecorderSettings

            diffdrive.plan_drive_recording(diffdrive.drive_record_length(plan), RecorderSettings())
    except (UsageError, SafetyError) as exc:
        reasons.append(str(exc))
    return reasons
