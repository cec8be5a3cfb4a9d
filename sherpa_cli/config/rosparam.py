"""The seed's rosparam format (Appendix D.1, ``ros_can_interface:``) -> ArmConfig.

Mapping (docs/config.md, "The seed's rosparam format"):

* each entry i of ``interfaces`` becomes a bus named after it, ``interface: socketcan``,
  ``channel`` = the name; ``send_interval[i]`` (µs) and ``scheduler_interval[i]`` (ms) become
  ``send_interval_us`` / ``poll_interval_ms``; ``queue_size`` and ``topics`` have no use here.
  The format has no bitrate (the seed sets it with ``ip link``), so it stays None.
* node key ``k`` becomes drive ``node<k>``; a plain node also joint ``joint<k>``; a
  differential pair (``diffdrive`` names the partner's node key) becomes pair ``pair<lo>_<hi>``
  with Σ joint ``joint<lo>`` and Δ joint ``joint<hi>``, both taken from the lower node's keys.
* ``cal_sw_L`` + ``cal_sw_H``: stop switches at pos_min / pos_max; ``cal_sw_L`` alone: a home
  switch at ``cal_pos`` (or pos_min); ``cal_sw_H`` alone: a high stop switch.
* ``cal_pos`` missing: pos_min, unless ``ext_pos_input`` gives an absolute position (seed D.1.2).
* No overshoot, velocity, acceleration, current or drive model in the format: overshoot 0
  (with a warning), the rest None (left as on the drive).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from sherpa_cli.config.catalog import builtin_catalog
from sherpa_cli.config.model import (
    AbsEncoderConfig,
    ArmConfig,
    BusConfig,
    DriveConfig,
    JointConfig,
    JointRole,
    PairConfig,
    SwitchConfig,
    SwitchKind,
)
from sherpa_cli.config.native import default_name
from sherpa_cli.config.yamlnodes import Locs, Section, YNode, as_int, as_map, as_str, describe
from sherpa_cli.errors import ConfigError, Location

TOP_KEY = "ros_can_interface"
RCI_KEYS = ["topics", "interfaces", "queue_size", "send_interval", "scheduler_interval", "nodes"]
NODE_KEYS = ["topics", "dev_bus", "dev_id", "dev_type", "cpr", "pos_min", "pos_max", "pos_margin", "cal_speed",
             "cal_pos", "ext_pos_input", "cal_sw_L", "cal_sw_H", "diffdrive", "pos_min_dd", "pos_max_dd",
             "pos_margin_dd", "cal_sw_dd_L", "cal_sw_dd_H"]
DD_KEYS = ["pos_min_dd", "pos_max_dd", "pos_margin_dd", "cal_sw_dd_L", "cal_sw_dd_H"]
INT_KEYS = ["dev_id", "dev_type", "cpr", "pos_min", "pos_max", "pos_margin", "cal_speed", "cal_pos", "cal_sw_L",
            "cal_sw_H", "diffdrive", *DD_KEYS]
# Keys whose value is the same physical fact on both nodes of a pair; a mismatch is worth a warning.
PAIR_SHARED = ["cpr", "pos_min", "pos_max", "pos_margin", "cal_speed", "cal_pos", "cal_sw_L",
               "cal_sw_H", *DD_KEYS]
ELMO_SIMPLIQ = 1


def is_rosparam(root: YNode) -> bool:
    return root.kind == "map" and TOP_KEY in root.value


@dataclass
class _Node:
    key: str
    number: int
    sec: Section
    v: dict[str, Any] = field(default_factory=dict)

    @property
    def drive(self) -> str:
        return f"node{self.key}"

    @property
    def joint(self) -> str:
        return f"joint{self.key}"

    def loc(self, key: str) -> Location:
        return self.sec.loc(key)


def load_rosparam(root: YNode, filename: str) -> tuple[ArmConfig, Locs, list[str]]:
    locs = Locs(filename)
    warnings: list[str] = []
    for key, child in root.value.items():
        if key != TOP_KEY:
            # Other ROS nodes' parameters often share the file; they are not ours to judge.
            warnings.append(f"{child.loc}: top-level key '{key}' is not read (only {TOP_KEY} is)")
    rci = Section(root.value[TOP_KEY], RCI_KEYS, what=f"the {TOP_KEY} mapping (interfaces, nodes, ...)")
    locs.put(("buses",), rci.loc("interfaces"))

    iface_node = rci.req("interfaces")
    iface_items = iface_node.value if iface_node.kind == "seq" else [iface_node]
    interfaces = [as_str(i) for i in iface_items]
    if not interfaces:
        raise iface_node.error("no CAN interfaces listed; expected e.g. [can0, can1]")
    send = _per_interface(rci, "send_interval", interfaces, 1000)
    sched = _per_interface(rci, "scheduler_interval", interfaces, 10)
    buses: dict[str, BusConfig] = {}
    for i, (name, item) in enumerate(zip(interfaces, iface_items, strict=True)):
        if name in buses:
            raise item.error(f"interface '{name}' is listed twice in interfaces")
        locs.put(("bus", name), item.loc)
        locs.put(("bus", name, "send_interval_us"), _item_loc(rci, "send_interval", i))
        locs.put(("bus", name, "poll_interval_ms"), _item_loc(rci, "scheduler_interval", i))
        buses[name] = BusConfig(name=name, interface="socketcan", channel=name, bitrate=None,
                                send_interval_us=send[i], poll_interval_ms=sched[i], options={}, where=item.loc)

    nodes_node = rci.req("nodes")
    nodes: dict[str, _Node] = {}
    previous = -1
    for key, child in as_map(nodes_node, "a mapping of node numbers '0'..'127'").items():
        kloc = Location(child.file, child.key_line, child.path)
        if not (key.isascii() and key.isdigit()) or not 0 <= int(key) <= 127:
            raise ConfigError(f"node key '{key}' is not a node number; expected '0'..'127'", kloc)
        number = int(key)
        if str(number) in nodes:
            raise ConfigError(f"node number {number} is given twice", kloc)
        key = str(number)
        if number < previous:
            warnings.append(f"{kloc}: node '{key}' comes after node '{previous}'; the seed expects ascending order")
        previous = max(previous, number)
        sec = Section(child, NODE_KEYS, what="a node mapping (dev_bus, dev_id, dev_type, cpr, ...)")
        node = _Node(key, number, sec)
        for req in ("dev_bus", "dev_id", "dev_type", "cpr", "pos_min", "pos_max", "pos_margin"):
            sec.req(req)
        for k in INT_KEYS:
            node.v[k] = sec.int(k)
        for k in ("dev_bus", "ext_pos_input"):
            node.v[k] = sec.str(k)
        if node.v["dev_type"] != ELMO_SIMPLIQ:
            raise ConfigError(f"dev_type {node.v['dev_type']} is not supported; only dev_type {ELMO_SIMPLIQ} "
                              "(Elmo SimplIQ servo drive) is", sec.loc("dev_type"))
        if node.v["diffdrive"] is None:
            for k in DD_KEYS:
                if k in sec:
                    raise ConfigError(f"'{k}' is only valid on a differential node (one with diffdrive)",
                                      sec.loc(k))
        nodes[key] = node

    drives: dict[str, DriveConfig] = {}
    for n in nodes.values():
        locs.put(("drive", n.drive), n.sec.node.loc)
        locs.put(("drive", n.drive, "bus"), n.loc("dev_bus"))
        locs.put(("drive", n.drive, "node"), n.loc("dev_id"))
        drives[n.drive] = DriveConfig(name=n.drive, bus=n.v["dev_bus"], node=n.v["dev_id"], model=None, motor=None,
                                      where=n.sec.node.loc)

    joints: dict[str, JointConfig] = {}
    pairs: dict[str, PairConfig] = {}
    done: set[str] = set()
    for n in nodes.values():
        if n.key in done:
            continue
        if n.v["diffdrive"] is None:
            joints[n.joint] = _joint(n, JointRole.PLAIN, n.joint, n.drive, None, dd=False, locs=locs)
            continue
        partner = _partner(n, nodes)
        lo, hi = sorted((n, partner), key=lambda x: x.number)
        done.update((lo.key, hi.key))
        differ = [k for k in PAIR_SHARED if lo.v.get(k) != hi.v.get(k)]
        if differ:
            warnings.append(f"{hi.sec.node.loc}: nodes '{lo.key}' and '{hi.key}' of a differential pair disagree on "
                            f"{', '.join(differ)}; the values of the lower node '{lo.key}' are used")
        pname = f"pair{lo.key}_{hi.key}"
        a, b = sorted((lo, hi), key=lambda x: x.v["dev_id"])
        locs.put(("pair", pname), lo.sec.node.loc)
        locs.put(("pair", pname, "drives"), hi.loc("diffdrive"))
        for x in (lo, hi):
            locs.put(("pair", pname, "drive", x.drive), x.loc("diffdrive"))
        # Each node has its own ext_pos_input: the lower node's reads Σ, the higher node's Δ.
        joints[lo.joint] = _joint(lo, JointRole.SIGMA, lo.joint, None, pname, dd=False, locs=locs)
        joints[hi.joint] = _joint(lo, JointRole.DELTA, hi.joint, None, pname, dd=True, locs=locs,
                                  ext_node=hi)
        pairs[pname] = PairConfig(name=pname, drive_a=a.drive, drive_b=b.drive, sigma=lo.joint, delta=hi.joint,
                                  current=None, where=lo.sec.node.loc)

    # Repeated per joint this would drown the real findings; the format simply lacks it.
    warnings.append(f"{filename}: the rosparam format has no overshoot; every joint's overshoot is 0, so LL/HL[3] "
                    "equal the full range (add it in the native format)")
    warnings.append(f"{filename}: the rosparam format names no drive models or motors; current and input checks "
                    "against the catalog use defaults")
    cfg = ArmConfig(name=default_name(filename), buses=buses, drives=drives, joints=joints, pairs=pairs,
                    catalog=builtin_catalog(), source=filename)
    return cfg, locs, warnings


def _per_interface(rci: Section, key: str, interfaces: list[str], default: int) -> list[int]:
    node = rci.get(key)
    if node is None:
        return [default] * len(interfaces)
    if node.kind == "scalar":
        return [as_int(node)] * len(interfaces)
    if node.kind != "seq":
        raise node.error(f"expected a list with one value per interface, got {describe(node)}")
    if len(node.value) != len(interfaces):
        raise node.error(f"{key} has {len(node.value)} value(s) but interfaces lists {len(interfaces)}; "
                         "expected one value per interface")
    return [as_int(i) for i in node.value]


def _item_loc(rci: Section, key: str, i: int) -> Location:
    node = rci.get(key)
    if node is not None and node.kind == "seq":
        return node.value[i].loc
    return rci.loc(key)


def _partner(n: _Node, nodes: dict[str, _Node]) -> _Node:
    dd = n.v["diffdrive"]
    where = n.loc("diffdrive")
    if str(dd) == n.key:
        raise ConfigError(f"node '{n.key}' names itself as its diffdrive partner; expected the other node of the pair",
                          where)
    partner = nodes.get(str(dd))
    if partner is None:
        raise ConfigError(f"node '{n.key}' has diffdrive: {dd}, but there is no node '{dd}' in nodes "
                          "(diffdrive names the partner's node number, not its CAN id)", where)
    back = partner.v["diffdrive"]
    if back != n.number:
        what = "has no diffdrive" if back is None else f"has diffdrive: {back}"
        raise ConfigError(f"nodes '{n.key}' and '{partner.key}' are not a pair: node '{n.key}' has diffdrive: {dd} "
                          f"but node '{partner.key}' ({_line(partner.sec.node.loc)}) {what}; each must name the "
                          "other", where)
    if partner.v["dev_bus"] != n.v["dev_bus"]:
        raise ConfigError(f"differential pair nodes '{n.key}' (bus {n.v['dev_bus']}) and '{partner.key}' "
                          f"(bus {partner.v['dev_bus']}, {_line(partner.loc('dev_bus'))}) are on different buses; "
                          "both motors of a pair must be on one bus", n.loc("dev_bus"))
    return partner


def _line(loc: Location) -> str:
    return f"line {loc.line}"


def _joint(n: _Node, role: JointRole, name: str, drive: str | None, pair: str | None, *, dd: bool,
           locs: Locs, ext_node: _Node | None = None) -> JointConfig:
    v = n.v
    sfx = "_dd" if dd else ""

    def pick(key: str) -> tuple[Any, str]:
        # Δ keys default to the Σ ones (Table D.4).
        if dd and v.get(key + "_dd") is not None:
            return v[key + "_dd"], key + "_dd"
        return v[key], key

    pos_min, kmin = pick("pos_min")
    pos_max, kmax = pick("pos_max")
    margin, kmargin = pick("pos_margin")
    prefix = ("joint", name)
    locs.put(prefix, n.sec.node.loc)
    locs.put((*prefix, "cpr"), n.loc("cpr"))
    locs.put((*prefix, "range"), n.loc(kmin))
    locs.put((*prefix, "range", "min"), n.loc(kmin))
    locs.put((*prefix, "range", "max"), n.loc(kmax))
    locs.put((*prefix, "range", "margin"), n.loc(kmargin))
    locs.put((*prefix, "calibration", "speed"), n.loc("cal_speed"))

    ext_node = ext_node or n
    ext = ext_node.v["ext_pos_input"]
    if dd:
        # cal_pos is the Σ joint's (Table C.2); the Δ joint falls back to its own low end.
        cal_pos = None if ext else pos_min
        locs.put((*prefix, "calibration", "position"), n.loc(kmin))
    else:
        cal_pos = v["cal_pos"] if v["cal_pos"] is not None else (None if ext else pos_min)
        locs.put((*prefix, "calibration", "position"), n.loc("cal_pos" if v["cal_pos"] is not None else kmin))

    low, high = v[f"cal_sw{sfx}_L"], v[f"cal_sw{sfx}_H"]
    switches: list[SwitchConfig] = []
    specs: list[tuple[int, SwitchKind, int, str | None, str]] = []
    if low is not None and high is not None:
        specs = [(low, SwitchKind.STOP, pos_min, "low", f"cal_sw{sfx}_L"),
                 (high, SwitchKind.STOP, pos_max, "high", f"cal_sw{sfx}_H")]
    elif low is not None:
        home = cal_pos if cal_pos is not None else pos_min
        specs = [(low, SwitchKind.HOME, home, None, f"cal_sw{sfx}_L")]
    elif high is not None:
        specs = [(high, SwitchKind.STOP, pos_max, "high", f"cal_sw{sfx}_H")]
    for i, (inp, kind, pos, side, key) in enumerate(specs):
        loc = n.loc(key)
        for part in ((), ("input",), ("position",), ("drives",)):
            locs.put((*prefix, "switches", str(i), *part), loc)
        switches.append(SwitchConfig(input=inp, kind=kind, position=pos, side=side, where=loc))

    abs_enc = AbsEncoderConfig(source=ext, offset=0, where=ext_node.loc("ext_pos_input")) if ext else None
    return JointConfig(name=name, role=role, drive=drive, pair=pair, cpr=v["cpr"], pos_min=pos_min, pos_max=pos_max,
                       margin=margin, overshoot=0, switches=tuple(switches), cal_speed=v["cal_speed"],
                       cal_pos=cal_pos, abs_encoder=abs_enc, where=n.sec.node.loc)
