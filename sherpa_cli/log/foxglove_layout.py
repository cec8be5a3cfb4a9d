"""The Foxglove layout of docs/foxglove/sherpa.json: one plot per joint (position and velocity of
``/joint_states``), one plot per F/T sensor (``/sherpa/wrench/<device>``, in recordings), the drives'
status table (``/diagnostics``), the log panel (``/rosout``: EMCY)
and the bus load. It serves the live view and an MCAP recording alike (same topics and fields).

Plots address a joint by its index in ``/joint_states``: the config's joint order with every joint
watched (`sherpa monitor --foxglove`, `sherpa log record --foxglove` or `-o run.mcap` without
targets). The shipped file is the bundled config's; regenerate it with::

    python -m sherpa_cli.log.foxglove_layout configs/sherpa-arm.yaml > docs/foxglove/sherpa.json

Pure: a dict out, no I/O (but the ``__main__`` above).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

from sherpa_cli.config.model import ArmConfig
from sherpa_cli.log import ros_msgs

Tree = str | dict[str, Any]


def _plot(title: str, paths: list[tuple[str, str]]) -> dict[str, Any]:
    return {"paths": [{"value": value, "enabled": True, "timestampMethod": "receiveTime", "label": label}
                      for value, label in paths],
            "showXAxisLabels": True, "showYAxisLabels": True, "showLegend": True, "legendDisplay": "floating",
            "showPlotValuesInLegend": True, "isSynced": True, "xAxisVal": "timestamp",
            "foxglovePanelTitle": title}


def _split(items: list[Tree], direction: str) -> Tree:
    """A balanced mosaic tree of ``items`` side by side (row) or above each other (column)."""
    if len(items) == 1:
        return items[0]
    half = (len(items) + 1) // 2
    return {"first": _split(items[:half], direction), "second": _split(items[half:], direction),
            "direction": direction, "splitPercentage": round(100 * half / len(items), 2)}


def layout(cfg: ArmConfig, *, columns: int = 2) -> dict[str, Any]:
    config: dict[str, Any] = {}
    plots: list[Tree] = []
    for i, name in enumerate(cfg.joints):
        panel = f"Plot!{name}"
        config[panel] = _plot(name, [(f"{ros_msgs.TOPIC_JOINTS}.position[{i}]", f"{name} rad"),
                                     (f"{ros_msgs.TOPIC_JOINTS}.velocity[{i}]", f"{name} rad/s")])
        plots.append(panel)
    for dev in cfg.ft_sensors():  # recordings only: the live view does not publish the wrench
        panel = f"Plot!ft_{dev.name}"
        topic = ros_msgs.TOPIC_WRENCH + dev.name
        config[panel] = _plot(f"{dev.name} (N, N·m)", [
            *((f"{topic}.wrench.force.{a}", f"F{a} N") for a in "xyz"),
            *((f"{topic}.wrench.torque.{a}", f"T{a} N·m") for a in "xyz")])
        plots.append(panel)
    config["Plot!bus_load"] = _plot("bus load", [
        (f'{ros_msgs.TOPIC_BUS_LOAD}.buses[:]{{bus=="{bus}"}}.heard_load', f"{bus} heard") for bus in cfg.buses])
    config["DiagnosticSummary!drives"] = {"topicToRender": ros_msgs.TOPIC_STATUS, "minLevel": 0, "pinnedIds": [],
                                          "hardwareIdFilter": "", "sortByLevel": True,
                                          "foxglovePanelTitle": "drive status (MO, SR, MF)"}
    config["RosOut!log"] = {"topicToRender": ros_msgs.TOPIC_LOG, "searchTerms": [], "minLogLevel": 1,
                            "foxglovePanelTitle": "EMCY and notes"}
    rows = [_split(plots[r:r + columns], "row") for r in range(0, len(plots), columns)]
    side = _split(["DiagnosticSummary!drives", "RosOut!log", "Plot!bus_load"], "column")
    return {"configById": config, "globalVariables": {}, "userNodes": {}, "playbackConfig": {"speed": 1},
            "layout": {"first": _split(rows, "column"), "second": side, "direction": "row",
                       "splitPercentage": 65}}


def dumps(cfg: ArmConfig) -> str:
    return json.dumps(layout(cfg), indent=2, ensure_ascii=False) + "\n"


if __name__ == "__main__":  # pragma: no cover - the regeneration command of the module docstring
    from sherpa_cli.config import load_config

    sys.stdout.write(dumps(load_config(Path(sys.argv[1]))))
