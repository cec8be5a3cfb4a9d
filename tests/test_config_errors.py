"""Bad configs: each must raise ConfigError naming file, line, key path and what is wrong.

Every case edits a valid base config in one place. The edit must apply exactly once (so a
stale case fails instead of silently testing the base), and the expected line is found in
the edited text, so the cases keep working when the base grows.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pytest

from sherpa_cli.config import load_config_text
from sherpa_cli.errors import ConfigError, ExitCode

ROOT = Path(__file__).resolve().parent.parent

BASE = """\
name: test-arm
il_codes: {stop: 21, home: 5}
buses:
  can0: {interface: socketcan, channel: can0, bitrate: 1000000}
  can1: {interface: socketcan, channel: can1}
drives:
  elbow_a: {bus: can0, node: 10, model: whistle-10/60, motor: tq-robodrive-50x14}
  diff_a: {bus: can0, node: 20, model: whistle-20/60, motor: tq-robodrive-70x18}
  diff_b: {bus: can0, node: 21, model: whistle-20/60, motor: tq-robodrive-70x18}
  wrist_a: {bus: can1, node: 30, model: whistle-10/60}
joints:
  elbow:
    drive: elbow_a
    cpr: 3600
    range:
      min: -1000
      max: 1000
      margin: 30
      overshoot: 20
    velocity: {limit: 300, trip: 400}
    acceleration: {accel: 1000, decel: 1000}
    current: {continuous: 3.0, peak: 10.0, peak_time: 2}
    switches:
      - {input: 3, kind: stop, side: low}
      - {input: 4, kind: stop, side: high}
    calibration: {speed: -100, position: -1000}
  wrist:
    drive: wrist_a
    cpr: 2000
    range: {min: -500, max: 500}
    current: {continuous: 1.0, peak: 3.0, peak_time: 1}
    abs_encoder: {source: "drive:PY", offset: 0}
pairs:
  shoulder:
    drives: [diff_b, diff_a]
    current: {continuous: 6.0, peak: 20.0, peak_time: 2}
    sigma:
      name: pitch
      cpr: 6000
      range: {min: -1500, max: 1500, margin: 60, overshoot: 30}
      switches:
        - {input: 1, kind: stop, side: low}
        - {input: 2, kind: stop, side: high}
    delta:
      name: roll
      cpr: 6000
      range: {min: -1500, max: 1500, margin: 60, overshoot: 30}
      switches:
        - {input: 3, kind: stop, side: low}
        - {input: 4, kind: stop, side: high}
poses:
  rest:
    elbow: 0.1
    pitch: 10deg
