"""Device types: the registry from a config type name to the class that talks to it, and reading the
CiA 406 encoder's position (encoder.py: TPDO1 with SDO as the fallback); the ATI F/T sensor's CAN
protocol is ft_sensor.py.

The seed's ``dev_type`` selected device-specific code (1 = Elmo was the only one). Here the
config's type name picks a class from :data:`REGISTRY`, the way python-can maps interface names
to bus classes; `drives:` are all "elmo", `devices:` name their type. Each class is built on the
device's SDO client (bus/sdo.py ``DriveSdo`` or anything with ``upload(index, sub)``).

May import bus, elmo, joints, config, errors.
"""

from __future__ import annotations

import struct
from typing import Protocol

from sherpa_cli.config.model import DEVICE_TYPES
from sherpa_cli.devices.ft_sensor import FtReader
from sherpa_cli.elmo.drive import ElmoDrive
from sherpa_cli.errors import UsageError

CIA406_DEVICE_PROFILE = 406
POSITION_VALUE = (0x6004, 0)  # CiA 406 position value, INTEGER32 (the TPDO1 default mapping)
TPDO1_BASE = 0x180


class SdoClient(Protocol):
    """What a device class needs of its SDO client (bus/sdo.py ``DriveSdo``; tests pass fakes)."""

    def upload(self, index: int, sub: int = 0, *, name: str | None = None) -> bytes: ...


class CanOpenEncoder:
    """A CANopen absolute encoder (CiA 406): the position value by SDO (0x6004) or from its TPDO."""

    type = "canopen-encoder"
    profile = CIA406_DEVICE_PROFILE

    def __init__(self, sdo: SdoClient) -> None:
        self.sdo = sdo

    def position(self) -> int:
        return struct.unpack("<i", bytes(self.sdo.upload(*POSITION_VALUE, name="position value"))[:4])[0]

    @staticmethod
    def tpdo_id(node: int) -> int:
        return TPDO1_BASE + node

    @staticmethod
    def position_from_tpdo(data: bytes) -> int:
        """The position from a TPDO1 frame with the default mapping (0x6004 first, INTEGER32)."""
        return struct.unpack_from("<i", bytes(data), 0)[0]


# the F/T sensor is no CANopen node: its class is built on a frame port, not an SDO client; a drive's
# class (the drive seam, sherpa_cli/drive.py) on its session's clients: devices/drives.py opens it
REGISTRY: dict[str, type] = {"elmo": ElmoDrive, "canopen-encoder": CanOpenEncoder, "ft_sensor": FtReader}
assert tuple(REGISTRY) == DEVICE_TYPES, "config.model.DEVICE_TYPES and the registry must list the same types"


def device_class(type_name: str) -> type:
    try:
        return REGISTRY[type_name]
    except KeyError:
        raise UsageError(f"unknown device type '{type_name}'; known: {', '.join(REGISTRY)}") from None
