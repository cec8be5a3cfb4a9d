"""The dead-man: the drive objects the guard arms (heartbeat consumer, error behaviour, loss action).

The consumer entry 0x1016:1 watches the host's heartbeat (``0x700 + host id``); when it stops for
``consumer_time_ms`` the drive applies 0x1029:1 / 0x6007 and switches its motor off on its own.
"""

from __future__ import annotations

from sherpa_cli.elmo.protocol import COMM_ERROR, CONSUMER, HEARTBEAT_BASE, LOSS_ACTION, NMT_OPERATIONAL

__all__ = ["COMM_ERROR", "CONSUMER", "HEARTBEAT_BASE", "LOSS_ACTION", "NMT_OPERATIONAL", "OBJECT_NAMES", "SIZES"]

SIZES = {CONSUMER: "<I", COMM_ERROR: "<B", LOSS_ACTION: "<h"}
OBJECT_NAMES = {CONSUMER: "consumer heartbeat time", COMM_ERROR: "error behaviour",
                LOSS_ACTION: "abort connection option code"}
