"""`sherpa identify`: who each drive says it is, what state it is in, and whether that fits.

Identity over SDO (0x1000, 0x1008, 0x1009, 0x100A, 0x1018 sub 1-4), state over the binary
interpreter (MO, UM, SR, MF, PX), buses read concurrently. Findings flag a drive whose
device name does not match the model the config names, and drives of one model whose
firmware or product code differ from the others of that model (a replaced drive with
other firmware is the classic cause of "same parameters, different behaviour").
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

from sherpa_cli.config.model import ArmConfig, JointConfig
from sherpa_cli.elmo.userprog import program_running, read_ps
from sherpa_cli.joints.diffpair import to_joints
from sherpa_cli.joints.units import counts_to_rad
from sherpa_cli.motion.calibration import counter_mismatch_text, encoder_on_drive
from sherpa_cli.ops.params_read import Progress, open_drive, per_bus

if TYPE_CHECKING:
    from sherpa_cli.bus.session import ArmSession

STATE_KEYS = ("MO", "UM", "SR", "MF", "PX")


@dataclass(frozen=True)
class JointPosition:
    """PX in joint units: a plain joint is its motor; a pair motor shows Σ (drive a) or Δ (drive b)."""

    joint: str
    counts: int
    rad: float
    formula: str | None = None  # how a pair joint follows from the two motors
    # an absolute-encoder joint whose counter does not mean its encoder (a power cycle): why, with both
    # numbers; the position is then not the joint's
    uncalibrated: str | None = None

    def as_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {"joint": self.joint, "counts": self.counts, "rad": self.rad, "formula": self.formula}
        if self.uncalibrated is not None:
            out["uncalibrated"] = self.uncalibrated
        return out

    def with_encoder(self, joint: JointConfig, py: int | None) -> JointPosition:
        """This position checked against the joint's encoder reading ``py`` (None: not read)."""
        if py is None or not encoder_on_drive(joint):
            return self
        return replace(self, uncalibrated=counter_mismatch_text(joint, self.counts, py))


@dataclass(frozen=True)
class DriveIdentity:
    drive: str
    bus: str
    node: int
    model: str | None  # what the config names
    identity: dict[str, Any] = field(default_factory=dict)
    identity_notes: dict[str, str] = field(default_factory=dict)
    state: dict[str, int | float] = field(default_factory=dict)
    joint: JointPosition | None = None
    error: str | None = None  # the drive could not be read (it is then also in IdentifyReport.failed)
    findings: tuple[str, ...] = ()
    encoder: int | None = None  # PY of a drive that reads its joint's absolute encoder

    def as_json(self) -> dict[str, Any]:
        from sherpa_cli.elmo import faults

        state: dict[str, Any] = dict(self.state)
        decoded = {}
        if isinstance(sr := self.state.get("SR"), int):
            decoded["SR"] = faults.describe_sr(sr)
        if isinstance(mf := self.state.get("MF"), int):
            decoded["MF"] = faults.describe_mf(mf)
        return {"drive": self.drive, "bus": self.bus, "node": self.node, "model": self.model,
                "identity": self.identity, "identity_unreadable": self.identity_notes, "state": state,
                "decoded": decoded, "joint_position": self.joint.as_json() if self.joint else None,
                "error": self.error, "findings": list(self.findings)}


@dataclass(frozen=True)
class IdentifyReport:
    drives: tuple[DriveIdentity, ...]
    errors: tuple[BaseException, ...] = ()  # one per drive that could not be read, in config order

    @property
    def findings(self) -> list[tuple[str, str]]:
        return [(d.drive, f) for d in self.drives for f in d.findings]

    def as_json(self) -> dict[str, Any]:
        return {"drives": [d.as_json() for d in self.drives],
                "findings": [{"drive": d, "finding": f} for d, f in self.findings],
                "failed": [d.drive for d in self.drives if d.error]}


