"""Minimal EDS files of the simulated nodes (configs/eds/): the objects their SDO servers answer,
with types, access and PDO mapping, written by canopen's own exporter from the very dictionaries the
simulator serves (sim/sdo.py), so a master that loads them sees what the simulator does.

    python -m sherpa_cli.sim.eds configs/eds      # regenerate; tests/test_sim_cia301.py checks they match
"""

from __future__ import annotations

import io
import sys
from pathlib import Path

from canopen import objectdictionary as od
from canopen.objectdictionary import eds

from sherpa_cli.elmo.protocol import SYNC_ID
from sherpa_cli.sim.encoder import ENCODER_OBJECTS, POSITION_ENTRY, SimEncoder
from sherpa_cli.sim.pdo import COB_INVALID, COB_NO_RTR, TPDO_BASES
from sherpa_cli.sim.sdo import DRIVE_OBJECTS, build_object_dictionary
from sherpa_cli.sim.settings import SimSettings

FILES = {"whistle-sim.eds": "whistle", "encoder-sim.eds": "encoder"}
FILE_INFO = {"FileName": "", "FileVersion": 1, "FileRevision": 0, "EdsVersion": "4.0", "CreatedBy": "sherpa-cli",
             "CreationDate": "01-01-2025", "CreationTime": "12:00AM", "ModificationDate": "01-01-2025",
             "ModificationTime": "12:00AM"}


def _sub(d: od.ObjectDictionary, index: int, sub: int) -> od.ODVariable:
    record = d[index]
    assert isinstance(record, od.ODRecord)
    return record[sub]


def _node_relative(var: od.ODVariable, offset: int) -> None:
    """A default of ``$NODEID+offset`` (canopen adds the node id when a master loads the file)."""
    var.default_raw = f"$NODEID+0x{offset:X}"  # type: ignore[attr-defined]  # export_eds writes it as given


def dictionary(kind: str) -> od.ObjectDictionary:
    """The simulated ``whistle`` or ``encoder``'s object dictionary, with its boot defaults."""
    s = SimSettings()
    if kind == "whistle":
        d = build_object_dictionary(DRIVE_OBJECTS)
        d.device_information.vendor_name, d.device_information.product_name = "Elmo (simulated)", s.device_name
        d.device_information.product_number = s.product_code
        for n, base in TPDO_BASES.items():
            _node_relative(_sub(d, 0x1800 + n, 1), (COB_NO_RTR if n == 1 else COB_INVALID) | base)
            _sub(d, 0x1800 + n, 2).default = 254
            _sub(d, 0x1A00 + n, 0).default = 1 if n == 1 else 0
        _sub(d, 0x1A01, 1).default = 0x20130040
        _node_relative(_sub(d, 0x1401, 1), 0x300)
        _sub(d, 0x1401, 2).default = 255
        _sub(d, 0x1601, 0).default, _sub(d, 0x1601, 1).default = 1, 0x20120040
    elif kind == "encoder":
        d = build_object_dictionary(ENCODER_OBJECTS, SimEncoder.sdo_tpdos, SimEncoder.sdo_fixed_tpdos, rpdo2=False)
        d.device_information.vendor_name, d.device_information.product_name = "(simulated)", "CANopen encoder"
        for n, base, ttype in ((0, 0x180, 254), (1, 0x280, 1)):
            _node_relative(_sub(d, 0x1800 + n, 1), base)
            _sub(d, 0x1800 + n, 2).default = ttype
            _sub(d, 0x1A00 + n, 0).default, _sub(d, 0x1A00 + n, 1).default = 1, POSITION_ENTRY
    else:
        raise ValueError(f"no simulated node '{kind}' (whistle, encoder)")
    sync = d[0x1005]
    assert isinstance(sync, od.ODVariable)
    sync.default = SYNC_ID
    d.device_information.vendor_number = s.vendor_id if kind == "whistle" else None
    for bitrate in (125_000, 250_000, 500_000, 1_000_000):
        d.device_information.allowed_baudrates.add(bitrate)
    return d


def eds_text(kind: str) -> str:
    """The EDS of ``kind`` as text (fixed dates: the same on every run)."""
    out = io.StringIO()
    name = next(f for f, k in FILES.items() if k == kind)
    eds.export_eds(dictionary(kind), out, file_info={**FILE_INFO, "FileName": name})
    return _sorted_baud_rates(out.getvalue())


def _sorted_baud_rates(text: str) -> str:
    """canopen writes the BaudRate_N lines in the iteration order of a set of floats and ints, which
    differed between two environments with the same canopen (deps-lowest): sorted by rate, the
    file is the same everywhere."""
    lines = text.splitlines(keepends=True)
    rows = [i for i, line in enumerate(lines) if line.startswith("BaudRate_")]
    if rows and rows == list(range(rows[0], rows[-1] + 1)):
        block = sorted((lines[i] for i in rows), key=lambda line: int(line.split("_", 1)[1].split("=", 1)[0]))
        lines[rows[0]:rows[-1] + 1] = block
    return "".join(lines)


def main(argv: list[str]) -> int:
    target = Path(argv[0] if argv else "configs/eds")
    target.mkdir(parents=True, exist_ok=True)
    for filename, kind in FILES.items():
        (target / filename).write_text(eds_text(kind), encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
