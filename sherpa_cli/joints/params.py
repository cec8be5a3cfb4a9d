"""The parameter set one drive should hold (DriveParams) and the order parameters are listed and
written in. Below both the derivation (limits.py) and the current checks (currents.py)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

__all__ = ["PARAM_ORDER", "DriveParams", "ParamValue"]

# Order in which parameters are listed (and, by default, written); IL[n] follow ascending.
PARAM_ORDER = ("LL[2]", "HL[2]", "VL[2]", "VH[2]", "LL[3]", "HL[3]", "VL[3]", "VH[3]",
               "AC", "DC", "CL[1]", "PL[1]", "PL[2]")

ParamValue = int | float


@dataclass(frozen=True)
class DriveParams:
    """The parameter set one drive should hold, in write order (``params`` is read-only)."""

    drive: str
    bus: str
    node: int
    params: Mapping[str, ParamValue] = field(default_factory=lambda: MappingProxyType({}))

    def __post_init__(self) -> None:
        if not isinstance(self.params, MappingProxyType):
            object.__setattr__(self, "params", MappingProxyType(dict(self.params)))