def _read_one(session: ArmSession, drive: str, progress: Progress | None) -> DriveIdentity:
    d = session.cfg.drives[drive]
    client, identity, notes = open_drive(session, drive, progress)
    state: dict[str, int | float] = {}
    for key in STATE_KEYS:
        if progress:
            progress(drive, key)
        state[key] = client.get(key)
    ps = read_ps(client)  # user program (elmo/userprog.py); absent when the drive refuses PS
    if ps is not None:
        state["PS"] = ps
    joint = session.cfg.joint_of_drive(drive)
    encoder = int(client.get("PY")) if joint is not None and encoder_on_drive(joint) else None
    return DriveIdentity(drive, d.bus, d.node, d.model, identity, notes, state, encoder=encoder)


def identify(session: ArmSession, drives: Sequence[str], progress: Progress | None = None) -> IdentifyReport:
    cfg: ArmConfig = session.cfg
    outcomes = per_bus(session, drives, lambda name: _read_one(session, name, progress))
    read: list[DriveIdentity] = []
    errors: list[BaseException] = []
    for name, o in outcomes.items():
        if o.ok:
            read.append(o.value)
        else:
            d = cfg.drives[name]
            assert o.error is not None
            read.append(DriveIdentity(name, d.bus, d.node, d.model, error=str(o.error)))
            errors.append(o.error)
    positions = joint_positions(cfg, {r.drive: int(r.state["PX"]) for r in read if isinstance(r.state.get("PX"), int)})
    findings = find_mismatches(cfg, read)
    for r in read:
        if program_running(ps := r.state.get("PS")):  # type: ignore[arg-type]
            findings.setdefault(r.drive, []).append(
                f"a user program is running (PS={ps}): SV is refused and it can fight moving commands")
    out = tuple(DriveIdentity(r.drive, r.bus, r.node, r.model, r.identity, r.identity_notes, r.state,
                              _checked(cfg, positions.get(r.drive), r.drive, r.encoder), r.error,
                              tuple(findings.get(r.drive, ())), r.encoder)
                for r in read)
    return IdentifyReport(out, tuple(errors))


def _checked(cfg: ArmConfig, position: JointPosition | None, drive: str, py: int | None) -> JointPosition | None:
    joint = cfg.joint_of_drive(drive)
    return position if position is None or joint is None else position.with_encoder(joint, py)


def joint_positions(cfg: ArmConfig, px: dict[str, int]) -> dict[str, JointPosition]:
    """Joint positions from motor counts: Σ = m_a + m_b on drive a's row, Δ = m_a - m_b on drive b's."""
    out: dict[str, JointPosition] = {}
    for drive, counts in px.items():
        joint = cfg.joint_of_drive(drive)
        if joint is not None:
            out[drive] = JointPosition(joint.name, counts, counts_to_rad(counts, joint.cpr))
    for pair in cfg.pairs.values():
        if pair.drive_a in px and pair.drive_b in px:
            s, d = to_joints(px[pair.drive_a], px[pair.drive_b])
            sigma, delta = cfg.joints[pair.sigma], cfg.joints[pair.delta]
            out[pair.drive_a] = JointPosition(sigma.name, s, counts_to_rad(s, sigma.cpr),
                                              f"Σ = {pair.drive_a} + {pair.drive_b}")
            out[pair.drive_b] = JointPosition(delta.name, d, counts_to_rad(d, delta.cpr),
                                              f"Δ = {pair.drive_a} - {pair.drive_b}")
    return out


def row_joint(cfg: ArmConfig, drive: str) -> str | None:
    """The joint a drive's row stands for, as in :func:`joint_positions`, whether or not PX is known."""
    joint = cfg.joint_of_drive(drive)
    if joint is not None:
        return joint.name
    pair = cfg.pair_of_drive(drive)
    if pair is None:
        return None
    return pair.sigma if drive == pair.drive_a else pair.delta


def _norm(text: str) -> str:
    return "".join(c for c in text.lower() if c.isalnum())