"""

ROSPARAM_BASE = (ROOT / "configs/seed-d1.yaml").read_text(encoding="utf-8")


@dataclass(frozen=True)
class Bad:
    id: str
    old: str  # must occur exactly once in the base
    new: str
    line_of: str  # the expected line is the first line of the edited text containing this
    path: str  # the key path the error must name
    phrase: str  # what is wrong, as the message must say it
    base: str = "native"


NATIVE = [
    # --- protocol settings
    Bad("protocol-negative-retries", "il_codes: {stop: 21, home: 5}\n",
        "il_codes: {stop: 21, home: 5}\nprotocol: {retries: -1}\n", "protocol:", "protocol.retries",
        "retries -1 is negative"),
    Bad("protocol-zero-timeout", "il_codes: {stop: 21, home: 5}\n",
        "il_codes: {stop: 21, home: 5}\nprotocol: {reply_timeout: 0}\n", "protocol:", "protocol.reply_timeout",
        "must be > 0"),
    Bad("protocol-huge-sdo-timeout", "il_codes: {stop: 21, home: 5}\n",
        "il_codes: {stop: 21, home: 5}\nprotocol: {sdo_timeout: 600}\n", "protocol:", "protocol.sdo_timeout",
        "must be > 0 and <= 60"),
    Bad("motion-listen-shorter-than-the-consumer-time", "il_codes: {stop: 21, home: 5}\n",
        "il_codes: {stop: 21, home: 5}\nmotion: {host_id_listen_ms: 100}\n", "motion:", "motion.host_id_listen_ms",
        "could take the id of a command killed a moment ago"),
    Bad("protocol-echo-not-bool", "il_codes: {stop: 21, home: 5}\n",
        "il_codes: {stop: 21, home: 5}\nprotocol: {set_echo: 1}\n", "protocol:", "protocol.set_echo",
        "expected true or false"),
    Bad("protocol-unknown-key", "il_codes: {stop: 21, home: 5}\n",
        "il_codes: {stop: 21, home: 5}\nprotocol: {set_ecko: false}\n", "protocol:", "protocol.set_ecko",
        "did you mean 'set_echo'?"),
    # --- YAML syntax
    Bad("yaml-mapping-in-value", "    drive: wrist_a\n", "    drive: wrist_a: x\n", "drive: wrist_a: x",
        "joints.wrist", "YAML syntax error: mapping values are not allowed here"),
    Bad("yaml-unclosed-flow", "    cpr: 2000\n", "    cpr: [2000\n", "range: {min: -500",
        "joints.wrist.cpr[1]", "YAML syntax error: expected ',' or ']'"),
    Bad("yaml-bad-indent", "    cpr: 2000\n", "   cpr: 2000\n", "   cpr: 2000", "joints",
        "YAML syntax error: expected <block end>"),
    Bad("yaml-duplicate-key", "    cpr: 2000\n", "    cpr: 2000\n    cpr: 2001\n", "cpr: 2001", "joints.wrist.cpr",
        "duplicate key 'cpr' (first given at line 29)"),
    # --- unknown keys, with suggestions
    Bad("unknown-range-key-seed-spelling", "      min: -1000\n", "      pos_mn: -1000\n", "pos_mn",
        "joints.elbow.range.pos_mn", "unknown key 'pos_mn' in joints.elbow.range; did you mean 'min'?"),
    Bad("unknown-range-key-typo", "      margin: 30\n", "      margn: 30\n", "margn",
        "joints.elbow.range.margn", "unknown key 'margn' in joints.elbow.range; did you mean 'margin'?"),
    Bad("unknown-top-key", "pairs:\n", "pair:\n", "pair:", "pair", "unknown key 'pair' in the top level; did you "
        "mean 'pairs'?"),
    Bad("unknown-drive-key", "node: 30, model: whistle-10/60}", "node: 30, modle: whistle-10/60}", "wrist_a:",
        "drives.wrist_a.modle", "unknown key 'modle' in drives.wrist_a; did you mean 'model'?"),
    Bad("unknown-bus-key", "bitrate: 1000000}", "bitrat: 1000000}", "bitrat", "buses.can0.bitrat",
        "did you mean 'bitrate'?"),
    Bad("unknown-switch-key", "\n      - {input: 3, kind", "\n      - {inpt: 3, kind", "inpt",
        "joints.elbow.switches[0].inpt", "unknown key 'inpt' in joints.elbow.switches[0]; did you mean 'input'?"),
    Bad("unknown-joint-key", "    abs_encoder:", "    abs_encodr:", "abs_encodr", "joints.wrist.abs_encodr",
        "did you mean 'abs_encoder'?"),
    Bad("current-on-pair-joint", "      name: roll\n", "      name: roll\n      current: {continuous: 1.0}\n",
        "current: {continuous: 1.0}", "pairs.shoulder.delta.current", "unknown key 'current' in pairs.shoulder.delta"),
    # --- wrong types
    Bad("int-given-string", "    cpr: 3600\n", "    cpr: many\n", "cpr: many", "joints.elbow.cpr",
        "expected an integer, got the string 'many'"),
    Bad("int-given-bool", "node: 30,", "node: true,", "wrist_a:", "drives.wrist_a.node",
        "expected an integer, got the boolean true"),
    Bad("int-given-float", "    cpr: 2000\n", "    cpr: 2000.5\n", "cpr: 2000.5", "joints.wrist.cpr",
        "expected an integer, got the number 2000.5"),
    Bad("int-given-quoted", "      max: 1000\n", "      max: '1000'\n", "max: '1000'", "joints.elbow.range.max",
        "expected an integer, got the string '1000'"),
    Bad("number-given-string", "{continuous: 3.0,", "{continuous: lots,", "continuous: lots",
        "joints.elbow.current.continuous", "expected a number, got the string 'lots'"),
    Bad("number-given-bool", "peak: 3.0,", "peak: yes,", "peak: yes", "joints.wrist.current.peak",
        "expected a number, got the boolean true"),
    Bad("range-given-list", "range: {min: -500, max: 500}", "range: [-500, 500]", "range: [-500", "joints.wrist.range",
        "expected a mapping {min, max, margin, overshoot}, got a list"),
    Bad("switches-given-mapping", "    abs_encoder: {source: \"drive:PY\", offset: 0}\n",
        "    switches: {input: 1}\n", "switches: {input: 1}", "joints.wrist.switches", "expected a list of switches"),
    Bad("bus-given-string", "bus: can1, node: 30", "bus: [can1], node: 30", "wrist_a:", "drives.wrist_a.bus",
        "expected a string, got a list"),
    Bad("options-not-mapping", "channel: can1}", "channel: can1, options: 5}", "can1: {", "buses.can1.options",
        "expected a mapping of keyword arguments"),
    # --- missing keys
    Bad("missing-cpr", "    cpr: 2000\n", "", "  wrist:", "joints.wrist.cpr", "missing required key 'cpr' in "
        "joints.wrist"),
    Bad("missing-joint-drive", "    drive: wrist_a\n", "", "  wrist:", "joints.wrist.drive",
        "missing required key 'drive' in joints.wrist"),
    Bad("missing-range-max", "range: {min: -500, max: 500}", "range: {min: -500}", "range: {min: -500}",
        "joints.wrist.range.max", "missing required key 'max' in joints.wrist.range"),
    Bad("missing-node", "wrist_a: {bus: can1, node: 30,", "wrist_a: {bus: can1,", "wrist_a:", "drives.wrist_a.node",
        "missing required key 'node' in drives.wrist_a"),
    Bad("missing-peak-time", "peak: 3.0, peak_time: 1}", "peak: 3.0}", "peak: 3.0}",
        "joints.wrist.current.peak_time", "missing required key 'peak_time'"),
    Bad("missing-switch-kind", "\n      - {input: 3, kind: stop, side: low}", "\n      - {input: 3, side: low}",
        "{input: 3, side: low}", "joints.elbow.switches[0].kind", "missing required key 'kind'"),
    Bad("missing-sigma-name", "      name: pitch\n", "", "    sigma:", "pairs.shoulder.sigma.name",
        "missing required key 'name' in pairs.shoulder.sigma"),
    Bad("null-required-value", "    drive: wrist_a\n", "    drive:\n", "    drive:\n", "joints.wrist.drive",
        "'drive' needs a value"),
    # --- drives and buses
    Bad("node-zero", "node: 30,", "node: 0,", "wrist_a:", "drives.wrist_a.node",
        "node id 0 of drive 'wrist_a' is not a valid CAN node id; expected 1..127"),
    Bad("node-128", "node: 30,", "node: 128,", "wrist_a:", "drives.wrist_a.node", "expected 1..127"),
    Bad("duplicate-node", "wrist_a: {bus: can1, node: 30,", "wrist_a: {bus: can0, node: 10,", "wrist_a:",
        "drives.wrist_a.node", "drives 'elbow_a' (line 7) and 'wrist_a' (line 10) both use node id 10 on bus 'can0'"),
    Bad("undefined-bus", "bus: can1, node: 30", "bus: can3, node: 30", "wrist_a:", "drives.wrist_a.bus",
        "drive 'wrist_a' is on bus 'can3', which is not defined; did you mean 'can1'?"),
    Bad("unknown-model", "node: 30, model: whistle-10/60}", "node: 30, model: whistle-10/06}", "wrist_a:",
        "drives.wrist_a.model", "unknown drive model 'whistle-10/06'; did you mean 'whistle-10/60'?"),
    Bad("unknown-motor", "motor: tq-robodrive-50x14}", "motor: maxon-ec45}", "elbow_a:", "drives.elbow_a.motor",
        "unknown motor 'maxon-ec45'"),
    Bad("bitrate-zero", "bitrate: 1000000}", "bitrate: 0}", "can0: {", "buses.can0.bitrate",
        "bitrate 0 must be positive"),
    Bad("poll-interval-zero", "channel: can1}", "channel: can1, poll_interval_ms: 0}", "can1: {",
        "buses.can1.poll_interval_ms", "poll_interval_ms 0 must be at least 1 ms"),
    Bad("bad-drive-name", "  wrist_a: {", "  'wrist a': {", "wrist a", "drives.wrist a", "invalid drive name 'wrist a'"),
    # --- ranges
    Bad("min-above-max", "range: {min: -500, max: 500}", "range: {min: 500, max: -500}", "range: {min: 500",
        "joints.wrist.range.max", "range max -500 must be above range min 500"),
    Bad("min-equals-max", "range: {min: -500, max: 500}", "range: {min: 500, max: 500}", "range: {min: 500",
        "joints.wrist.range.max", "range max 500 must be above range min 500"),
    Bad("negative-margin", "      margin: 30\n", "      margin: -5\n", "margin: -5", "joints.elbow.range.margin",
        "margin -5 is negative"),
    Bad("negative-overshoot", "      overshoot: 20\n", "      overshoot: -1\n", "overshoot: -1",
        "joints.elbow.range.overshoot", "overshoot -1 is negative"),
    Bad("margin-leaves-no-normal-range", "      margin: 30\n", "      margin: 1000\n", "margin: 1000",
        "joints.elbow.range.margin", "margin 1000 leaves no normal range: 2*margin must be less than max-min = 2000"),
    Bad("cpr-zero", "    cpr: 3600\n", "    cpr: 0\n", "cpr: 0", "joints.elbow.cpr", "cpr 0 must be positive"),
    Bad("cpr-negative-sigma", "name: pitch\n      cpr: 6000", "name: pitch\n      cpr: -6000", "cpr: -6000",
        "pairs.shoulder.sigma.cpr", "cpr -6000 must be positive"),
    # --- velocity, acceleration, current, calibration
    Bad("trip-equals-limit", "{limit: 300, trip: 400}", "{limit: 300, trip: 300}", "velocity:",
        "joints.elbow.velocity.trip", "velocity trip 300 must be above the velocity limit 300"),
    Bad("trip-below-limit", "{limit: 300, trip: 400}", "{limit: 300, trip: 200}", "velocity:",
        "joints.elbow.velocity.trip", "velocity trip 200 must be above the velocity limit 300"),
    Bad("accel-zero", "{accel: 1000,", "{accel: 0,", "acceleration:", "joints.elbow.acceleration.accel",
        "acceleration accel 0 must be positive"),
    Bad("peak-below-continuous", "{continuous: 6.0, peak: 20.0", "{continuous: 6.0, peak: 5.0", "peak: 5.0",
        "pairs.shoulder.current.peak", "peak current 5.0 A is below the continuous current 6.0 A"),
    Bad("negative-current", "{continuous: 1.0,", "{continuous: -1.0,", "continuous: -1.0",
        "joints.wrist.current.continuous", "current continuous must be positive, got -1.0"),
    Bad("calibration-speed-zero", "calibration: {speed: -100", "calibration: {speed: 0", "calibration:",
        "joints.elbow.calibration.speed", "calibration speed 0 would never reach the switch"),
    Bad("calibration-position-outside", "position: -1000}", "position: -1100}", "calibration:",
        "joints.elbow.calibration.position", "calibration position -1100 is outside the overshoot range -1020..1020"),
    Bad("abs-encoder-no-source", "{source: \"drive:PY\", offset: 0}", "{offset: 0}", "abs_encoder:",
        "joints.wrist.abs_encoder.source", "missing required key 'source'"),
    # --- joints, pairs and who uses which drive
    Bad("joint-undefined-drive", "    drive: wrist_a\n", "    drive: wrist_x\n", "drive: wrist_x", "joints.wrist.drive",
        "joint 'wrist' uses drive 'wrist_x', which is not defined; did you mean 'wrist_a'?"),
    Bad("drive-used-by-two-joints", "    drive: wrist_a\n", "    drive: elbow_a\n", "drive: elbow_a\n    cpr: 2000",
        "joints.wrist.drive", "drive 'elbow_a' is used by both joint 'elbow' (line 13) and joint 'wrist'"),
    Bad("drive-used-by-joint-and-pair", "    drive: wrist_a\n", "    drive: diff_a\n", "drives: [diff_b, diff_a]",
        "pairs.shoulder.drives[1]", "drive 'diff_a' is used by both joint 'wrist' (line 28) and pair 'shoulder'"),
    Bad("pair-on-two-buses", "diff_b: {bus: can0,", "diff_b: {bus: can1,", "drives: [diff_b", "pairs.shoulder.drives",
        "pair 'shoulder' drives 'diff_a' (bus can0) and 'diff_b' (bus can1) are on different buses"),
    Bad("pair-undefined-drive", "drives: [diff_b, diff_a]", "drives: [diff_b, diff_c]", "drives: [diff_b",
        "pairs.shoulder.drives[1]", "pair 'shoulder' uses drive 'diff_c', which is not defined"),
    Bad("pair-three-drives", "drives: [diff_b, diff_a]", "drives: [diff_b, diff_a, wrist_a]", "drives: [diff_b",
        "pairs.shoulder.drives", "a differential pair needs exactly 2 drives, got 3"),
    Bad("pair-same-drive-twice", "drives: [diff_b, diff_a]", "drives: [diff_a, diff_a]", "drives: [diff_a",
        "pairs.shoulder.drives", "pair 'shoulder' names drive 'diff_a' twice"),
    Bad("joint-named-like-other-drive", "  wrist:\n", "  elbow_a:\n", "  elbow_a:\n    drive",
        "joints.elbow_a", "joint 'elbow_a' has the same name as drive 'elbow_a' (line 7) but is not moved by it"),
    Bad("pair-named-like-joint", "  shoulder:\n", "  elbow:\n", "  elbow:\n    drives", "pairs.elbow",
        "pair 'elbow' has the same name as joint 'elbow' (line 12)"),
    Bad("duplicate-joint-name", "      name: pitch\n", "      name: elbow\n", "name: elbow",
        "pairs.shoulder.sigma.name", "joint name 'elbow' is already used (line 12)"),
    # --- switches
    Bad("switch-input-above-model", "\n      - {input: 3, kind", "\n      - {input: 7, kind", "{input: 7",
        "joints.elbow.switches[0].input",
        "switch input 7 is outside the inputs of drive 'elbow_a' (model whistle-10/60 has inputs 1..6)"),
    Bad("switch-input-zero", "\n      - {input: 3, kind", "\n      - {input: 0, kind", "{input: 0",
        "joints.elbow.switches[0].input", "switch input 0 is not a digital input number"),
    Bad("switch-input-catalog-override", "pairs:\n", "catalog: {drives: {whistle-20/60: {inputs: 3}}}\npairs:\n",
        "        - {input: 4", "pairs.shoulder.delta.switches[1].input",
        "switch input 4 is outside the inputs of drive 'diff_a' (model whistle-20/60 has inputs 1..3)"),
    Bad("stop-switch-outside-overshoot", "\n      - {input: 3, kind: stop, side: low}",
        "\n      - {input: 3, kind: stop, side: low, position: -1100}", "position: -1100",
        "joints.elbow.switches[0].position", "stop switch at -1100 is outside the overshoot range -1020..1020"),
    Bad("home-switch-outside-full-range", "\n      - {input: 4, kind: stop, side: high}",
        "\n      - {input: 5, kind: home, position: 1010}", "position: 1010", "joints.elbow.switches[1].position",
        "home switch at 1010 is outside the full range -1000..1000"),
    Bad("switch-unknown-kind", "{input: 3, kind: stop, side: low}\n      - {input: 4",
        "{input: 3, kind: stpo, side: low}\n      - {input: 4", "kind: stpo", "joints.elbow.switches[0].kind",
        "unknown switch kind 'stpo'; expected 'stop' or 'home'; did you mean 'stop'?"),
    Bad("stop-switch-without-side", "\n      - {input: 3, kind: stop, side: low}", "\n      - {input: 3, kind: stop}",
        "{input: 3, kind: stop}", "joints.elbow.switches[0].side", "a stop switch needs 'side: low' or 'side: high'"),
    Bad("switch-bad-side", "\n      - {input: 3, kind: stop, side: low}",
        "\n      - {input: 3, kind: stop, side: middle}", "side: middle", "joints.elbow.switches[0].side",
        "unknown switch side 'middle'; expected 'low' or 'high'"),
    Bad("home-switch-with-side", "\n      - {input: 4, kind: stop, side: high}",
        "\n      - {input: 4, kind: home, side: high, position: 0}", "kind: home", "joints.elbow.switches[1].side",
        "'side' is only for stop switches"),
    Bad("home-switch-without-position", "\n      - {input: 4, kind: stop, side: high}",
        "\n      - {input: 4, kind: home}", "kind: home", "joints.elbow.switches[1].position",
        "missing required key 'position' of a home switch"),
    Bad("two-switches-one-input", "\n      - {input: 4, kind: stop, side: high}",
        "\n      - {input: 3, kind: stop, side: high}", "{input: 3, kind: stop, side: high}",
        "joints.elbow.switches[1].input", "input 3 of drive 'elbow_a' is already used by a switch of joint 'elbow' "
        "(line 24)"),
    Bad("sigma-delta-share-an-input", "        - {input: 3, kind: stop, side: low}",
        "        - {input: 1, kind: stop, side: low}", "        - {input: 1, kind: stop, side: low}\n        - {input: 4",
        "pairs.shoulder.delta.switches[0].input", "input 1 of drive 'diff_a' is already used by a switch of joint "
        "'pitch'"),
    Bad("switch-wired-to-foreign-drive", "\n      - {input: 3, kind: stop, side: low}",
        "\n      - {input: 3, kind: stop, side: low, drives: [wrist_a]}", "drives: [wrist_a]",
        "joints.elbow.switches[0].drives", "switch is wired to drive 'wrist_a', which does not move joint 'elbow'"),
    # --- il codes and catalog
    Bad("il-codes-equal", "il_codes: {stop: 21, home: 5}", "il_codes: {stop: 21, home: 21}", "il_codes:",
        "il_codes.home", "il_codes.stop and il_codes.home are both 21"),
    Bad("il-codes-typo", "il_codes: {stop: 21, home: 5}", "il_codes: {stop: 21, hom: 5}", "il_codes:",
        "il_codes.hom", "did you mean 'home'?"),
    Bad("catalog-new-model-incomplete", "pairs:\n", "catalog:\n  drives:\n    whistle-7/60: {nominal_voltage: 50}\n"
        "pairs:\n", "whistle-7/60", "catalog.drives.whistle-7/60.max_voltage", "missing required key 'max_voltage'"),
    Bad("catalog-peak-fraction", "pairs:\n", "catalog: {peak_fraction: 1.5}\npairs:\n", "peak_fraction",
        "catalog.peak_fraction", "peak_fraction 1.5 must be above 0 and at most 1"),
    Bad("catalog-motor-peak-below-cont", "pairs:\n", "catalog:\n  motors:\n    tq-robodrive-50x14: {current_peak: 1}\n"
        "pairs:\n", "current_peak: 1", "catalog.motors.tq-robodrive-50x14.current_peak",
        "current_peak 1.0 of motor 'tq-robodrive-50x14' is below its current_cont 3.5"),
]

NATIVE += [
    # --- poses (docs/move.md)
    Bad("pose-unknown-joint", "    elbow: 0.1\n", "    elbw: 0.1\n", "elbw: 0.1", "poses.rest.elbw",
        "joint 'elbw' is not in the config; did you mean 'elbow'?"),
    Bad("pose-outside-the-normal-range", "    elbow: 0.1\n", "    elbow: 3\n", "elbow: 3", "poses.rest.elbow",
        "is 1719 counts, outside the joint's normal range [-970, 970]"),
    Bad("pose-bad-unit", "pitch: 10deg", "pitch: 10furlongs", "pitch: 10furlongs", "poses.rest.pitch",
        "unknown unit 'furlongs'"),
    Bad("pose-a-list", "    pitch: 10deg\n", "    pitch: [1, 2]\n", "pitch: [1, 2]", "poses.rest.pitch",
        "expected a position"),
    Bad("pose-nan", "    elbow: 0.1\n", "    elbow: .nan\n", "elbow: .nan", "poses.rest.elbow",
        "finite"),
]

ROSPARAM = [
    Bad("ros-diffdrive-missing-partner", "diffdrive: 2,", "diffdrive: 5,", "diffdrive: 5",
        "ros_can_interface.nodes.1.diffdrive", "node '1' has diffdrive: 5, but there is no node '5' in nodes",
        base="rosparam"),
    Bad("ros-diffdrive-not-reciprocal", "diffdrive: 1,", "diffdrive: 3,", "diffdrive: 2",
        "ros_can_interface.nodes.1.diffdrive", "nodes '1' and '2' are not a pair: node '1' has diffdrive: 2 but "
        "node '2' (line 17) has diffdrive: 3", base="rosparam"),
    Bad("ros-diffdrive-self", "diffdrive: 2,", "diffdrive: 1,", "diffdrive: 1, pos_min_dd: -1500",
        "ros_can_interface.nodes.1.diffdrive", "node '1' names itself", base="rosparam"),
    Bad("ros-pair-on-two-buses", "dev_bus: can0, dev_id: 30", "dev_bus: can1, dev_id: 30", "dev_id: 20",
        "ros_can_interface.nodes.1.dev_bus", "differential pair nodes '1' (bus can0) and '2' (bus can1, line 17) are "
        "on different buses", base="rosparam"),
    Bad("ros-dev-type", "dev_type: 1, cpr: 3600,\n", "dev_type: 2, cpr: 3600,\n", "dev_type: 2",
        "ros_can_interface.nodes.0.dev_type", "dev_type 2 is not supported; only dev_type 1 (Elmo SimplIQ servo "
        "drive) is", base="rosparam"),
    Bad("ros-dev-id-zero", "dev_id: 40,", "dev_id: 0,", "dev_id: 0", "ros_can_interface.nodes.3.dev_id",
        "node id 0 of drive 'node3' is not a valid CAN node id", base="rosparam"),
    Bad("ros-duplicate-dev-id", "dev_id: 30,", "dev_id: 20,", "dev_id: 20,\ndev_type: 1, cpr: 6000, pos_min: -1500, "
        "pos_max: 1500, pos_margin: 60,\ndiffdrive: 1", "ros_can_interface.nodes.2.dev_id",
        "drives 'node1' (line 13) and 'node2' (line 17) both use node id 20 on bus 'can0'", base="rosparam"),
    Bad("ros-unknown-node-key", "pos_margin: 36, cal_speed", "pos_mrgin: 36, cal_speed", "pos_mrgin",
        "ros_can_interface.nodes.0.pos_mrgin", "unknown key 'pos_mrgin' in ros_can_interface.nodes.0; did you mean "
        "'pos_margin'?", base="rosparam"),
    Bad("ros-missing-dev-bus", "'3': {topics: joint/shoulder/joint_mc/0, dev_bus: can1,",
        "'3': {topics: joint/shoulder/joint_mc/0,", "'3':", "ros_can_interface.nodes.3.dev_bus",
        "missing required key 'dev_bus' in ros_can_interface.nodes.3", base="rosparam"),
    Bad("ros-undefined-interface", "dev_bus: can1,", "dev_bus: can2,", "'3':", "ros_can_interface.nodes.3.dev_bus",
        "drive 'node3' is on bus 'can2', which is not defined", base="rosparam"),
    Bad("ros-bad-node-key", "'3': {", "'x3': {", "'x3'", "ros_can_interface.nodes.x3",
        "node key 'x3' is not a node number; expected '0'..'127'", base="rosparam"),
    Bad("ros-list-length", "send_interval: [1000, 1000]", "send_interval: [1000]", "send_interval",
        "ros_can_interface.send_interval", "send_interval has 1 value(s) but interfaces lists 2", base="rosparam"),
    Bad("ros-dd-key-without-diffdrive", "ext_pos_input: joint/shoulder/joint4/position}",
        "ext_pos_input: joint/shoulder/joint4/position, pos_min_dd: 3}", "pos_min_dd: 3",
        "ros_can_interface.nodes.3.pos_min_dd", "'pos_min_dd' is only valid on a differential node", base="rosparam"),
    Bad("ros-min-above-max", "pos_min: -1750, pos_max: 1750,\npos_margin: 36, cal_speed",
        "pos_min: 1750, pos_max: -1750,\npos_margin: 36, cal_speed", "pos_min: 1750, pos_max: -1750,",
        "ros_can_interface.nodes.0.pos_max", "range max -1750 must be above range min 1750", base="rosparam"),
    Bad("ros-cpr-string", "dev_type: 1, cpr: 3600,\n", "dev_type: 1, cpr: lots,\n", "cpr: lots",
        "ros_can_interface.nodes.0.cpr", "expected an integer, got the string 'lots'", base="rosparam"),
    Bad("ros-switch-input-too-high", "cal_sw_dd_H: 4}\n    '2'", "cal_sw_dd_H: 9}\n    '2'", "cal_sw_dd_H: 9",
        "ros_can_interface.nodes.1.cal_sw_dd_H", "switch input 9 is outside the inputs of drive", base="rosparam"),
]

CASES = NATIVE + ROSPARAM


def _apply(case: Bad) -> tuple[str, int]:
    base = BASE if case.base == "native" else ROSPARAM_BASE
    assert base.count(case.old) == 1, f"{case.id}: edit target must occur exactly once in the base"
    text = base.replace(case.old, case.new)
    hits = [i for i, line in enumerate(text.splitlines(), 1) if case.line_of.split("\n")[0] in line]
    if "\n" in case.line_of:
        hits = [text[:text.index(case.line_of)].count("\n") + 1]
    assert hits, f"{case.id}: line marker {case.line_of!r} not in the edited text"
    return text, hits[0]


def test_the_bases_are_valid():
    cfg = load_config_text(BASE, "base.yaml")
    assert cfg.pairs["shoulder"].drive_a == "diff_a"  # sorted by node id
    assert load_config_text(ROSPARAM_BASE, "ros.yaml").pairs


def test_there_are_enough_distinct_cases():
    assert len({c.id for c in CASES}) == len(CASES)
    assert len({(c.base, c.old, c.new) for c in CASES}) == len(CASES)
    assert len(CASES) >= 45


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_bad_config_is_rejected_with_location(case: Bad):
    text, line = _apply(case)
    filename = f"cfg/{case.id}.yaml"
    with pytest.raises(ConfigError) as exc:
        load_config_text(text, filename)
    err = exc.value
    assert err.exit_code == ExitCode.USAGE == 2
    assert err.location.file == filename
    assert err.location.line == line, f"{err} (expected line {line})"
    assert err.location.path == case.path, str(err)
    message = str(err)
    assert message.startswith(f"{filename}:{line}: {case.path}: "), message
    assert case.phrase in err.problem, message


def test_several_problems_report_the_first_and_count_the_rest():
    text = BASE.replace("      margin: 30\n", "      margin: -5\n").replace("node: 30,", "node: 0,")
    with pytest.raises(ConfigError) as exc:
        load_config_text(text, "two.yaml")
    assert exc.value.location.line == 10  # drives come before joints in the file
    assert "1 more problem" in (exc.value.hint or "")


def test_empty_and_non_mapping_files():
    with pytest.raises(ConfigError) as exc:
        load_config_text("", "empty.yaml")
    assert "empty.yaml:1" in str(exc.value) and "empty" in exc.value.problem
    with pytest.raises(ConfigError) as exc:
        load_config_text("- a\n- b\n", "list.yaml")
    assert "list.yaml:1" in str(exc.value) and "expected a mapping" in exc.value.problem


def test_multiple_documents_are_rejected():
    with pytest.raises(ConfigError) as exc:
        load_config_text(BASE + "---\nname: other\n", "multi.yaml")
    assert "YAML syntax error" in exc.value.problem
    assert exc.value.location.line == BASE.count("\n") + 1
