"""The one ``Settings`` object of VisionCell (environment prefix ``VISIONCELL_``).

Only the backend reads configuration; it builds a :class:`Settings` at start-up and passes
it down.  Validators refuse unsafe or inconsistent configurations with a message that names
the setting and the value.
"""

from __future__ import annotations

import ipaddress
import re
from pathlib import Path
from typing import Literal

from pydantic import Field, SecretStr, field_validator, model_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

__all__ = ["DEV_SECRET", "MAX_TRUSTED_PROXIES", "Settings", "parse_trusted_proxies"]

#: The secret used when none is configured.  Accepted only in the development
#: environment and only while every listener is bound to the loopback interface.
DEV_SECRET = "visioncell-development-secret-change-me"

#: A cell name: a short slug (lower-case letters and digits, inner '-' or '_', <= 40 chars).
CELL_NAME_PATTERN = re.compile(r"^[a-z0-9](?:[a-z0-9_-]{0,38}[a-z0-9])?$")


#: An origin (scheme, host, optional port; no path, no wildcard).
_ORIGIN = re.compile(
    r"^https?://[A-Za-z0-9.-]{1,253}(?::[0-9]{1,5})?$|^https?://\[[0-9A-Fa-f:.]{2,45}\](?::[0-9]{1,5})?$"
)


#: An OPC UA endpoint: opc.tcp://HOST:PORT with an optional path.
_OPCUA_ENDPOINT = re.compile(
    r"^opc\.tcp://(?P<host>[A-Za-z0-9.-]{1,253}|\[[0-9A-Fa-f:.]{2,45}\]):(?P<port>[0-9]{1,5})"
    r"(?P<path>/[A-Za-z0-9._~/-]{0,128})?$"
)

#: Most entries of ``VISIONCELL_TRUSTED_PROXIES``.
MAX_TRUSTED_PROXIES = 32

Network = ipaddress.IPv4Network | ipaddress.IPv6Network


def parse_trusted_proxies(value: str) -> tuple[Network, ...]:
    """The networks of a comma-separated list of IP addresses and CIDR networks.

    ``ValueError`` naming ``VISIONCELL_TRUSTED_PROXIES`` and the bad entry for anything else
    (a host name, a wildcard, more than :data:`MAX_TRUSTED_PROXIES` entries).
    """
    if not isinstance(value, str):
        raise ValueError(f"VISIONCELL_TRUSTED_PROXIES must be text, got {value!r}")
    if len(value) > 64 * MAX_TRUSTED_PROXIES:
        raise ValueError(
            f"VISIONCELL_TRUSTED_PROXIES is too long ({len(value)} characters): list at most "
            f"{MAX_TRUSTED_PROXIES} addresses or networks"
        )
    entries = [e.strip() for e in value.split(",") if e.strip()]
    if len(entries) > MAX_TRUSTED_PROXIES:
        raise ValueError(
            f"VISIONCELL_TRUSTED_PROXIES lists {len(entries)} entries; at most "
            f"{MAX_TRUSTED_PROXIES} are accepted"
        )
    networks = []
    for entry in entries:
        try:
            networks.append(ipaddress.ip_network(entry, strict=False))
        except ValueError:
            raise ValueError(
                "VISIONCELL_TRUSTED_PROXIES must be a comma-separated list of IP addresses "
                f"or networks (e.g. '10.0.0.5, 192.168.1.0/24'), got {entry[:80]!r}"
            ) from None
    return tuple(networks)


def _is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