def find_mismatches(cfg: ArmConfig, read: Sequence[DriveIdentity]) -> dict[str, list[str]]:
    """Per drive: device name vs the config's model; firmware / product code vs its model group."""
    out: dict[str, list[str]] = {}
    ok = [r for r in read if r.error is None]
    for r in ok:
        name = r.identity.get("device_name")
        if r.model and name is not None and _norm(name) != _norm(r.model):
            out.setdefault(r.drive, []).append(
                f"model: the drive reports '{name}', the config names {r.model}")
    groups: dict[str, list[DriveIdentity]] = {}
    for r in ok:
        groups.setdefault(r.model or "(no model in the config)", []).append(r)
    for model, members in groups.items():
        for key, what in (("software_version", "firmware"), ("product_code", "product code")):
            values = [m.identity.get(key) for m in members if m.identity.get(key) is not None]
            counts = Counter(values).most_common()
            if len(counts) < 2:
                continue
            majority = counts[0][0] if counts[0][1] > counts[1][1] else None
            for m in members:
                v = m.identity.get(key)
                if v is None or v == majority:
                    continue
                shown = f"0x{v:08X}" if isinstance(v, int) else f"'{v}'"
                if majority is not None:
                    usual = f"0x{majority:08X}" if isinstance(majority, int) else f"'{majority}'"
                    text = f"{what} {shown} differs from the other {model} drives ({usual})"
                else:
                    text = f"{what} {shown}: the {model} drives disagree, no {what} is in the majority"
                out.setdefault(m.drive, []).append(text)
    return out


# -- other device types (`devices:`, sherpa_cli/devices) -------------------------------------------

@dataclass(frozen=True)
class DeviceIdentity:
    device: str
    type: str
    bus: str
    node: int
    device_type: int | None = None  # 0x1000
    vendor_id: int | None = None  # 0x1018:1
    name: str | None = None  # 0x1008
    position: int | None = None  # CiA 406 0x6004 (encoders)
    joint: str | None = None  # the joint whose abs_encoder it is
    joint_position: int | None = None  # position + that joint's abs_encoder offset
    error: str | None = None

    def as_json(self) -> dict[str, Any]:
        return {"device": self.device, "type": self.type, "bus": self.bus, "node": self.node,
                "device_type": self.device_type, "vendor_id": self.vendor_id, "name": self.name,
                "position": self.position, "joint": self.joint, "joint_position": self.joint_position,
                "error": self.error}


def identify_devices(session: ArmSession, names: Sequence[str]) -> list[DeviceIdentity]:
    """Identity by SDO (0x1000, 0x1018:1, 0x1008) and, for an encoder, its position (0x6004)."""
    from sherpa_cli.bus.targets import DriveRef
    from sherpa_cli.devices import CanOpenEncoder, device_class
    from sherpa_cli.errors import SdoError

    cfg: ArmConfig = session.cfg
    out = []
    for name in names:
        dev = cfg.devices[name]
        sdo = session.sdo(DriveRef(dev.name, dev.bus, dev.node))
        joint = next((j for j in cfg.joints.values()
                      if j.abs_encoder is not None and cfg.device_by_source(j.abs_encoder.source) is dev), None)
        try:
            device_type = int.from_bytes(sdo.upload(0x1000, 0)[:4], "little")
            vendor = int.from_bytes(sdo.upload(0x1018, 1)[:4], "little")
            text = bytes(sdo.upload(0x1008, 0)).decode("latin-1").rstrip("\x00")
            impl = device_class(dev.type)(sdo)
            pos = impl.position() if isinstance(impl, CanOpenEncoder) else None
        except SdoError as exc:
            out.append(DeviceIdentity(dev.name, dev.type, dev.bus, dev.node, error=str(exc)))
            continue
        jpos = pos + joint.abs_encoder.offset if joint is not None and pos is not None else None  # type: ignore[union-attr]
        out.append(DeviceIdentity(dev.name, dev.type, dev.bus, dev.node, device_type, vendor, text, pos,
                                  joint.name if joint is not None else None, jpos))
    return out
