"""Links to the line's PLC and the plant's MES: an OPC UA server and a Modbus TCP server over
one protocol-independent trigger/result handshake (docs/plc.md)."""

from backend.plc.handshake import (
    DECISION_CODES,
    ErrorCode,
    Handshake,
    LinkUser,
    PlcResult,
    Snapshot,
    SystemState,
)
from backend.plc.links import PlcLinks, plc_links

__all__ = [
    "DECISION_CODES",
    "ErrorCode",
    "Handshake",
    "LinkUser",
    "PlcLinks",
    "PlcResult",
    "Snapshot",
    "SystemState",
    "plc_links",
]
