"""The protocol's numbers, defined once: CANopen (CiA 301) COB-ID bases and NMT codes, the objects
the tool writes, and the Elmo unit modes. Pure constants; every other module imports them from here.
Sources: ../shared/docs/elmo-protocol.md (CiA 301, Elmo's CAN implementation guide [IG])."""

from __future__ import annotations

# -- COB-ID function codes (CiA 301 predefined connection set) ----------------------------------
NMT_ID = 0x000
SYNC_ID = 0x080
EMCY_BASE = 0x080  # + node id
TPDO1_BASE, RPDO1_BASE = 0x180, 0x200
TPDO2_BASE, RPDO2_BASE = 0x280, 0x300  # Elmo: the binary interpreter's reply / request
TPDO3_BASE, RPDO3_BASE = 0x380, 0x400
TPDO4_BASE, RPDO4_BASE = 0x480, 0x500
SDO_TX_BASE, SDO_RX_BASE = 0x580, 0x600  # server -> client, client -> server
HEARTBEAT_BASE = 0x700  # + node id: NMT error control (heartbeat, boot-up)

# -- NMT --------------------------------------------------------------------------------------
NMT_START, NMT_STOP, NMT_PRE_OP, NMT_RESET_NODE, NMT_RESET_COMM = 0x01, 0x02, 0x80, 0x81, 0x82
# heartbeat state bytes
NMT_BOOT_UP, NMT_STOPPED, NMT_OPERATIONAL, NMT_PRE_OPERATIONAL = 0x00, 0x04, 0x05, 0x7F

# -- objects (index, sub-index) the tool writes -----------------------------------------------
CONSUMER = (0x1016, 1)  # u32: host id << 16 | time ms (heartbeat consumer)
COMM_ERROR = (0x1029, 1)  # u8: error behaviour on a communication error
LOSS_ACTION = (0x6007, 0)  # i16: abort connection option code
GROUP_INDEX = 0x2040  # Elmo: the binary interpreter's group id ([IG] 13-10)
TPDO_COMM, TPDO_MAP = 0x1800, 0x1A00  # + PDO number - 1
RPDO_COMM, RPDO_MAP = 0x1400, 0x1600
COB_INVALID = 0x80000000  # bit 31 of a PDO COB-ID: the PDO is off

# -- Elmo unit modes (UM) ---------------------------------------------------------------------
UM_TORQUE, UM_SPEED, UM_POSITION = 1, 2, 5  # UM=4 is dual feedback (position on PY)
