"""Who reaches the console, the REST API and the 3D view, and how: listeners, sign-in and
its throttle, proxies and CORS, the read caches and the limits on requests."""

from __future__ import annotations

from pydantic import BaseModel, Field, SecretStr, field_validator

from backend.settings.checks import _ORIGIN, DEV_SECRET, Network, parse_trusted_proxies


class AccessFields(BaseModel):
    """Settings of the listeners, the sign-in, the read caches and the request limits."""

    http_host: str = Field("127.0.0.1", description="Address of the console and REST API.")
    http_port: int = Field(8000, ge=1, le=65535, description="Port of the console and REST API.")
    viser_host: str = Field("127.0.0.1", description="Address of the viser 3D view.")
    viser_port: int = Field(8080, ge=1, le=65535, description="Port of the viser 3D view (pinned).")
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
    auth_listen: bool = Field(
        True,
        description="On PostgreSQL, drop sign-ins that another process revoked (a token, a "
        "disabled user) at once through LISTEN/NOTIFY (after the 2 s sign-in cache otherwise).",
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

    def trusted_proxy_networks(self) -> tuple[Network, ...]:
        """``trusted_proxies`` as networks (an address is a network of one)."""
        return parse_trusted_proxies(self.trusted_proxies)
