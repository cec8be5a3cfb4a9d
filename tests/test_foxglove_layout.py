"""docs/foxglove/sherpa.json is the bundled config's layout (log/foxglove_layout.py): one plot per
joint at its index in /joint_states, the status table, the log panel, every panel placed."""

from __future__ import annotations

import json

from conftest import ROOT

from sherpa_cli.config import load_config
from sherpa_cli.log.foxglove_layout import dumps

SHIPPED = ROOT / "docs/foxglove/sherpa.json"


def _leaves(tree):
    if isinstance(tree, str):
        return [tree]
    return _leaves(tree["first"]) + _leaves(tree["second"])


def test_the_shipped_layout_is_the_bundled_configs():
    cfg = load_config(ROOT / "configs/sherpa-arm.yaml")
    assert SHIPPED.read_text(encoding="utf-8") == dumps(cfg), (
        "regenerate: python -m sherpa_cli.log.foxglove_layout configs/sherpa-arm.yaml > docs/foxglove/sherpa.json")
    layout = json.loads(SHIPPED.read_text(encoding="utf-8"))
    panels = layout["configById"]
    assert sorted(_leaves(layout["layout"])) == sorted(panels)  # every configured panel is on the screen
    for i, joint in enumerate(cfg.joints):
        assert panels[f"Plot!{joint}"]["paths"][0]["value"] == f"/joint_states.position[{i}]"
    assert panels["DiagnosticSummary!drives"]["topicToRender"] == "/diagnostics"
    assert panels["RosOut!log"]["topicToRender"] == "/rosout"


def test_monitor_publishes_the_joints_in_the_layouts_order(cli, monkeypatch):
    """The index the layout plots is the index the live view publishes: every joint, config order."""
    from sherpa_cli.cli import robotics

    published = []

    class View:
        def joint_states(self, names, position, *a, **kw):
            published.append(list(names))

        def __getattr__(self, name):
            return lambda *a, **kw: None

    cfg = load_config(ROOT / "configs/sherpa-arm.yaml")
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.bus.targets import drive_refs
    from sherpa_cli.ops.monitor import Monitor
    from sherpa_cli.sim.arm import SimArm

    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as session, \
            Monitor(session, drive_refs(cfg, None)) as mon:
        mon.poll()
        robotics.MonitorFeed(View(), cfg).publish(mon.snapshot())
    assert published == [list(cfg.joints)]


def test_an_arm_with_an_ft_sensor_gets_a_wrench_plot():
    layout = json.loads(dumps(load_config(ROOT / "tests/data/ft-arm.yaml")))
    panels = layout["configById"]
    plot = panels["Plot!ft_wrist_ft"]
    assert [p["value"] for p in plot["paths"]] == [
        "/sherpa/wrench/wrist_ft.wrench.force.x", "/sherpa/wrench/wrist_ft.wrench.force.y",
        "/sherpa/wrench/wrist_ft.wrench.force.z", "/sherpa/wrench/wrist_ft.wrench.torque.x",
        "/sherpa/wrench/wrist_ft.wrench.torque.y", "/sherpa/wrench/wrist_ft.wrench.torque.z"]
    assert sorted(_leaves(layout["layout"])) == sorted(panels)  # on the screen too