class Settings(BaseSettings):
    """Configuration of one VisionCell process.

    Every field can be set from the environment as ``VISIONCELL_<NAME>`` (case-insensitive).
    """

    model_config = SettingsConfigDict(
        env_prefix="VISIONCELL_", extra="ignore", validate_default=True
    )

    environment: Literal["development", "production"] = Field(
        "development", description="'production' forbids the development secret and disabling auth."
    )
    cell_name: str = Field(
        "cell-1",
        description="Name of this cell's row in the database; several cells (processes) may "
        "share one PostgreSQL database, each with its own calibrations and inspections.",
    )
    database_url: str = Field(
        "sqlite+aiosqlite:///var/visioncell.db",
        description="SQLAlchemy async URL: sqlite+aiosqlite:///FILE or postgresql+asyncpg://USER@HOST/DB.",
    )
    database_busy_timeout_s: float = Field(
        30.0,
        gt=0,
        le=300,
        description="SQLite: how long a write waits for another connection's lock, seconds.",
    )
    http_host: str = Field("127.0.0.1", description="Address of the console and REST API.")
    http_port: int = Field(8000, ge=1, le=65535, description="Port of the console and REST API.")
    viser_host: str = Field("127.0.0.1", description="Address of the viser 3D view.")
    viser_port: int = Field(8080, ge=1, le=65535, description="Port of the viser 3D view (pinned).")
    driver: Literal["sim", "serial", "ideal"] = Field(
        "sim",
        description="Robot driver: the MuJoCo cell, the serial controller or the ideal follower.",
    )
    camera: Literal["sim", "opencv", "folder"] = Field(
        "sim",
        description="Image source: the simulated eye-in-hand camera, OpenCV, or an image folder.",
    )
    camera_device: str = Field("0", description="OpenCV camera: V4L2 index or a video/stream URL.")
    camera_folder: Path | None = Field(
        None,
        description="Folder camera: images to replay (default: the OpenCV chessboard photos in the data directory).",
    )
    camera_replay: Literal["stream", "look"] = Field(
        "stream",
        description="Folder camera and video files: 'stream' plays the images on by "
        "themselves (looping); 'look': each look of the cell takes the next image, so a "
        "session recorded from a real cell replays through the inspection loop.",
    )
    camera_order: Literal["name", "manifest"] = Field(
        "name",
        description="Folder camera: replay the images sorted by file name, or in the order "
        "the folder's order.txt lists them (one file name per line).",
    )
    cell_layout: Path | None = Field(
        None,
        description="A real cell's layout file (TOML or JSON: the station, the belt, the "
        "sorting bins; robot.layoutfile).  Unset: a fixed station in front of the arm, no "
        "bins.  The simulated cell has its own layout.",
    )
    camera_transfer: Literal["auto", "linear", "srgb"] = Field(
        "auto",
        description="The camera's transfer curve, for the colour descriptor (color-sift) and "
        "the colour tie-break: 'srgb' for 8-bit gamma-encoded cameras, 'linear' for raw or "
        "16-bit linear ones; 'auto' chooses by camera kind (see resolved_camera_transfer).",
    )
    camera_fps: float = Field(
        10.0, gt=0, le=120, description="Acquisition rate of the camera task, frames/s."
    )
    camera_idle_fps: float = Field(
        1.0,
        gt=0,
        le=120,
        description="Acquisition rate while nobody has asked for a frame for 2 s (a rendered camera costs CPU).",
    )
    data_dir: Path = Field(Path("../shared/data"), description="Public test data (see its README).")
    var_dir: Path = Field(
        Path("var"), description="Writable directory for the SQLite file, logs and job output."
    )
    serial_port: str | None = Field(
        None, description="Serial driver: device path of the controller."
    )
    serial_baud: int = Field(115200, gt=0, description="Serial driver: baud rate.")
    time_scale: float = Field(
        1.0,
        gt=0,
        le=100,
        description="Simulated seconds per wall-clock second (sim and ideal drivers).",
    )
    state_rate_hz: float = Field(
        50.0, gt=0, le=1000, description="Robot state publishing rate, Hz."
    )
    auth_enabled: bool = Field(
        True, description="Require bearer tokens on the API (only loopback may turn this off)."
    )
    signin_max_failures: int = Field(
        5, ge=1, le=1000, description="Failed sign-ins from one address that block it."
    )
    signin_window_s: float = Field(
        60.0, gt=0, le=86400, description="Window over which failed sign-ins are counted, s."
    )
    signin_block_s: float = Field(
        60.0, gt=0, le=86400, description="How long a blocked address gets 429, s."
    )
    signin_max_clients: int = Field(
        10_000, ge=1, le=1_000_000, description="Most client addresses the throttle tracks."
    )
    trusted_proxies: str = Field(
        "",
        description="Reverse proxies whose X-Forwarded-For names the client (the sign-in "
        "throttle's key): a comma-separated list of at most 32 IP addresses or networks, e.g. "
        "'10.0.0.5, 192.168.1.0/24'; empty (the default): the header is ignored and the "
        "peer's address is the client.",
    )
    cors_origins: list[str] = Field(
        default_factory=list,
        description="Origins allowed to call the API from another site (CORS); empty: none. "
        "Each is scheme://host[:port], e.g. 'https://hmi.plant.local'.",
    )
    secret_key: SecretStr = Field(
        SecretStr(DEV_SECRET), description="Pepper for hashing API tokens (HMAC-SHA256)."
    )
    bootstrap_operator: bool = Field(
        True,
        description="At start-up, issue a fresh token for a built-in user and print it: "
        "'engineer' on a development cell listening on loopback only, 'operator' otherwise.",
    )
    view3d_enabled: bool = Field(True, description="Start the viser 3D view.")
    sim_demo: bool = Field(
        True,
        description="Simulator: start with a few catalogue objects on the belt, indexing at the station.",
    )
    log_level: Literal["debug", "info", "warning", "error"] = "info"
    event_loop: Literal["auto", "uvloop", "asyncio"] = Field(
        "auto",
        description="Event loop of `visioncell serve`: uvloop when it is installed (auto), "
        "required (uvloop), or the standard library's (asyncio).",
    )
    read_cache_ttl_s: float = Field(
        1.0,
        ge=0.0,
        le=10.0,
        allow_inf_nan=False,
        description="How long the hot list and status reads are reused, seconds (0: off); "
        "a write by this process is seen at once, another process's within this time.",
    )
    fast_reads: bool = Field(
        True,
        description="Answer the console's hot reads (status, state, lists) from memory in "
        "front of FastAPI when the sign-in and the answer are known (backend/api/fastpath.py); "
        "false: every request through FastAPI.",
    )
    ws_compression: bool = Field(
        False,
        description="Offer per-message deflate on the console WebSocket (its messages are "
        "small JSON: compressing them costs the server CPU for a few bytes saved).",
    )
    recognition_method: Literal["sift", "orb", "akaze", "color-sift"] = Field(
        "sift",
        description="Feature method of trained views and inspections (changing it makes the "
        "stored views stale until `visioncell models reextract`).",
    )
    recognition_max_features: int = Field(
        1000, ge=50, le=4000, description="Strongest keypoints kept per trained view."
    )
    recognise_max_images: int = Field(
        16, ge=1, le=64, description="Most images one POST /api/recognition/recognise takes."
    )
    threshold_follow: bool = Field(
        True,
        description="Recompute the automatic threshold as a job after every change of the "
        "trained views or negatives (off: only teaches recompute it).",
    )
    threshold_quiet_s: float = Field(
        2.0,
        ge=0.0,
        le=600.0,
        allow_inf_nan=False,
        description="The automatic threshold is recomputed once the trained views have not "
        "changed for this long, seconds (many uploads in a row: one recomputation).",
    )
    image_retention: Literal["all", "failures"] = Field(
        "all",
        description="Inspection images (and 3D scene recordings) kept: of every inspection, or "
        "of unknown and failed ones only.",
    )
    image_max_age_days: int | None = Field(
        None, ge=1, le=3650, description="Prune images older than this many days (None: never)."
    )
    image_max_bytes: int | None = Field(
        None,
        ge=1_000_000,
        le=2**50,
        description="Prune the oldest inspections' images beyond this many bytes (None: no cap).",
    )
    image_prune_interval_s: float = Field(
        3600.0, ge=10.0, le=7 * 86400.0, description="Period of the automatic prune, s."
    )
    index_poll_s: float = Field(
        2.0,
        ge=0.05,
        le=60.0,
        description="How often the live index checks the database for models and views "
        "changed by another process (cell or CLI) when it cannot LISTEN (SQLite, or the "
        "PostgreSQL listening connection lost), s.",
    )
    index_listen: bool = Field(
        True,
        description="On PostgreSQL, learn of other processes' model and view changes at once "
        "through LISTEN/NOTIFY (polling every index_poll_s otherwise).",
    )
    motion_log: Path | None = Field(
        None,
        description="Append every motion command, with the e-stop, link and lock state that "
        "allowed it, to this JSON-lines file (an audit; off by default).",
    )
    auth_listen: bool = Field(
        True,
        description="On PostgreSQL, drop sign-ins that another process revoked (a token, a "
        "disabled user) at once through LISTEN/NOTIFY (after the 2 s sign-in cache otherwise).",
    )

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

    max_json_body_bytes: int = Field(
        1 << 20,
        ge=4096,
        le=64 << 20,
        description="Largest request body of a JSON route, bytes (413 beyond; checked on the "
        "Content-Length and while the body streams in, backend/api/edge.py).",
    )
    max_upload_body_bytes: int = Field(
        64 << 20,
        ge=1 << 20,
        le=1 << 30,
        description="Largest request body of an upload route (multipart images), bytes.",
    )
    max_request_pixels: int = Field(
        64_000_000,
        ge=1_000_000,
        le=1_000_000_000,
        description="Decoded pixels one request's images and masks may take in all (413 "
        "beyond, read from each file's header before it is decoded; backend/heavy.py).",
    )
    max_analysed_pixels: int = Field(
        4_194_304,
        ge=100_000,
        le=100_000_000,
        description="Largest uploaded image that is analysed (a trained view's features, a "
        "calibration sample's board search), pixels (413 beyond, from its header; SIFT "
        "takes about 230 bytes per pixel).",
    )
    heavy_workers: int = Field(
        1,
        ge=1,
        le=64,
        description="Threads decoding and analysing uploads (one leaves the other cores to "
        "the event loop and the cell; more where there are cores to spare).",
    )
    heavy_jobs: int = Field(
        2,
        ge=1,
        le=256,
        description="Requests decoding images or rendering plots at once (each holds its "
        "decoded images in memory).",
    )
    heavy_admit_wait_s: float = Field(
        10.0,
        ge=0.0,
        le=600.0,
        allow_inf_nan=False,
        description="Longest wait of such a request for its turn before a 503 busy, s.",
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

    @field_validator("trusted_proxies")
    @classmethod
    def _valid_proxies(cls, v: str) -> str:
        parse_trusted_proxies(v)  # raises naming the setting and the bad entry
        return ",".join(e.strip() for e in v.split(",") if e.strip())

    @field_validator("cors_origins")
    @classmethod
    def _valid_origins(cls, v: list[str]) -> list[str]:
        if len(v) > 32:
            raise ValueError(f"cors_origins holds at most 32 origins, got {len(v)}")
        for origin in v:
            if origin == "*" or not _ORIGIN.match(origin):
                raise ValueError(
                    "each of cors_origins must be an origin 'http(s)://host[:port]' without "
                    f"path or wildcard, got {origin!r}"
                )
        return v

    @field_validator("cell_name")
    @classmethod
    def _valid_cell_name(cls, v: str) -> str:
        if not CELL_NAME_PATTERN.match(v):
            raise ValueError(
                "cell_name must be a short slug: 1-40 lower-case letters, digits, '-' or '_', "
                f"starting and ending with a letter or digit, got {v!r}"
            )
        return v

    @field_validator("camera_device")
    @classmethod
    def _valid_device(cls, v: str) -> str:
        if not v.strip() or len(v) > 2048 or "\x00" in v:
            raise ValueError(
                "camera_device must be a V4L2 index ('0', '/dev/video0'), a video file or a "
                f"stream URL of at most 2048 characters, got {v[:80]!r}"
            )
        return v

    @field_validator("database_url")
    @classmethod
    def _valid_db(cls, v: str) -> str:
        if not (v.startswith("sqlite+aiosqlite://") or v.startswith("postgresql+asyncpg://")):
            raise ValueError(
                "database_url must use an async driver: 'sqlite+aiosqlite:///FILE' or "
                f"'postgresql+asyncpg://USER@HOST/DB', got {v!r}"
            )
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

    def opcua_host(self) -> str:
        """The host of ``opcua_endpoint`` (empty when there is none)."""
        m = _OPCUA_ENDPOINT.match(self.opcua_endpoint or "")
        return "" if m is None else m.group("host").strip("[]")

    def trusted_proxy_networks(self) -> tuple[Network, ...]:
        """``trusted_proxies`` as networks (an address is a network of one)."""
        return parse_trusted_proxies(self.trusted_proxies)

    def loopback_only(self) -> bool:
        """Whether the console, the REST API and the 3D view listen on the loopback
        interface only (nobody else on the network can reach them)."""
        return _is_loopback(self.http_host) and _is_loopback(self.viser_host)

    # -- derived paths ---------------------------------------------------------------------
    @property
    def is_sqlite(self) -> bool:
        """True for the embedded SQLite database."""
        return self.database_url.startswith("sqlite")

    def sqlite_path(self) -> Path | None:
        """File of the SQLite database, or None for in-memory/PostgreSQL."""
        if not self.is_sqlite:
            return None
        path = self.database_url.split(":///", 1)[-1]
        return None if path in ("", ":memory:") else Path(path)

    def resolved_camera_folder(self) -> Path:
        """Folder replayed by the folder camera."""
        return self.camera_folder or self.data_dir / "calibration" / "opencv-left"

    def resolved_camera_transfer(self) -> tuple[str, str]:
        """The transfer curve of ``(the colour descriptor, the colour tie-break)``.

        An explicit ``camera_transfer`` sets both.  ``auto``: the folder and OpenCV cameras
        are read as linear by both, chosen by measurement on the real illumination sets
        (``docs/readme/camera-transfer.md``: on 8-bit sRGB images the descriptor's recall
        is the same either way and the tie-break's signature tells the scenes apart as well
        or better read as linear; on linear images reading them as sRGB halves the
        signature's separation); the simulated camera renders linear values, which the
        descriptor reads as they are, while the tie-break keeps the sRGB reading its
        thresholds were measured with in the simulated cell's campaigns.
        """
        if self.camera_transfer != "auto":
            return self.camera_transfer, self.camera_transfer
        if self.camera == "sim":
            return "linear", "srgb"
        return "linear", "linear"

    def redacted_database_url(self) -> str:
        """The database URL with any password replaced by ``***``."""
        from sqlalchemy.engine import make_url

        return make_url(self.database_url).render_as_string(hide_password=True)
