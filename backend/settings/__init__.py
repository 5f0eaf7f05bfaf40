"""The one ``Settings`` object of VisionCell (environment prefix ``VISIONCELL_``).

Only the backend reads configuration; it builds a :class:`Settings` at start-up and passes
it down.  Validators refuse unsafe or inconsistent configurations with a message that names
the setting and the value.

The fields are declared by concern in the submodules (:mod:`~backend.settings.cell`,
:mod:`~backend.settings.access`, :mod:`~backend.settings.recognition`,
:mod:`~backend.settings.plc`) and composed here with the checks that span them.
"""

from __future__ import annotations

import ipaddress

from pydantic import field_validator, model_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

from backend.settings.access import AccessFields
from backend.settings.cell import CellFields
from backend.settings.checks import (
    CELL_NAME_PATTERN,
    DEV_SECRET,
    MAX_TRUSTED_PROXIES,
    Network,
    _is_loopback,
    parse_trusted_proxies,
)
from backend.settings.plc import PlcFields
from backend.settings.recognition import RecognitionFields

__all__ = [
    "CELL_NAME_PATTERN",
    "DEV_SECRET",
    "MAX_TRUSTED_PROXIES",
    "Network",
    "Settings",
    "parse_trusted_proxies",
]


class Settings(PlcFields, RecognitionFields, AccessFields, CellFields, BaseSettings):
    """Configuration of one VisionCell process.

    Every field can be set from the environment as ``VISIONCELL_<NAME>`` (case-insensitive).
    """

    model_config = SettingsConfigDict(
        env_prefix="VISIONCELL_", extra="ignore", validate_default=True
    )

    @field_validator("http_host", "viser_host", "modbus_host")
    @classmethod
    def _valid_host(cls, v: str) -> str:
        if v != "localhost":
            try:
                ipaddress.ip_address(v)
            except ValueError as exc:
                raise ValueError(f"host must be an IP address or 'localhost', got {v!r}") from exc
        return v

    @model_validator(mode="after")
    def _safe(self) -> Settings:
        public = [
            f"{name}={host!r}"
            for name, host in (
                ("http_host", self.http_host),
                ("viser_host", self.viser_host),
                *((("opcua_endpoint", self.opcua_host()),) if self.opcua_endpoint else ()),
                *((("modbus_host", self.modbus_host),) if self.modbus_port else ()),
            )
            if not _is_loopback(host)
        ]
        if public and not self.auth_enabled:
            raise ValueError(
                f"refusing to bind to a non-loopback address ({', '.join(public)}) with "
                "auth_enabled=False: anyone on the network could move the robot"
            )
        dev_secret = self.secret_key.get_secret_value() == DEV_SECRET
        if dev_secret and (public or self.environment == "production"):
            raise ValueError(
                "VISIONCELL_SECRET_KEY must be set to a private value in production or when "
                f"binding to a non-loopback address ({', '.join(public) or 'environment=production'})"
            )
        if len(self.secret_key.get_secret_value()) < 16:
            raise ValueError("VISIONCELL_SECRET_KEY must be at least 16 characters long")
        if self.environment == "production" and not self.auth_enabled:
            raise ValueError("auth_enabled=False is not allowed in production")
        if self.driver == "serial" and not self.serial_port:
            raise ValueError(
                "driver='serial' needs VISIONCELL_SERIAL_PORT (the controller's device path)"
            )
        if self.camera_replay == "look" and self.camera == "sim":
            raise ValueError(
                "camera_replay='look' replays a recording: it needs the folder camera or an "
                "opencv camera on a video file, not the simulated camera"
            )
        if self.camera_order == "manifest" and self.camera != "folder":
            raise ValueError("camera_order='manifest' is an order of the folder camera's images")
        if self.cell_layout is not None:
            if "sim" in (self.driver, self.camera):
                raise ValueError(
                    "VISIONCELL_CELL_LAYOUT describes a real cell: the simulated cell "
                    f"(driver={self.driver!r}, camera={self.camera!r}) has its own layout"
                )
            from robot.layoutfile import LayoutError, load_layout

            try:
                load_layout(self.cell_layout)
            except LayoutError as exc:
                raise ValueError(f"VISIONCELL_CELL_LAYOUT: {exc}") from None
        if self.opcua_user_certificates is not None and self.opcua_security == "none":
            raise ValueError(
                "opcua_user_certificates needs an encrypting policy: set opcua_security to "
                "'encrypt' or 'both'"
            )
        if self.http_port == self.viser_port and self.http_host == self.viser_host:
            raise ValueError(f"http_port and viser_port must differ, both are {self.http_port}")
        return self

    def loopback_only(self) -> bool:
        """Whether the console, the REST API and the 3D view listen on the loopback
        interface only (nobody else on the network can reach them)."""
        return _is_loopback(self.http_host) and _is_loopback(self.viser_host)
