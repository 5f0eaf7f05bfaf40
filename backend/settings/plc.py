"""The links to a line's PLC or the MES: the OPC UA server and the Modbus TCP handshake."""

from __future__ import annotations

import ipaddress
from pathlib import Path
from typing import Literal

from pydantic import BaseModel, Field, field_validator

from backend.settings.checks import _OPCUA_ENDPOINT


class PlcFields(BaseModel):
    """Settings of the PLC links (OPC UA, Modbus TCP)."""

    opcua_endpoint: str | None = Field(
        None,
        description="Serve OPC UA for a line's PLC or the MES at this endpoint, "
        "'opc.tcp://HOST:PORT[/PATH]' (HOST an IP address or 'localhost'; e.g. "
        "'opc.tcp://127.0.0.1:4840/visioncell'); None (the default): no OPC UA server. "
        "Clients sign in with a VisionCell user's name and one of its API tokens as the "
        "password (docs/plc.md).",
    )
    opcua_anonymous: Literal["off", "read-only"] = Field(
        "off",
        description="OPC UA clients without a user: refused ('off'), or allowed to read and "
        "subscribe, never to call a method ('read-only').",
    )
    opcua_security: Literal["none", "encrypt", "both"] = Field(
        "both",
        description="OPC UA security policies offered: 'none' (None: user names and tokens "
        "cross the network in clear), 'encrypt' (Basic256Sha256, SignAndEncrypt only), or "
        "'both'.  The server's certificate and key are made at first start under "
        "var_dir/opcua (self-signed; replace them with the plant's).",
    )
    opcua_user_certificates: Path | None = Field(
        None,
        description="Folder of user certificates, NAME.der or NAME.pem: an OPC UA client "
        "signing in with one of them (an X509 identity token, over the encrypting policy) "
        "acts as the enabled VisionCell user NAME; None: certificates sign nobody in.",
    )
    opcua_nodesets: bool = Field(
        True,
        description="Load OPC 40100's MachineVision and the DI NodeSet2 files from "
        "data_dir/opcua into the OPC UA server when they are there (a few seconds at start, "
        "on the server's own thread).",
    )
    modbus_port: int | None = Field(
        None,
        ge=1,
        le=65535,
        description="Serve the Modbus TCP handshake (docs/plc.md's register map) on this "
        "port; None (the default): no Modbus server.",
    )
    modbus_host: str = Field(
        "127.0.0.1",
        description="Address of the Modbus TCP server (Modbus has no sign-in: keep it on the "
        "loopback interface or the cell's own network segment).",
    )
    modbus_role: Literal["viewer", "operator", "engineer"] = Field(
        "operator",
        description="The role every Modbus client acts with: 'viewer' reads, 'operator' "
        "also triggers, runs, resets and selects recipes; 'engineer' the same (recipes are created and changed in the console, REST or the CLI only).",
    )
    plc_result_queue: int = Field(
        32,
        ge=1,
        le=1000,
        description="Results each PLC link holds until its PLC acknowledges them (a "
        "continuous run stores objects faster than a slow PLC reads them).",
    )

    @field_validator("opcua_endpoint")
    @classmethod
    def _valid_opcua_endpoint(cls, v: str | None) -> str | None:
        if v is None:
            return None
        m = _OPCUA_ENDPOINT.match(v) if isinstance(v, str) and len(v) <= 256 else None
        if m is None or not 1 <= int(m.group("port")) <= 65535:
            raise ValueError(
                "opcua_endpoint must be 'opc.tcp://HOST:PORT[/PATH]' with HOST an IP address "
                f"or 'localhost' and PORT in 1..65535 (at most 256 characters), got {str(v)[:80]!r}"
            )
        host = m.group("host").strip("[]")
        if host != "localhost":
            try:
                ipaddress.ip_address(host)
            except ValueError:
                raise ValueError(
                    f"opcua_endpoint's host must be an IP address or 'localhost', got {host!r}"
                ) from None
        return v

    def opcua_host(self) -> str:
        """The host of ``opcua_endpoint`` (empty when there is none)."""
        m = _OPCUA_ENDPOINT.match(self.opcua_endpoint or "")
        return "" if m is None else m.group("host").strip("[]")
