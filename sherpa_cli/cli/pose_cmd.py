"""`sherpa pose list|show|diff|save`: the config's named poses, how far the arm is from one, and
teaching one from where the arm stands."""

from __future__ import annotations

from typing import TYPE_CHECKING

import typer

from sherpa_cli.cli.context import state
from sherpa_cli.cli.options import name_list
from sherpa_cli.words import plural

if TYPE_CHECKING:
    from sherpa_cli.config.model import Pose

app = typer.Typer(help="Named poses: list, show, how far the arm is from one, teach one (save).",
                  no_args_is_help=True)

PoseName = typer.Argument(..., metavar="POSE", help="A pose of the config's poses: section.", show_default=False)


def _value(v: float | str) -> str:
    return v if isinstance(v, str) else f"{v:g}"


def _rad(v: float | None) -> str:
    return "?" if v is None else f"{round(v, 4) + 0.0:+.4f}"


@app.command("list")
def list_cmd(ctx: typer.Context) -> None:
    """The poses of the config: name, how many joints, where each is written."""
    st = state(ctx)
    cfg = st.load_config()
    if st.json_mode:
        st.out.json({"poses": [{"name": p.name, "joints": dict(p.values), "where": str(p.where)}
                               for p in cfg.poses.values()]})
        return
    if not cfg.poses:
        st.out.line("no poses in the config (teach one: sherpa pose save NAME)")
        return
    st.out.table(None, ["pose", "joints", "where"],
                 [[p.name, len(p.values), str(p.where)] for p in cfg.poses.values()], right=(1,))


@app.command("show")
def show(ctx: typer.Context, name: str = PoseName) -> None:
    """Each joint of a pose: as written, in rad and in counts."""
    from sherpa_cli.joints.units import counts_to_rad
    from sherpa_cli.ops.poses import pose_named

    st = state(ctx)
    cfg = st.load_config()
    pose: Pose = pose_named(cfg, name)
    rows = [(j, pose.values[j], counts_to_rad(c, cfg.joints[j].cpr), c) for j, c in pose.counts.items()]
    if st.json_mode:
        st.out.json({"pose": pose.name, "where": str(pose.where),
                     "joints": {j: {"written": w, "rad": round(r, 6), "counts": c} for j, w, r, c in rows}})
        return
    st.out.table(f"pose {pose.name} ({pose.where})", ["joint", "written", "rad", "counts"],
                 [[j, _value(w), _rad(r), c] for j, w, r, c in rows], right=(2, 3))


@app.command("diff")
def diff(ctx: typer.Context, name: str = PoseName) -> None:
    """How far each joint of a pose stands from it now (reads the drives; moves nothing)."""
    from sherpa_cli.api import Arm

    st = state(ctx)
    with st.session() as session:
        d = Arm(session).pose_diff(name)
    if st.json_mode:
        st.out.json({"pose": d.pose, "at_pose": d.at_pose, "joints": {
            j.joint: {"pose_rad": round(j.target, 6), "pose_counts": j.target_counts,
                      "now_rad": None if j.now is None else round(j.now, 6), "now_counts": j.now_counts,
                      "off_counts": j.off_counts} for j in d.joints}})
        return
    st.out.table(f"pose {d.pose}: where the arm stands", ["joint", "pose rad", "now rad", "off rad", "off counts"],
                 [[j.joint, _rad(j.target), _rad(j.now), _rad(j.off), "?" if j.off_counts is None else j.off_counts]
                  for j in d.joints], right=(1, 2, 3, 4))
    for j in d.joints:
        if j.now is None:
            st.out.warn(f"{j.joint}: position not known ({j.calibration})")
    if d.at_pose:
        st.out.line(f"at pose {d.pose}: every joint within 1 count")
    else:
        known = [j for j in d.joints if j.off_counts is not None]
        far = max(known, key=lambda j: abs(j.off_counts or 0), default=None)
        if far is not None and far.off_counts:
            st.out.line(f"not at pose {d.pose}: largest offset {far.joint} {_rad(far.off)} rad "
                        f"({far.off_counts:+d} counts); sherpa move {d.pose} --apply goes there")


@app.command("save")
def save(
    ctx: typer.Context,
    name: str = PoseName,
    joints: list[str] | None = typer.Option(None, "--joints", metavar="JOINTS",
                                            help="Only these joints (comma-separated or repeated); default: all."),
    replace: bool = typer.Option(False, "--replace", help="Overwrite a pose of that name."),
) -> None:
    """Teach a pose: where the (calibrated) joints stand now, written into the config file under
    poses:. The file's comments and layout stay; the new file is checked as a config before it
    replaces the old one. Moves nothing; only reads the drives.

    \b
    Examples:
      sherpa pose save dock
      sherpa pose save camera --joints wrist_1,wrist_2,wrist_3 --replace
    """
    from sherpa_cli.api import Arm

    st = state(ctx)
    with st.session() as session:
        saved = Arm(session).save_pose(name, name_list(joints), replace=replace)
    if st.json_mode:
        st.out.json({"pose": saved.name, "file": saved.path, "replaced": saved.replaced,
                     "joints": {j: {"rad": v, "counts": saved.counts[j]} for j, v in saved.values.items()}})
        return
    st.out.table(f"pose {saved.name}", ["joint", "rad", "counts"],
                 [[j, _rad(v), saved.counts[j]] for j, v in saved.values.items()], right=(1, 2))
    st.out.line(f"{'replaced' if saved.replaced else 'saved'} pose {saved.name} in {saved.path} "
                f"({plural(len(saved.values), 'joint')})")
